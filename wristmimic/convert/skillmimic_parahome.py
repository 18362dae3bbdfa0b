"""SkillMimic(-V2) ParaHome ``.pt`` clips -> canonical HDF5.

Source layout (like ``../shared/data/skillmimic_parahome``)::

    SRC/motions/<any sub-folders>/NNN_sXX_<skill>[_<start>_<end>].pt   float32 (T, 409 | 415)
    SRC/humanoids/sXX.xml                                              per-subject humanoid (61 bodies)
    SRC/objects/<obj>.urdf + SRC/objects/<obj>.obj

Columns (D = 403 + 6 * objects + 1 ... see :func:`column_map`): 0:3 root position; 3:6 root rotation vector;
6:9 unused (zero); 9:189 60 joints x 3 exp-maps (MJCF body order without the root); 189:402 71 x 3 joint
positions (first 61 = bodies, rest zero); then per object 3 position + 3 rotation vector; last a contact flag
(mostly empty). Joint hinge angles = intrinsic XYZ Euler angles of each exp-map rotation (the exp-maps fed
straight to the hinges are 8-20 cm off). The clips carry no static scene and no usable contact labels, so
contacts come from geometry and static supports are inferred where the object rests.
"""

from __future__ import annotations

import re
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from wristmimic.convert.common import (
    ConvertOptions,
    ConvertReport,
    box_record,
    contact_summary,
    geometric_contact_meta,
    geometric_contacts,
    humanoid_record,
    kinematics,
    write_objects,
)
from wristmimic.convert.objects import list_objects
from wristmimic.convert.progress import progress_bar
from wristmimic.convert.supports import InferredSupport, SupportParams, infer_supports
from wristmimic.errors import InputError
from wristmimic.format.records import ObjectRecord, SequenceRecord
from wristmimic.format.writer import DatasetWriter
from wristmimic.rotations import rotvec_to_quat
from wristmimic.safe_io import load_pt_tensor, sha256_file

NUM_BODIES = 61
NUM_JOINTS = 60
POS_SLOTS = 71
HEAD = 403  # root 3 + rot 3 + zeros 3 + dofs 180 + positions 213 + ... objects start at 402
OBJ0 = 402
_CLIP_RE = re.compile(
    r"^(?P<skill_id>\d{3})_(?P<subject>s\d+)_(?P<skill>[a-z]+(?:_[a-z]+)*?)(?:_(?P<start>\d+)_(?P<end>\d+))?$"
)


def column_map(num_objects: int) -> dict[str, tuple[int, int, str]]:
    """Column ranges of a clip with ``num_objects`` objects."""
    cols = {
        "root_pos": (0, 3, "root (pHipOrigin) position -> root_pos"),
        "root_rotvec": (3, 6, "root rotation vector -> root_quat"),
        "unused_6_9": (6, 9, "root velocity placeholder: verified zero"),
        "dof_expmap": (9, 189, "60 x 3 joint exp-maps -> joint_quat, joint_angles (XYZ Euler)"),
        "joint_pos": (189, 189 + 3 * NUM_BODIES, "61 x 3 world joint positions -> source_body_pos"),
        "unused_pos": (189 + 3 * NUM_BODIES, OBJ0, "position slots 61..70: verified zero"),
    }
    for k in range(num_objects):
        a = OBJ0 + 6 * k
        cols[f"object{k}_pos"] = (a, a + 3, f"object {k} base position -> object_pos")
        cols[f"object{k}_rotvec"] = (a + 3, a + 6, f"object {k} base rotation vector -> object_quat")
    end = OBJ0 + 6 * num_objects
    cols["contact_flag"] = (end, end + 1, "contact flag (mostly zero): kept as source_contact_flag statistics")
    return cols


@dataclass
class Clip:
    """A clip file and what its name says."""

    path: Path
    sequence_id: str
    subject: str
    skill: str
    objects: list[str]
    start: int | None
    end: int | None


def parse_clip_name(stem: str) -> dict[str, str | None]:
    """``003_s10_place_kettle_2580_2680`` -> skill id, subject, skill, start, end."""
    m = _CLIP_RE.match(stem)
    if not m:
        raise InputError(
            stem + ".pt",
            "file name",
            "not a SkillMimic clip name",
            "NNN_sXX_<skill>[_<start>_<end>].pt (or pass --subject and --objects)",
        )
    return m.groupdict()


def objects_from_skill(skill: str, available: list[str]) -> list[str]:
    """Object names in the last word of the skill, left to right, longest match first
    (``pour_kettlecup`` -> kettle, cup)."""
    word = skill.split("_")[-1]
    names = sorted(available, key=len, reverse=True)
    found: list[str] = []
    i = 0
    while i < len(word):
        for n in names:
            if word.startswith(n, i):
                found.append(n)
                i += len(n)
                break
        else:
            i += 1
    return found


def discover(
    src: Path,
    *,
    clips: list[str] | None = None,
    subject: str | None = None,
    objects: list[str] | None = None,
    skip_missing: bool = False,
) -> tuple[list[Clip], dict[str, str]]:
    """Find clips under ``motions/`` and resolve their humanoid and objects.

    Returns (clips, skipped: clip id -> reason). Missing pieces raise unless ``skip_missing``.
    """
    src = Path(src)
    if not (src / "motions").is_dir():
        raise InputError(src, "motions/", "folder missing", "SkillMimic layout: motions/, humanoids/, objects/")
    files = sorted((src / "motions").rglob("*.pt"))
    if not files:
        raise InputError(src / "motions", "**/*.pt", "no clip files")
    available = list_objects(src / "objects") if (src / "objects").is_dir() else []
    out: list[Clip] = []
    skipped: dict[str, str] = {}
    seen: dict[str, Path] = {}
    for f in files:
        stem = f.stem
        parsed = _CLIP_RE.match(stem)
        sid = stem[4:] if re.match(r"^\d{3}_", stem) else stem
        if clips and sid not in clips and stem not in clips:
            continue
        if sid in seen:
            raise InputError(f, "sequence id", f"{sid!r} also comes from {seen[sid]}", "unique clip names")
        seen[sid] = f
        if parsed is None and (subject is None or objects is None):
            parse_clip_name(stem)  # raises with the expected pattern
        subj = subject or parsed["subject"]
        objs = objects or objects_from_skill(parsed["skill"], available)
        problem = None
        if not (src / "humanoids" / f"{subj}.xml").is_file():
            problem = f"humanoid humanoids/{subj}.xml missing"
        elif not objs:
            problem = f"no object of {sorted(available)} named in skill {parsed['skill'] if parsed else stem!r}"
        else:
            miss = [o for o in objs if o not in available]
            if miss:
                problem = f"object mesh for {miss[0]!r} missing in objects/"
        if problem:
            if not skip_missing:
                raise InputError(f, sid, problem, "the clip's humanoid and meshes (or --skip-missing)")
            skipped[sid] = problem
            continue
        out.append(
            Clip(
                f,
                sid,
                subj,
                parsed["skill"] if parsed else "",
                objs,
                int(parsed["start"]) if parsed and parsed["start"] else None,
                int(parsed["end"]) if parsed and parsed["end"] else None,
            )
        )
    if clips:
        missing = [c for c in clips if c not in seen and not any(s.stem == c for s in files)]
        if missing:
            raise InputError(src / "motions", missing[0], "no such clip", f"one of {sorted(seen)[:6]}")
    return out, skipped


def read_clip(path: Path, num_objects: int) -> np.ndarray:
    """Load and check one clip tensor (float64)."""
    data = load_pt_tensor(path)
    D = OBJ0 + 6 * num_objects + 1
    if data.shape[1] not in (409, 415) or data.shape[0] < 2:
        raise InputError(path, "<tensor>", f"shape {data.shape}", "(T >= 2, 409) for one object or (T, 415) for two")
    if data.shape[1] != D:
        n = (data.shape[1] - OBJ0 - 1) // 6
        raise InputError(
            path,
            "<tensor>",
            f"{data.shape[1]} columns = {n} object(s), the name gives {num_objects}",
            "as many objects as the clip holds (use --objects)",
        )
    cols = column_map(num_objects)
    for name in ("unused_6_9", "unused_pos"):
        a, b, _ = cols[name]
        if np.any(data[:, a:b] != 0):
            raise InputError(path, f"columns {a}:{b}", "non-zero values in unused columns", "zeros")
    return data


def _support_record(
    sup: InferredSupport, sid: str, k: int, opts: ConvertOptions, params: SupportParams
) -> ObjectRecord:
    he = np.asarray(sup.half_extents, float)
    extra = {
        "sequence": sid,
        "intervals": [list(map(int, i)) for i in sup.intervals],
        "top_z": float(sup.top_z),
        "center": np.asarray(sup.center).tolist(),
        "half_extents": he.tolist(),
        "support_params": params.to_dict(),
    }
    return box_record(
        f"support{k}",
        2 * he,
        opts.object_density,
        static=True,
        inferred=True,
        n_surface=opts.surface_points,
        surface_seed=opts.surface_seed,
        source_file=f"inferred from {sid}",
        extra=extra,
    )


def convert_skillmimic_parahome(
    src: str | Path,
    out: str | Path,
    *,
    clips: list[str] | None = None,
    subject: str | None = None,
    objects: list[str] | None = None,
    skip_missing: bool = False,
    supports: SupportParams | None = None,
    options: ConvertOptions | None = None,
) -> ConvertReport:
    """Convert a SkillMimic ParaHome folder into one canonical file at ``out`` (atomic)."""
    opts = options or ConvertOptions()
    sparams = supports or SupportParams()
    src = Path(src)
    found, skipped = discover(src, clips=clips, subject=subject, objects=objects, skip_missing=skip_missing)
    if not found:
        raise InputError(
            src / "motions", None, "no clip can be converted: " + "; ".join(f"{k}: {v}" for k, v in skipped.items())
        )
    report = ConvertReport(Path(out), skipped=skipped)
    datas = {c.sequence_id: read_clip(c.path, len(c.objects)) for c in found}
    inputs = {str(c.path.relative_to(src)): sha256_file(c.path) for c in found}
    with (
        DatasetWriter(
            out,
            source_dataset="parahome",
            source_format="skillmimic-pt",
            converter="skillmimic-parahome",
            input_sha256=inputs,
        ) as w,
        progress_bar(opts.show_progress) as bar,
    ):
        humanoids = {}
        for subj in sorted({c.subject for c in found}):
            p = src / "humanoids" / f"{subj}.xml"
            rec, skel = humanoid_record(p.read_text(), subj, p.name)
            if skel.num_bodies != NUM_BODIES:
                raise InputError(p, "bodies", f"{skel.num_bodies} bodies", f"{NUM_BODIES} (ParaHome humanoid)")
            w.add_humanoid(subj, rec)
            humanoids[subj] = (rec, skel)
            inputs[str(p.relative_to(src))] = sha256_file(p)
        names = sorted({o for c in found for o in c.objects})
        assets = write_objects(w, names, src / "objects", src, opts, report, inputs, bar)
        task = bar.add_task("clips", total=len(found))
        for clip in found:
            t0 = time.perf_counter()
            hrec, skel = humanoids[clip.subject]
            seq, support_recs = _clip(clip, datas[clip.sequence_id], hrec, skel, assets, opts, sparams)
            for oid, orec in support_recs.items():
                w.add_object(oid, orec)
            w.add_sequence(clip.sequence_id, seq)
            report.sequences.append(clip.sequence_id)
            report.seconds_per_sequence[clip.sequence_id] = time.perf_counter() - t0
            report.fk_rotation_error_deg[clip.sequence_id] = seq.extra["fk_rotation_error_deg"]
            bar.advance(task)
        w.set_attr("input_sha256", inputs)
    return report


def _clip(
    clip: Clip, data: np.ndarray, hrec, skel, assets, opts: ConvertOptions, sparams: SupportParams
) -> tuple[SequenceRecord, dict[str, ObjectRecord]]:
    T = data.shape[0]
    O = len(clip.objects)
    root_pos = data[:, 0:3]
    root_quat = rotvec_to_quat(data[:, 3:6])
    joint_quat = rotvec_to_quat(data[:, 9:189].reshape(T, NUM_JOINTS, 3))
    kin = kinematics(skel, root_pos, root_quat, joint_quat, None, str(clip.path))
    obj_pos = np.stack([data[:, OBJ0 + 6 * k : OBJ0 + 6 * k + 3] for k in range(O)], axis=1)
    obj_quat = np.stack([rotvec_to_quat(data[:, OBJ0 + 6 * k + 3 : OBJ0 + 6 * k + 6]) for k in range(O)], axis=1)
    meshes = [(assets[o].vertices, assets[o].faces) for o in clip.objects]
    dist, geo = geometric_contacts(skel, hrec.roles, kin.qpos, meshes, obj_pos, obj_quat, opts.contact)
    summ = contact_summary(geo, hrec.roles, opts.contact)
    touched = summ["hand"].any(axis=1)
    sup_recs: dict[str, ObjectRecord] = {}
    k = 0
    for j, o in enumerate(clip.objects):
        for sup in infer_supports(assets[o].vertices, assets[o].faces, obj_pos[:, j], obj_quat[:, j], touched, sparams):
            sup_recs[f"{clip.sequence_id}__support{k}"] = _support_record(sup, clip.sequence_id, k, opts, sparams)
            k += 1
    n_sup = len(sup_recs)
    if n_sup:
        centers = np.stack([np.asarray(r.extra["center"]) for r in sup_recs.values()])
        obj_pos = np.concatenate([obj_pos, np.broadcast_to(centers[None], (T, n_sup, 3))], axis=1)
        obj_quat = np.concatenate([obj_quat, np.broadcast_to(np.array([1.0, 0, 0, 0]), (T, n_sup, 4))], axis=1)
    flag = data[:, -1]
    src_pos = data[:, 189 : 189 + 3 * NUM_BODIES].reshape(T, NUM_BODIES, 3)
    seq = SequenceRecord(
        humanoid_id=clip.subject,
        object_ids=[*clip.objects, *sup_recs],
        subject=clip.subject,
        dataset="parahome",
        root_pos=root_pos,
        root_quat=root_quat,
        joint_quat=joint_quat,
        joint_angles=kin.joint_angles,
        body_pos=kin.body_pos,
        body_quat=kin.body_quat,
        source_body_pos=src_pos,
        source_body_pos_valid=np.ones(NUM_BODIES, bool),
        object_pos=obj_pos,
        object_quat=obj_quat,
        contact_labels=geo,
        contact_geometric=geo,
        contact_distance=dist,
        hand_contact=summ["hand"],
        object_contact=touched,
        first_contact_frame=summ["first"],
        contact_window=summ["window"],
        contact_meta=geometric_contact_meta(opts.contact, "object surface samples"),
        text=clip.skill.replace("_", " "),
        source_file=str(clip.path.name),
        extra={
            "fk_rotation_error_deg": kin.fk_rotation_error_deg,
            "skill": clip.skill,
            "clip_start": clip.start,
            "clip_end": clip.end,
            "dynamic_objects": clip.objects,
            "inferred_supports": list(sup_recs),
            "source_contact_flag_fraction": float((flag > 0.5).mean()),
        },
    )
    return seq, sup_recs
