"""Raw OMOMO release (joblib ``*_diffusion_manip_seq_joints24.p`` + ``captured_objects/``) -> canonical HDF5.

Record keys (``omomo-intermimic.md`` §1.2), per sequence: ``seq_name`` (``sub<N>_<object>_<NNN>``), ``betas``
(1 x 16 SMPL-X shape), ``gender``, ``trans`` (T x 3), ``root_orient`` (T x 3 axis-angle), ``pose_body`` (T x 63,
21 body joints; no hands: fingers stay at rest), ``obj_trans`` (T x 3 x 1), ``obj_rot`` (T x 3 x 3), ``obj_scale``
(T); two-part objects (mop, vacuum) add ``obj_bottom_trans/rot/scale``. World Z-up, metres, 30 fps, kept as is.

Meshes: ``captured_objects/<obj>_cleaned_simplified.obj`` (two-part: ``..._top.obj`` posed by ``obj_*`` and
``..._bottom.obj`` posed by ``obj_bottom_*``), world vertices ``s R v + t``: the scale is baked into the mesh
per sequence (an object id gets a ``_scale<s>`` suffix when sequences use different scales) and the pose is
``(R, t)``. The humanoid of each subject is generated from its betas and gender with the ``smplx`` package
(:mod:`wristmimic.humanoid.smplx_body`; the user supplies the SMPL-X model files). Body rotations compose the
SMPL-X joint rotations along the kinematic tree, then the upright rest rotation; the root sits at
``trans + J_pelvis(betas)``. FK of the generated humanoid is checked against the ``smplx`` model's posed joints.
"""

from __future__ import annotations

import re
import time
from dataclasses import dataclass
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
from wristmimic.convert.progress import progress_bar
from wristmimic.convert.raw_common import PartObject, mesh_asset, short_hash, write_part_objects
from wristmimic.errors import InputError
from wristmimic.format.records import SequenceRecord
from wristmimic.format.writer import DatasetWriter
from wristmimic.humanoid.kinematics import local_from_global
from wristmimic.humanoid.smplx_body import (
    MODEL_URL,
    SMPLX_INDEX,
    SMPLX_PARENTS,
    UPRIGHT_QUAT,
    ShapedBody,
    SmplxModels,
    find_model_file,
    smplx_mjcf,
)
from wristmimic.rotations import matrix_to_quat, quat_conj, quat_mul, rotvec_to_quat
from wristmimic.safe_io import safe_pickle_load, sha256_file

TWO_PART = ("mop", "vacuum")
SCALE_TOL = 1e-4
JOINT_TOL_M = 1e-3
_NAME = re.compile(r"^(?P<subject>sub\d+)_(?P<object>[a-z]+)_(?P<num>\d+)$")


@dataclass
class OmomoSequence:
    """One checked OMOMO record."""

    sid: str
    subject: str
    object: str
    gender: str
    betas: np.ndarray  # (n,)
    trans: np.ndarray  # (T, 3)
    root_orient: np.ndarray  # (T, 3)
    pose_body: np.ndarray  # (T, 21, 3)
    parts: dict[str, tuple[np.ndarray, np.ndarray, float]]  # "" | "top" | "bottom" -> (t (T,3), R (T,3,3), scale)

    @property
    def num_frames(self) -> int:
        return int(self.trans.shape[0])


def _arr(path: Path, where: str, rec: dict, key: str, shape: tuple[int | None, ...]) -> np.ndarray:
    if key not in rec:
        raise InputError(path, f"{where}.{key}", "missing", "the OMOMO record keys (omomo-intermimic.md §1.2)")
    a = np.asarray(rec[key], dtype=np.float64)
    if a.ndim == len(shape) + 1 and a.shape[-1] == 1:
        a = a[..., 0]  # obj_trans is stored T x 3 x 1 (a scale may be T x 1)
    if a.ndim != len(shape) or any(s is not None and s != n for s, n in zip(shape, a.shape, strict=False)):
        raise InputError(path, f"{where}.{key}", f"shape {a.shape}", str(tuple("T" if s is None else s for s in shape)))
    if not np.isfinite(a).all():
        raise InputError(path, f"{where}.{key}", "non-finite values", "finite numbers")
    return a


def _part(path: Path, where: str, rec: dict, prefix: str, T: int) -> tuple[np.ndarray, np.ndarray, float]:
    t = _arr(path, where, rec, f"{prefix}trans", (T, 3))
    R = _arr(path, where, rec, f"{prefix}rot", (T, 3, 3))
    s = _arr(path, where, rec, f"{prefix}scale", (T,))
    if s.min() <= 0 or np.ptp(s) > SCALE_TOL * s.mean():
        raise InputError(path, f"{where}.{prefix}scale", f"scale {s.min():.5f}..{s.max():.5f}", "constant and > 0")
    if np.abs(np.einsum("tji,tjk->tik", R, R) - np.eye(3)).max() > 1e-3 or np.linalg.det(R).min() < 0:
        raise InputError(path, f"{where}.{prefix}rot", "not rotation matrices", "orthonormal, det +1")
    return t, R, float(s.mean())


def _text(v: object) -> str:
    if isinstance(v, bytes):
        return v.decode("utf-8", "replace")
    return str(v.item() if isinstance(v, np.ndarray) and v.size == 1 else v)


def check_record(path: Path, key: object, rec: object) -> OmomoSequence:
    """Check one record (``key`` is its index in the file) and return it in float64 arrays."""
    where = f"[{key}]"
    if not isinstance(rec, dict):
        raise InputError(path, where, f"holds a {type(rec).__name__}", "a dict per sequence")
    name = _text(rec.get("seq_name", ""))
    m = _NAME.match(name)
    if not m:
        raise InputError(path, f"{where}.seq_name", f"{name!r}", "sub<N>_<object>_<NNN>")
    where = f"{where} {name}"
    T = _arr(path, where, rec, "trans", (None, 3)).shape[0]
    if T < 2:
        raise InputError(path, f"{where}.trans", f"{T} frames", ">= 2 frames")
    gender = _text(rec.get("gender", "")).lower()
    if gender not in ("male", "female", "neutral"):
        raise InputError(path, f"{where}.gender", f"{rec.get('gender')!r}", "'male' or 'female'")
    betas = np.asarray(rec.get("betas", np.zeros(0)), dtype=np.float64).reshape(-1)
    if not 1 <= len(betas) <= 300 or not np.isfinite(betas).all():
        raise InputError(path, f"{where}.betas", f"{len(betas)} values", "1 x 16 finite SMPL-X shape parameters")
    obj = m["object"]
    if obj in TWO_PART:
        parts = {"top": _part(path, where, rec, "obj_", T), "bottom": _part(path, where, rec, "obj_bottom_", T)}
    else:
        parts = {"": _part(path, where, rec, "obj_", T)}
    return OmomoSequence(
        name, m["subject"], obj, gender, betas, _arr(path, where, rec, "trans", (T, 3)),
        _arr(path, where, rec, "root_orient", (T, 3)),
        _arr(path, where, rec, "pose_body", (T, 63)).reshape(T, 21, 3), parts,
    )  # fmt: skip


def read_records(path: str | Path, sequences: list[str] | None = None) -> list[OmomoSequence]:
    """Load the joblib/pickle file (restricted unpickling) and check the selected records."""
    path = Path(path)
    data = safe_pickle_load(path)
    if not isinstance(data, dict) or not data:
        raise InputError(path, "<root>", f"holds a {type(data).__name__}", "{index: record dict}")
    names = {_text(r.get("seq_name")): k for k, r in data.items() if isinstance(r, dict)}
    if sequences:
        missing = [s for s in sequences if s not in names]
        if missing:
            raise InputError(path, missing[0], "no such sequence", f"one of {sorted(names)[:6]}")
        keys = [names[s] for s in sequences]
    else:
        keys = sorted(data, key=lambda k: _text(data[k].get("seq_name", k)) if isinstance(data[k], dict) else str(k))
    seqs = [check_record(path, k, data[k]) for k in keys]
    ids = [s.sid for s in seqs]
    if len(set(ids)) != len(ids):
        raise InputError(path, "seq_name", "duplicate sequence names", "unique seq_name per record")
    return seqs


def mesh_file(objects_dir: Path, obj: str, part: str) -> Path:
    suffix = f"_{part}" if part else ""
    p = objects_dir / f"{obj}_cleaned_simplified{suffix}.obj"
    if not p.is_file():
        raise InputError(p, obj + suffix, "mesh missing", "captured_objects/<obj>_cleaned_simplified[_top|_bottom].obj")
    return p


def object_ids(seqs: list[OmomoSequence]) -> dict[tuple[str, str, float], str]:
    """(object, part, scale) -> object id: ``<obj>[_top|_bottom]``, plus ``_scale<s>`` when scales differ."""
    keys = sorted({(s.object, part, round(sc, 6)) for s in seqs for part, (_, _, sc) in s.parts.items()})
    out = {}
    for obj, part, sc in keys:
        base = f"{obj}_{part}" if part else obj
        variants = {k[2] for k in keys if k[:2] == (obj, part)}
        out[(obj, part, sc)] = base if len(variants) == 1 else f"{base}_scale{sc:.6g}"
    return out


def humanoid_ids(seqs: list[OmomoSequence]) -> dict[str, str]:
    """Sequence id -> humanoid id: the subject, plus a shape hash when one subject has several shapes."""
    shapes: dict[str, set[str]] = {}
    for s in seqs:
        shapes.setdefault(s.subject, set()).add(s.gender + short_hash(s.betas))
    return {s.sid: s.subject if len(shapes[s.subject]) == 1 else f"{s.subject}_{short_hash(s.betas)}" for s in seqs}


def body_quats(seq: OmomoSequence) -> np.ndarray:
    """(T, 52, 4) world rotations of the humanoid's bodies from the SMPL-X pose (fingers at rest)."""
    T = seq.num_frames
    g = np.zeros((T, 55, 4))
    g[:, 0] = rotvec_to_quat(seq.root_orient)
    local = rotvec_to_quat(seq.pose_body)
    for j in range(1, 55):
        parent = g[:, SMPLX_PARENTS[j]]
        g[:, j] = quat_mul(parent, local[:, j - 1]) if j < 22 else parent
    return quat_mul(g[:, SMPLX_INDEX], quat_conj(UPRIGHT_QUAT))


def smplx_joint_error(models: SmplxModels, seq: OmomoSequence, body_pos: np.ndarray) -> float:
    """Max distance (m) between FK body positions and the ``smplx`` model's posed joints."""
    import torch

    model, _ = models.model(seq.gender, len(seq.betas))
    n_expr = int(model.num_expression_coeffs)  # type: ignore[attr-defined]
    err = 0.0
    for a in range(0, seq.num_frames, 128):
        b = min(a + 128, seq.num_frames)
        n = b - a
        with torch.no_grad():
            out = model(  # type: ignore[operator]
                betas=torch.from_numpy(np.repeat(seq.betas[None], n, 0)),
                global_orient=torch.from_numpy(seq.root_orient[a:b]),
                body_pose=torch.from_numpy(seq.pose_body[a:b].reshape(n, 63)),
                transl=torch.from_numpy(seq.trans[a:b]),
                left_hand_pose=torch.zeros(n, 45, dtype=torch.float64),
                right_hand_pose=torch.zeros(n, 45, dtype=torch.float64),
                jaw_pose=torch.zeros(n, 3, dtype=torch.float64),
                leye_pose=torch.zeros(n, 3, dtype=torch.float64),
                reye_pose=torch.zeros(n, 3, dtype=torch.float64),
                expression=torch.zeros(n, n_expr, dtype=torch.float64),
                return_verts=True,
            )
        joints = out.joints[:, :55].numpy()[:, SMPLX_INDEX]
        err = max(err, float(np.linalg.norm(joints - body_pos[a:b], axis=-1).max()))
    return err


def _objects(
    seqs: list[OmomoSequence], objects_dir: Path, opts: ConvertOptions
) -> tuple[dict[tuple[str, str, float], str], dict[str, PartObject]]:
    """Object ids and their (scaled) meshes with part relations, before anything is written."""
    ids = object_ids(seqs)
    parts: dict[str, PartObject] = {}
    for s in seqs:
        top = ids.get((s.object, "top", round(s.parts.get("top", (0, 0, 0.0))[2], 6)))
        for part, (_, _, sc) in s.parts.items():
            oid = ids[(s.object, part, round(sc, 6))]
            if oid in parts:
                continue
            mesh = mesh_file(objects_dir, s.object, part)
            extra: dict[str, Any] = {"object": s.object, "part": part or "whole", "mesh_scale": sc}
            if part == "bottom":
                extra |= {"parent": top, "joint": {"type": "unknown", "note": "separately tracked second part"}}
            parts[oid] = PartObject(mesh_asset(oid, mesh, opts, sc), False, extra, mesh.name)
    return ids, parts


def convert_omomo_raw(
    pickle_path: str | Path,
    objects_dir: str | Path,
    out: str | Path,
    *,
    smplx_models: str | Path | None = None,
    sequences: list[str] | None = None,
    options: ConvertOptions | None = None,
) -> ConvertReport:
    """Convert raw OMOMO records into one canonical file at ``out`` (atomic)."""
    opts = options or ConvertOptions()
    if smplx_models is None or not Path(smplx_models).is_dir():
        raise InputError(
            smplx_models, "--smplx-models", "SMPL-X model folder not given or not found (each subject's humanoid "
            "is built from its betas)", f"a folder with SMPLX_MALE.npz / SMPLX_FEMALE.npz from {MODEL_URL} "
            "(free registration)",
        )  # fmt: skip
    pickle_path, objects_dir = Path(pickle_path), Path(objects_dir)
    seqs = read_records(pickle_path, sequences)
    models = SmplxModels(smplx_models)
    model_files = {g: find_model_file(smplx_models, g) for g in sorted({s.gender for s in seqs})}
    ids, parts = _objects(seqs, objects_dir, opts)
    hids = humanoid_ids(seqs)
    first = {hids[s.sid]: s for s in reversed(seqs)}  # one shaped body per humanoid
    bodies = {hid: models.shaped_body(s.gender, s.betas) for hid, s in sorted(first.items())}
    inputs = {pickle_path.name: sha256_file(pickle_path)}
    inputs |= {f"{objects_dir.name}/{p.asset.mesh_path.name}": p.asset.mesh_sha256 for p in parts.values()}
    inputs |= {f"smplx/{f.name}": sha256_file(f) for f in model_files.values()}
    report = ConvertReport(Path(out))
    with (
        DatasetWriter(
            out, source_dataset="omomo", source_format="omomo-raw", converter="omomo-raw", input_sha256=inputs
        ) as w,
        progress_bar(opts.show_progress) as bar,
    ):
        skels = {}
        for hid in sorted(bodies):
            hrec, skel = humanoid_record(smplx_mjcf(bodies[hid], hid), hid, bodies[hid].model_file.name)
            w.add_humanoid(hid, hrec)
            skels[hid] = (hrec, skel)
        write_part_objects(w, parts, opts, report, bar)
        task = bar.add_task("sequences", total=len(seqs))
        for s in seqs:
            t0 = time.perf_counter()
            hrec, skel = skels[hids[s.sid]]
            rec = _sequence(pickle_path, s, hids[s.sid], hrec, skel, bodies[hids[s.sid]], ids, parts, models, opts)
            w.add_sequence(s.sid, rec)
            report.sequences.append(s.sid)
            report.seconds_per_sequence[s.sid] = time.perf_counter() - t0
            report.fk_rotation_error_deg[s.sid] = rec.extra["fk_rotation_error_deg"]
            bar.advance(task)
    return report


def _sequence(
    path: Path, s: OmomoSequence, hid: str, hrec: Any, skel: Any, body: ShapedBody,
    ids: dict[tuple[str, str, float], str], parts: dict[str, PartObject], models: SmplxModels, opts: ConvertOptions,
) -> SequenceRecord:  # fmt: skip
    body_quat = body_quats(s)
    root_pos = s.trans + body.joints[0]
    joint_quat = local_from_global(skel, body_quat)
    kin = kinematics(skel, root_pos, body_quat[:, 0], joint_quat, body_quat, f"{path}: {s.sid}")
    joint_err = smplx_joint_error(models, s, kin.body_pos)
    if joint_err > JOINT_TOL_M:
        raise InputError(path, s.sid, f"humanoid FK is {joint_err * 1000:.1f} mm off the smplx joints", "< 1 mm")
    oids = [ids[(s.object, part, round(sc, 6))] for part, (_, _, sc) in s.parts.items()]
    obj_pos = np.stack([t for t, _, _ in s.parts.values()], axis=1)
    obj_quat = np.stack([matrix_to_quat(R) for _, R, _ in s.parts.values()], axis=1)
    meshes = [(parts[o].asset.vertices, parts[o].asset.faces) for o in oids]
    dist, geo = geometric_contacts(skel, hrec.roles, kin.qpos, meshes, obj_pos, obj_quat, opts.contact)
    summ = contact_summary(geo, hrec.roles, opts.contact)
    return SequenceRecord(
        humanoid_id=hid, object_ids=oids, subject=s.subject, dataset="omomo", root_pos=root_pos,
        root_quat=body_quat[:, 0], joint_quat=joint_quat, joint_angles=kin.joint_angles, body_pos=kin.body_pos,
        body_quat=body_quat, source_body_pos=kin.body_pos, source_body_pos_valid=np.zeros(len(body_quat[0]), bool),
        object_pos=obj_pos, object_quat=obj_quat, contact_labels=geo, contact_geometric=geo, contact_distance=dist,
        hand_contact=summ["hand"], object_contact=summ["hand"].any(axis=1), first_contact_frame=summ["first"],
        contact_window=summ["window"],
        contact_meta=geometric_contact_meta(opts.contact, "object surface samples"),
        source_file=path.name, extra={
            "fk_rotation_error_deg": kin.fk_rotation_error_deg, "smplx_joint_error_m": joint_err,
            "gender": s.gender, "betas": np.round(s.betas, 6).tolist(), "object": s.object,
            "object_scale": {o: parts[o].extra["mesh_scale"] for o in oids},
            "source_positions": "none stored: source_body_pos = FK of the generated humanoid (valid = false)",
        },
    )  # fmt: skip
