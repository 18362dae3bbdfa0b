"""Raw ParaHome release (``seq/sN/*.pkl``, ``scan/<obj>/simplified/*.obj``) -> canonical HDF5.

Source layout (``parahome-skillmimic.md`` §1.2-1.5)::

    ROOT/seq/sN/body_joint_orientations.pkl   (F, 23, 6)  6D = first two ROWS of R, global, body-centred frame
    ROOT/seq/sN/hand_joint_orientations.pkl   (F, 40, 6)  [:20] left, [20:] right, in the wrist (hand) frame
    ROOT/seq/sN/body_global_transform.pkl     (F, 4, 4)   body-centred -> world
    ROOT/seq/sN/bone_vectors.pkl              {'body'|'lhand'|'rhand': {parent: {child: (3,)}}}
    ROOT/seq/sN/object_transformations.pkl    {frame: {"<obj>_<base|partN>": (4, 4) world pose}}
    ROOT/seq/sN/joint_positions.pkl           (F, 73, 3)  optional: world joints, checks the FK
    ROOT/seq/sN/object_in_scene.json, text_annotation(s).json, joint_states.pkl   optional
    ROOT/scan/<obj>/simplified/{base,part1,part2}.obj

(``ROOT/sN`` without ``seq/`` works too.) Every pickle is read with the restricted unpickler. Body rotations:
``R_g R_j`` for body joints (``R_g`` from the global transform); hand joints ``R_g R_wrist R_hand``, and the
wrist body takes ``R_g R_wrist R_hand[wrist]`` (its finger offsets are in the hand frame). The humanoid is
generated from the sequence's ``bone_vectors.pkl`` (:mod:`wristmimic.humanoid.parahome`), so joint rotations
``parent^-1 child`` reproduce the rotations and ``joint_positions.pkl`` under MuJoCo FK. Every rigid part of
every object in the scene is its own object (``<obj>`` when it has only a base, else ``<obj>_base``,
``<obj>_part1``, ...), placed per frame from its transforms (a frame without a transform, or with an identity
placeholder, holds the nearest known pose). Static: furniture bases by name, or parts whose points move
< 5 mm/frame over the converted frames; contacts are computed against the others.
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from wristmimic.convert.common import (
    ConvertOptions,
    ConvertReport,
    contact_summary,
    geometric_contact_meta,
    geometric_contacts,
    humanoid_record,
    kinematics,
)
from wristmimic.convert.parahome_parts import ScenePart, object_parts, part_poses, scene_extras
from wristmimic.convert.progress import progress_bar
from wristmimic.convert.raw_common import PartObject, parse_frames, write_part_objects
from wristmimic.errors import InputError
from wristmimic.format.records import SequenceRecord
from wristmimic.format.writer import DatasetWriter
from wristmimic.humanoid.kinematics import local_from_global
from wristmimic.humanoid.parahome import BODY_NAMES, parahome_mjcf, read_bone_vectors
from wristmimic.rotations import matrix_to_quat, sixd_rows_to_matrix
from wristmimic.safe_io import safe_pickle_load, sha256_file

BODY23 = (
    "pHipOrigin jL5S1 jL4L3 jL1T12 jT9T8 jT1C7 jC1Head jRightT4Shoulder jRightShoulder jRightElbow jRightWrist "
    "jLeftT4Shoulder jLeftShoulder jLeftElbow jLeftWrist jRightHip jRightKnee jRightAnkle jRightBallFoot "
    "jLeftHip jLeftKnee jLeftAnkle jLeftBallFoot"
).split()
HAND20 = (
    "Wrist FirstCMC SecondCMC ThirdCMC FourthCMC FifthCMC FifthMCP FifthPIP FifthDIP FourthMCP FourthPIP "
    "FourthDIP ThirdMCP ThirdPIP ThirdDIP SecondMCP SecondPIP SecondDIP FirstMCP IP"
).split()
"""Order of each hand's 20 orientations in ``hand_joint_orientations.pkl``."""
HAND25 = (
    "Wrist FirstCMC SecondCMC ThirdCMC FourthCMC FifthCMC FifthMCP FifthPIP FifthDIP FifthTip FourthMCP "
    "FourthPIP FourthDIP FourthTip ThirdMCP ThirdPIP ThirdDIP ThirdTip SecondMCP SecondPIP SecondDIP SecondTip "
    "FirstMCP IP FirstTip"
).split()
"""Order of each hand's 25 positions in ``joint_positions.pkl`` (left 23:48, right 48:73)."""
_SIDES = {"Left": (14, 0, 23), "Right": (10, 20, 48)}  # body wrist index, orientation offset, position offset
_FILES = ("body_joint_orientations.pkl", "hand_joint_orientations.pkl", "body_global_transform.pkl")


@dataclass
class RawSequence:
    """Everything read (and checked) from one ``seq/sN`` folder."""

    name: str
    folder: Path
    root: Path
    body_rot: np.ndarray  # (F, 23, 3, 3)
    hand_rot: np.ndarray  # (F, 40, 3, 3)
    global_tf: np.ndarray  # (F, 4, 4)
    joint_pos: np.ndarray | None  # (F, 73, 3)
    bones: dict[tuple[str, str], np.ndarray]
    transforms: dict[int, dict[str, np.ndarray]]
    in_scene: dict[str, bool] | None
    annotations: list[tuple[int, int, str]]  # (start, end exclusive, text), sorted
    joint_states: dict[str, dict[int, float]]
    inputs: dict[str, str] = field(default_factory=dict)
    notes: dict[str, str] = field(default_factory=dict)  # what could not be used (reported, not fatal)

    @property
    def num_frames(self) -> int:
        return int(self.body_rot.shape[0])


@dataclass
class Clip:
    sequence_id: str
    start: int
    end: int  # exclusive
    text: str
    annotation: int | None = None


def sequence_folder(root: Path, sequence: str) -> Path:
    """``ROOT/seq/sN`` or ``ROOT/sN``."""
    for cand in (root / "seq" / sequence, root / sequence):
        if cand.is_dir():
            return cand
    raise InputError(root, f"seq/{sequence}", "sequence folder not found", "ROOT/seq/sN (ParaHome layout) or ROOT/sN")


def _array(path: Path, shape: tuple[int | None, ...]) -> np.ndarray:
    a = np.asarray(safe_pickle_load(path), dtype=np.float64) if path.is_file() else None
    if a is None:
        raise InputError(path, None, "file not found", "the ParaHome sequence files")
    if a.ndim != len(shape) or any(s is not None and s != n for s, n in zip(shape, a.shape, strict=False)):
        raise InputError(path, "<array>", f"shape {a.shape}", str(tuple("F" if s is None else s for s in shape)))
    if not np.isfinite(a).all():
        raise InputError(path, "<array>", "non-finite values", "finite numbers")
    return a


def _json(path: Path) -> Any:
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError) as e:
        raise InputError(path, None, f"not readable JSON ({e})") from None


def read_annotations(folder: Path, num_frames: int) -> tuple[list[tuple[int, int, str]], Path | None]:
    """``text_annotation.json`` or ``text_annotations.json``: ``{"start end": text}`` (inclusive)."""
    path = next((p for p in (folder / "text_annotation.json", folder / "text_annotations.json") if p.is_file()), None)
    if path is None:
        return [], None
    data = _json(path)
    if not isinstance(data, dict):
        raise InputError(path, "<root>", f"holds a {type(data).__name__}", '{"start end": "action"}')
    out = []
    for key, text in data.items():
        parts = str(key).split()
        if len(parts) != 2 or not all(p.isdigit() for p in parts) or int(parts[0]) > int(parts[1]):
            raise InputError(path, str(key), "not a frame range", '"START END" (inclusive)')
        a, b = int(parts[0]), min(int(parts[1]) + 1, num_frames)
        if a < b:
            out.append((a, b, str(text)))
    return sorted(out), path


def _transforms(path: Path) -> dict[int, dict[str, np.ndarray]]:
    data = safe_pickle_load(path)
    if not isinstance(data, dict):
        raise InputError(path, "<root>", f"holds a {type(data).__name__}", "{frame: {'<obj>_<part>': 4x4}}")
    out: dict[int, dict[str, np.ndarray]] = {}
    for f, parts in data.items():
        if not isinstance(parts, dict):
            raise InputError(path, f"frame {f}", "not a dict", "{'<obj>_<part>': 4x4}")
        row = {}
        for key, m in parts.items():
            m = np.asarray(m, dtype=np.float64)
            if m.shape != (4, 4) or not np.isfinite(m).all():
                raise InputError(path, f"frame {f}/{key}", f"shape {m.shape} or non-finite", "a finite 4x4 matrix")
            row[str(key)] = m
        out[int(f)] = row
    return out


def _joint_states(path: Path) -> dict[str, dict[int, float]]:
    if not path.is_file():
        return {}
    data = safe_pickle_load(path)
    if not isinstance(data, dict):
        raise InputError(path, "<root>", f"holds a {type(data).__name__}", "{'<obj>_partN': {frame: value}}")
    try:
        return {str(k): {int(f): float(np.asarray(v).reshape(-1)[0]) for f, v in d.items()} for k, d in data.items()}
    except (AttributeError, TypeError, ValueError, IndexError):
        raise InputError(path, "<root>", "not {part: {frame: number}}", "{'<obj>_partN': {frame: value}}") from None


def read_raw_sequence(root: str | Path, sequence: str) -> RawSequence:
    """Read and check every file of one sequence (nothing is written)."""
    root = Path(root)
    folder = sequence_folder(root, sequence)
    body6 = _array(folder / _FILES[0], (None, 23, 6))
    F = body6.shape[0]
    hand6 = _array(folder / _FILES[1], (F, 40, 6))
    gtf = _array(folder / _FILES[2], (F, 4, 4))
    jp_path = folder / "joint_positions.pkl"
    joint_pos = _array(jp_path, (None, 73, 3)) if jp_path.is_file() else None
    notes = {}
    if joint_pos is not None and len(joint_pos) != F:
        notes["joint_positions.pkl"] = f"{len(joint_pos)} frames, orientations have {F}: FK not checked"
        joint_pos = None
    bones = read_bone_vectors(folder / "bone_vectors.pkl")
    transforms = _transforms(folder / "object_transformations.pkl")
    scene_path = folder / "object_in_scene.json"
    in_scene = None
    if scene_path.is_file():
        scene = _json(scene_path)
        if not isinstance(scene, dict):
            raise InputError(scene_path, "<root>", f"holds a {type(scene).__name__}", "{object: true|false}")
        in_scene = {str(k): v is True or v == 1 or str(v).lower() == "true" for k, v in scene.items()}
    annotations, ann_path = read_annotations(folder, F)
    used = [folder / f for f in (*_FILES, "bone_vectors.pkl", "object_transformations.pkl", "joint_positions.pkl")]
    used += [p for p in (scene_path, ann_path, folder / "joint_states.pkl") if p is not None]
    inputs = {str(p.relative_to(root)): sha256_file(p) for p in used if p.is_file()}
    return RawSequence(
        sequence, folder, root, sixd_rows_to_matrix(body6), sixd_rows_to_matrix(hand6), gtf, joint_pos, bones,
        transforms, in_scene, annotations, _joint_states(folder / "joint_states.pkl"), inputs, notes,
    )  # fmt: skip


def select_clips(raw: RawSequence, frames: list[str] | None, annotations: list[int] | None) -> list[Clip]:
    """Clips from ``--frames a:b`` (end exclusive) and ``--annotation N``; neither: the whole sequence."""
    clips: list[Clip] = []
    for n in annotations or []:
        if not 0 <= n < len(raw.annotations):
            raise InputError(raw.folder, f"annotation {n}", f"{len(raw.annotations)} annotations", "a valid index")
        a, b, text = raw.annotations[n]
        clips.append(Clip(f"{raw.name}_{a}_{b}", a, b, text, n))
    for text in frames or []:
        a, b = parse_frames(text, raw.num_frames, raw.folder)
        over = [t for s, e, t in raw.annotations if s < b and e > a]
        clips.append(Clip(f"{raw.name}_{a}_{b}", a, b, "; ".join(dict.fromkeys(over))))
    if not clips:
        clips.append(
            Clip(f"{raw.name}_0_{raw.num_frames}", 0, raw.num_frames, "; ".join(t for *_, t in raw.annotations))
        )
    ids = [c.sequence_id for c in clips]
    if len(set(ids)) != len(ids):
        raise InputError(raw.folder, "clips", "the same clip is selected twice", "distinct clips")
    return clips


def body_rotations(raw: RawSequence, frames: np.ndarray) -> np.ndarray:
    """(T, 61, 3, 3) world rotations of the humanoid's bodies (MJCF order)."""
    rg = raw.global_tf[frames, :3, :3]
    rb = np.einsum("tij,tkjl->tkil", rg, raw.body_rot[frames])
    out = np.empty((len(frames), len(BODY_NAMES), 3, 3))
    for b, name in enumerate(BODY_NAMES):
        if name in BODY23 and not name.endswith("Wrist"):
            out[:, b] = rb[:, BODY23.index(name)]
            continue
        side = "Left" if "Left" in name else "Right"
        wrist, o, _ = _SIDES[side]
        short = name.removeprefix(f"j{side}")
        out[:, b] = rb[:, wrist] @ raw.hand_rot[frames, o + HAND20.index(short)]
    return out


def source_positions(raw: RawSequence, frames: np.ndarray) -> np.ndarray | None:
    """(T, 61, 3) ``joint_positions.pkl`` rows of the humanoid's bodies, or None without the file."""
    if raw.joint_pos is None:
        return None
    idx = []
    for name in BODY_NAMES:
        if name in BODY23:
            idx.append(BODY23.index(name))
        else:
            side = "Left" if "Left" in name else "Right"
            idx.append(_SIDES[side][2] + HAND25.index(name.removeprefix(f"j{side}")))
    return raw.joint_pos[frames][:, idx]


def convert_parahome_raw(
    root: str | Path,
    sequence: str,
    out: str | Path,
    *,
    frames: list[str] | None = None,
    annotations: list[int] | None = None,
    skip_missing: bool = False,
    options: ConvertOptions | None = None,
) -> ConvertReport:
    """Convert clips of one raw ParaHome sequence into one canonical file at ``out`` (atomic)."""
    opts = options or ConvertOptions()
    raw = read_raw_sequence(root, sequence)
    clips = select_clips(raw, frames, annotations)
    report = ConvertReport(Path(out), skipped=dict(raw.notes))
    used = np.unique(np.concatenate([np.arange(c.start, c.end) for c in clips]))
    parts, skipped = object_parts(raw.root, raw.transforms, raw.in_scene, skip_missing, opts)
    report.skipped.update(skipped)
    poses = {oid: part_poses(raw.transforms, p.key, raw.num_frames, raw.folder) for oid, p in parts.items()}
    part_objects = scene_extras(parts, poses, used)
    mjcf = parahome_mjcf(raw.bones, raw.name)
    inputs = dict(raw.inputs)
    inputs.update({str(p.asset.mesh_path.relative_to(raw.root)): p.asset.mesh_sha256 for p in part_objects.values()})
    with (
        DatasetWriter(
            out, source_dataset="parahome", source_format="parahome-raw", converter="parahome-raw", input_sha256=inputs
        ) as w,
        progress_bar(opts.show_progress) as bar,
    ):
        hrec, skel = humanoid_record(mjcf, raw.name, f"{raw.folder.name}/bone_vectors.pkl")
        w.add_humanoid(raw.name, hrec)
        write_part_objects(w, part_objects, opts, report, bar)
        task = bar.add_task("clips", total=len(clips))
        for clip in clips:
            t0 = time.perf_counter()
            seq = _clip(raw, clip, hrec, skel, parts, poses, part_objects, opts)
            w.add_sequence(clip.sequence_id, seq)
            report.sequences.append(clip.sequence_id)
            report.seconds_per_sequence[clip.sequence_id] = time.perf_counter() - t0
            report.fk_rotation_error_deg[clip.sequence_id] = seq.extra["fk_rotation_error_deg"]
            bar.advance(task)
    return report


def _joint_state_extra(raw: RawSequence, parts: dict[str, ScenePart], frames: np.ndarray) -> dict[str, Any]:
    """Per-frame joint states of the clip's articulated parts (summarised if too long for an attribute)."""
    out: dict[str, Any] = {}
    for oid, p in parts.items():
        states = raw.joint_states.get(p.key)
        if states:
            vals = [round(states[f], 6) if f in states else None for f in frames.tolist()]
            out[oid] = vals
    if len(json.dumps(out)) > 30000:  # HDF5 attributes stay well below 64 KiB
        known = {k: [x for x in v if x is not None] for k, v in out.items()}
        out = {k: {"omitted": "too long for an attribute", "min": min(v), "max": max(v)} for k, v in known.items() if v}
    return out


def _clip(
    raw: RawSequence, clip: Clip, hrec: Any, skel: Any, parts: dict[str, ScenePart],
    poses: dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]], objs: dict[str, PartObject], opts: ConvertOptions,
) -> SequenceRecord:  # fmt: skip
    frames = np.arange(clip.start, clip.end)
    T = len(frames)
    body_quat = matrix_to_quat(body_rotations(raw, frames))
    root_pos = raw.global_tf[frames, :3, 3]
    joint_quat = local_from_global(skel, body_quat)
    kin = kinematics(skel, root_pos, body_quat[:, 0], joint_quat, body_quat, str(raw.folder))
    src = source_positions(raw, frames)
    fk_err = None if src is None else np.linalg.norm(kin.body_pos - src, axis=-1)
    fk_pos = None if fk_err is None else {"mean": float(fk_err.mean()), "max": float(fk_err.max())}
    order = sorted(objs, key=lambda o: (objs[o].static, o))  # dynamic objects first
    obj_pos = np.stack([poses[o][0][frames] for o in order], axis=1)
    obj_quat = np.stack([poses[o][1][frames] for o in order], axis=1)
    dyn = [k for k, o in enumerate(order) if not objs[o].static]
    meshes = [(objs[order[k]].asset.vertices, objs[order[k]].asset.faces) for k in dyn]
    dist, geo = geometric_contacts(skel, hrec.roles, kin.qpos, meshes, obj_pos[:, dyn], obj_quat[:, dyn], opts.contact)
    summ = contact_summary(geo, hrec.roles, opts.contact)
    filled = {o: int(poses[o][2][frames].sum()) for o in order if poses[o][2][frames].any()}
    return SequenceRecord(
        humanoid_id=raw.name, object_ids=order, subject=raw.name, dataset="parahome",
        root_pos=root_pos, root_quat=body_quat[:, 0], joint_quat=joint_quat, joint_angles=kin.joint_angles,
        body_pos=kin.body_pos, body_quat=body_quat,
        source_body_pos=kin.body_pos if src is None else src,
        source_body_pos_valid=np.full(len(BODY_NAMES), src is not None),
        object_pos=obj_pos, object_quat=obj_quat, contact_labels=geo, contact_geometric=geo, contact_distance=dist,
        hand_contact=summ["hand"], object_contact=summ["hand"].any(axis=1), first_contact_frame=summ["first"],
        contact_window=summ["window"],
        contact_meta=geometric_contact_meta(opts.contact, "moving object parts"),
        text=clip.text, source_file=f"{raw.folder.name}/", extra={
            "fk_rotation_error_deg": kin.fk_rotation_error_deg,
            "fk_position_error_m": fk_pos,
            "clip_start": clip.start, "clip_end": clip.end, "annotation": clip.annotation,
            "dynamic_objects": [order[k] for k in dyn], "static_objects": [o for o in order if objs[o].static],
            "held_frames": filled, "joint_states": _joint_state_extra(raw, parts, frames), "num_frames_source": T,
        },
    )  # fmt: skip
