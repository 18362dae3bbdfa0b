"""Pieces shared by the raw-release converters (ParaHome ``seq/``, OMOMO joblib): meshes without URDFs,
rigid parts written as objects, the static rule and small index helpers."""

from __future__ import annotations

import hashlib
import re
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from wristmimic.convert.common import ConvertOptions, ConvertReport, object_record
from wristmimic.convert.objects import ObjectAsset, asset_from_mesh
from wristmimic.errors import InputError
from wristmimic.rotations import quat_rotate

STATIC_MOTION_M = 0.005
"""InterAct's rule: an object whose points move less than 5 mm per frame over the clip is static."""
_FRAMES = re.compile(r"^\s*(\d+)\s*:\s*(\d+)\s*$")


@dataclass
class PartObject:
    """One rigid part to write as an object: its asset, static flag and provenance (``extra``)."""

    asset: ObjectAsset
    static: bool
    extra: dict[str, Any] = field(default_factory=dict)
    source_file: str = ""


def mesh_asset(name: str, mesh_path: Path, opts: ConvertOptions, scale: float = 1.0) -> ObjectAsset:
    """An object from a bare OBJ (no URDF), uniformly scaled by ``scale`` (baked into the vertices)."""
    mesh_path = Path(mesh_path)
    if not mesh_path.is_file():
        raise InputError(mesh_path, "mesh", "file not found", "an OBJ mesh")
    if not (np.isfinite(scale) and scale > 0):
        raise InputError(mesh_path, "scale", f"invalid scale {scale}", "a finite number > 0")
    props = {} if scale == 1.0 else {"mesh_scale": [scale] * 3}
    return asset_from_mesh(name, mesh_path, None, props, opts.object_density, opts.surface_points, opts.surface_seed)


def write_part_objects(
    writer: Any, parts: dict[str, PartObject], opts: ConvertOptions, report: ConvertReport, bar: Any
) -> None:
    """Decompose (cached) and write every part as its own object, with ``extra`` provenance."""
    task = bar.add_task("objects (coacd hulls)", total=len(parts))
    for oid in sorted(parts):
        p = parts[oid]
        t0 = time.perf_counter()
        rec, _, hit = object_record(p.asset, opts, static=p.static)
        rec.extra = p.extra
        rec.source_file = p.source_file or rec.source_file
        writer.add_object(oid, rec)
        report.seconds_per_object[oid] = time.perf_counter() - t0
        report.hull_cache_hits[oid] = hit
        bar.advance(task)


def max_point_motion(points: np.ndarray, pos: np.ndarray, quat: np.ndarray) -> float:
    """Largest per-frame displacement (m) of any of ``points`` (object frame) under poses (T, 3), (T, 4)."""
    if len(pos) < 2:
        return 0.0
    sub = points[:: max(1, len(points) // 64)]
    world = quat_rotate(quat[:, None], sub[None]) + pos[:, None]
    return float(np.linalg.norm(np.diff(world, axis=0), axis=-1).max())


def parse_frames(text: str, num_frames: int, source: str | Path) -> tuple[int, int]:
    """``a:b`` (end exclusive, like a Python slice) -> (a, b), checked against the sequence length."""
    m = _FRAMES.match(text)
    if not m:
        raise InputError(source, "--frames", f"{text!r} is not a frame range", "START:END, e.g. 200:355")
    a, b = int(m[1]), int(m[2])
    if not 0 <= a < b <= num_frames or b - a < 2:
        raise InputError(source, "--frames", f"{a}:{b} outside the {num_frames} frames", "0 <= START < END - 1")
    return a, b


def short_hash(arr: np.ndarray) -> str:
    """First 8 hex digits of the sha256 of an array's float64 bytes (stable ids for variants)."""
    return hashlib.sha256(np.ascontiguousarray(arr, dtype=np.float64).tobytes()).hexdigest()[:8]
