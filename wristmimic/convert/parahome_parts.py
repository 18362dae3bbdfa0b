"""Objects of a raw ParaHome scene: one object per rigid part, per-frame poses, static flags, articulation.

``object_transformations.pkl`` keys are ``<obj>_base`` / ``<obj>_partN``; meshes are
``scan/<obj>/simplified/<part>.obj``. An object with only a base is written as ``<obj>``; an articulated one as
``<obj>_base``, ``<obj>_part1``, ... Each part's ``extra`` records the relation (object, part, parent base) and
an articulation estimated from the part's pose relative to its base over the converted frames (revolute axis
and angle range when it turns by more than 2 degrees, prismatic direction and travel when it slides by more
than 5 mm, else fixed).
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from wristmimic.convert.common import ConvertOptions
from wristmimic.convert.objects import ObjectAsset
from wristmimic.convert.raw_common import STATIC_MOTION_M, PartObject, max_point_motion, mesh_asset
from wristmimic.errors import InputError
from wristmimic.format.schema import STATIC_OBJECT_NAMES
from wristmimic.rotations import matrix_to_quat, quat_conj, quat_mul, quat_rotate, quat_to_rotvec

_KEY = re.compile(r"^(?P<obj>.+)_(?P<part>base|part\d+)$")
REVOLUTE_MIN_RAD = np.radians(2.0)
PRISMATIC_MIN_M = 0.005


@dataclass
class ScenePart:
    """One rigid part of a scene object."""

    key: str  # "<obj>_<part>" as in object_transformations.pkl
    obj: str
    part: str
    asset: ObjectAsset


def object_parts(
    root: Path,
    transforms: dict[int, dict[str, np.ndarray]],
    in_scene: dict[str, bool] | None,
    skip_missing: bool,
    opts: ConvertOptions,
) -> tuple[dict[str, ScenePart], dict[str, str]]:
    """Object id -> part (mesh loaded) for every part of every object in the scene; (parts, skipped)."""
    keys = sorted({k for row in transforms.values() for k in row})
    by_obj: dict[str, list[tuple[str, str]]] = {}
    for k in keys:
        m = _KEY.match(k)
        if not m:
            raise InputError("object_transformations.pkl", k, "not an object part key", "<obj>_base or <obj>_partN")
        if in_scene is None or in_scene.get(m["obj"], True):
            by_obj.setdefault(m["obj"], []).append((k, m["part"]))
    skipped = {o: "in object_in_scene.json but never in object_transformations.pkl"
               for o, v in (in_scene or {}).items() if v and o not in by_obj}  # fmt: skip
    out: dict[str, ScenePart] = {}
    for obj, plist in sorted(by_obj.items()):
        single = [p for _, p in plist] == ["base"]
        for key, part in plist:
            mesh = root / "scan" / obj / "simplified" / f"{part}.obj"
            if not mesh.is_file():
                if not skip_missing:
                    raise InputError(mesh, key, "mesh missing", "scan/<obj>/simplified/<part>.obj (or --skip-missing)")
                skipped[key] = f"mesh {mesh.relative_to(root)} missing"
                continue
            oid = obj if single else key
            out[oid] = ScenePart(key, obj, part, mesh_asset(oid, mesh, opts))
    return out, skipped


def part_poses(
    transforms: dict[int, dict[str, np.ndarray]], key: str, num_frames: int, source: Path
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(pos (F, 3), quat (F, 4), held (F,) bool) of one part over the whole sequence. Frames without a transform
    (or with an identity placeholder) hold the nearest earlier known pose (the first known one at the start)."""
    known = sorted(f for f, row in transforms.items() if key in row and not np.array_equal(row[key], np.eye(4)))
    known = [f for f in known if 0 <= f < num_frames]
    if not known:
        raise InputError(source / "object_transformations.pkl", key, "no pose in any frame", "a 4x4 pose per frame")
    mats = np.stack([transforms[f][key] for f in known])
    rot = mats[:, :3, :3]
    err = np.abs(np.einsum("kji,kjl->kil", rot, rot) - np.eye(3)).max(axis=(1, 2))
    bad = np.flatnonzero((err > 1e-3) | (np.linalg.det(rot) < 0) | np.any(mats[:, 3] != (0, 0, 0, 1), axis=1))
    if len(bad):
        f = known[bad[0]]
        raise InputError(source / "object_transformations.pkl", f"frame {f}/{key}", "not a rigid transform",
                         "a rotation and a translation (no scale)")  # fmt: skip
    idx = np.clip(np.searchsorted(known, np.arange(num_frames), side="right") - 1, 0, len(known) - 1)
    held = ~np.isin(np.arange(num_frames), known)
    return mats[idx, :3, 3], matrix_to_quat(rot)[idx], held


def _runs(frames: np.ndarray) -> list[np.ndarray]:
    return np.split(frames, np.flatnonzero(np.diff(frames) != 1) + 1)


def articulation(base: tuple[np.ndarray, np.ndarray], part: tuple[np.ndarray, np.ndarray]) -> dict[str, Any]:
    """Joint of a part relative to its base from their poses (T frames): revolute / prismatic / fixed."""
    inv = quat_conj(base[1])
    rel_q = quat_mul(inv, part[1])
    rel_t = quat_rotate(inv, part[0] - base[0])
    d = quat_to_rotvec(quat_mul(quat_conj(rel_q[:1]), rel_q))  # in the part's first relative frame
    ang = np.linalg.norm(d, axis=1)
    if ang.max() > REVOLUTE_MIN_RAD:
        k = int(np.argmax(ang))
        axis_part = d[k] / ang[k]
        signed = d @ axis_part
        axis = quat_rotate(rel_q[0], axis_part)  # in the base frame
        return {"type": "revolute", "axis": np.round(axis, 6).tolist(),
                "range": [float(signed.min()), float(signed.max())], "unit": "rad"}  # fmt: skip
    moved = rel_t - rel_t[0]
    travel = np.linalg.norm(moved, axis=1)
    if travel.max() > PRISMATIC_MIN_M:
        axis = np.linalg.svd(moved, full_matrices=False)[2][0]
        axis = axis if moved[int(np.argmax(travel))] @ axis > 0 else -axis
        s = moved @ axis
        return {"type": "prismatic", "axis": np.round(axis, 6).tolist(),
                "range": [float(s.min()), float(s.max())], "unit": "m"}  # fmt: skip
    return {"type": "fixed"}


def scene_extras(
    parts: dict[str, ScenePart], poses: dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]], used: np.ndarray
) -> dict[str, PartObject]:
    """Static flag and provenance of every part over the converted frames ``used``."""
    base_of = {p.obj: oid for oid, p in parts.items() if p.part == "base"}
    out: dict[str, PartObject] = {}
    for oid, p in parts.items():
        pos, quat = poses[oid][0], poses[oid][1]
        motion = max(max_point_motion(p.asset.surface_points, pos[r], quat[r]) for r in _runs(used))
        by_name = p.part == "base" and p.obj.lower() in STATIC_OBJECT_NAMES
        static = by_name or motion < STATIC_MOTION_M
        extra: dict[str, Any] = {
            "object": p.obj, "part": p.part, "transform_key": p.key,
            "static_rule": "name" if by_name else ("motion < 5 mm/frame" if static else "moving"),
            "max_motion_m_per_frame": round(motion, 6),
        }  # fmt: skip
        parent = base_of.get(p.obj)
        if p.part != "base" and parent is not None:
            b = poses[parent]
            extra["parent"] = parent
            extra["joint"] = articulation((b[0][used], b[1][used]), (pos[used], quat[used]))
            extra["joint"]["estimated_from"] = "part pose relative to the base over the converted frames"
        out[oid] = PartObject(p.asset, static, extra, str(Path("scan") / p.obj / "simplified" / f"{p.part}.obj"))
    return out
