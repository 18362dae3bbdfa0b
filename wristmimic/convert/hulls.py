"""Convex decomposition of object meshes with coacd, cached on disk.

MuJoCo collides every mesh geom as its convex hull, so a non-convex object is represented by several
convex pieces (one mesh asset + geom per hull). Pieces come from coacd (deterministic for a given seed);
every hull is checked and, where needed, reduced to at most ``max_ch_vertex`` vertices, so the
"<= 64 vertices per hull" guarantee of the paper holds whatever coacd returns. Results are cached as one
``.npz`` per cache key (mesh hash + parameters + coacd version) because a real object takes seconds to
minutes to decompose.
"""

from __future__ import annotations

import dataclasses
import hashlib
import importlib.metadata
import json
import numbers
import os
import re
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import coacd
import numpy as np
from scipy.spatial import ConvexHull, QhullError

from wristmimic.errors import InputError
from wristmimic.safe_io import OutputError, atomic_output, remove_stale_temporaries

#: Bumped whenever the post-processing of coacd's output changes (part of the cache key).
_POSTPROCESS_VERSION = 1
_PREPROCESS_MODES = ("auto", "on", "off")


@dataclass(frozen=True)
class HullParams:
    """coacd parameters (names as in ``coacd.run_coacd``); defaults follow the paper supplement."""

    threshold: float = 0.05
    max_convex_hull: int = 10  # paper supplement: 10 default; kettle, cup 80; chair 50
    max_ch_vertex: int = 64  # <= 64 vertices per hull (paper supplement)
    decimate: bool = True  # makes coacd enforce max_ch_vertex
    preprocess_mode: str = "auto"
    preprocess_resolution: int = 50
    resolution: int = 2000
    mcts_nodes: int = 20
    mcts_iterations: int = 150
    mcts_max_depth: int = 3
    merge: bool = True
    seed: int = 0

    def __post_init__(self) -> None:
        """Reject values coacd would misread (raises InputError with key ``hull_params.<field>``)."""

        def bad(name: str, expected: str) -> InputError:
            return InputError(None, f"hull_params.{name}", f"invalid value {getattr(self, name)!r}", expected)

        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            if f.type == "bool":
                ok = isinstance(value, (bool, np.bool_))
                coerced: Any = bool(value) if ok else None
            elif f.type == "int":
                ok = isinstance(value, numbers.Integral) and not isinstance(value, (bool, np.bool_))
                coerced = int(value) if ok else None
            elif f.type == "float":
                ok = isinstance(value, numbers.Real) and not isinstance(value, (bool, np.bool_))
                coerced = float(value) if ok else None
            else:
                ok = isinstance(value, str)
                coerced = value
            if not ok:
                raise bad(f.name, f"type {f.type}")
            object.__setattr__(self, f.name, coerced)  # plain Python types: stable JSON and cache keys
        if not (np.isfinite(self.threshold) and 0.0 < self.threshold <= 1.0):
            raise bad("threshold", "0 < threshold <= 1")
        if self.max_convex_hull != -1 and self.max_convex_hull < 1:
            raise bad("max_convex_hull", "-1 (unlimited) or >= 1")
        if self.max_ch_vertex < 4:
            raise bad("max_ch_vertex", ">= 4")
        if self.preprocess_mode not in _PREPROCESS_MODES:
            raise bad("preprocess_mode", " | ".join(_PREPROCESS_MODES))
        for name in (
            "preprocess_resolution",
            "resolution",
            "mcts_nodes",
            "mcts_iterations",
            "mcts_max_depth",
        ):
            if getattr(self, name) < 1:
                raise bad(name, ">= 1")
        if self.seed < 0:
            raise bad("seed", ">= 0")

    def to_dict(self) -> dict[str, Any]:
        """Plain JSON-able dict of every field."""
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> HullParams:
        """Inverse of :meth:`to_dict`; missing keys take defaults, unknown keys raise InputError."""
        if not isinstance(d, dict):
            raise InputError(None, "hull_params", f"not a mapping: {type(d).__name__}", "a dict")
        known = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(d) - known)
        if unknown:
            raise InputError(None, "hull_params", f"unknown keys {unknown}", f"keys among {sorted(known)}")
        return cls(**d)


_CUP = re.compile(r"cup(?!board)")


def hull_params_for(object_name: str, base: HullParams | None = None) -> HullParams:
    """Per-object coacd parameters: 80 hulls for kettles and cups, 50 for chairs, else ``base``'s count.

    Matching is on the lower-cased name: ``kettle`` anywhere, ``cup`` anywhere except as ``cupboard``
    (``cuttingboard`` is not a cup), ``chair`` anywhere (``woodchair``, ``whitechair``, ``deskchair`` ...).
    """
    base = HullParams() if base is None else base
    name = object_name.lower()
    if "kettle" in name or _CUP.search(name):
        return dataclasses.replace(base, max_convex_hull=80)
    if "chair" in name:
        return dataclasses.replace(base, max_convex_hull=50)
    return base


@dataclass
class HullSet:
    """Convex pieces of one mesh, in the mesh's own (object-local) frame."""

    vertices: list[np.ndarray]  # float64 (k_i, 3) each, object-local frame
    faces: list[np.ndarray]  # int32 (m_i, 3) each, indices into the same hull's vertices, outward
    params: HullParams
    coacd_version: str
    cache_key: str  # hex sha256 of (mesh sha256, params JSON, coacd version)
    cache_hit: bool
    seconds: float  # time spent in this call (0-ish on cache hit)
    mesh_sha256: str = field(default="")

    @property
    def num_hulls(self) -> int:
        """Number of convex pieces."""
        return len(self.vertices)


def mesh_sha256(vertices: np.ndarray, faces: np.ndarray) -> str:
    """sha256 of the float64 vertex bytes followed by the int32 face bytes (C-contiguous, little-endian)."""
    v = np.ascontiguousarray(vertices, dtype="<f8")
    f = np.ascontiguousarray(faces, dtype="<i4")
    h = hashlib.sha256()
    h.update(v.tobytes())
    h.update(f.tobytes())
    return h.hexdigest()


def default_cache_dir() -> Path:
    """``$WRISTMIMIC_CACHE_DIR/hulls`` if that variable is set, else ``~/.cache/wristmimic/hulls``."""
    root = os.environ.get("WRISTMIMIC_CACHE_DIR")
    if root:
        return Path(root).expanduser() / "hulls"
    return Path.home() / ".cache" / "wristmimic" / "hulls"


def coacd_version() -> str:
    """Installed coacd distribution version (part of every cache key)."""
    return importlib.metadata.version("coacd")


def _cache_key(mesh_hash: str, params: HullParams, version: str) -> str:
    payload = {
        "mesh_sha256": mesh_hash,
        "params": params.to_dict(),
        "coacd_version": version,
        "postprocess_version": _POSTPROCESS_VERSION,
    }
    return hashlib.sha256(json.dumps(payload, sort_keys=True).encode()).hexdigest()


# --------------------------------------------------------------------------- hull post-processing


def _outward_hull(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Convex hull of ``points``: (its vertices in input order, triangles oriented outward, local indices)."""
    hull = ConvexHull(points)
    keep = np.sort(hull.vertices)
    remap = np.full(len(points), -1, dtype=np.int64)
    remap[keep] = np.arange(len(keep))
    faces = remap[hull.simplices]
    verts = points[keep]
    tri = verts[faces]
    normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    flip = np.einsum("ij,ij->i", normal, hull.equations[:, :3]) < 0
    faces[flip] = faces[flip][:, ::-1]
    return np.ascontiguousarray(verts, dtype=np.float64), np.ascontiguousarray(faces, dtype=np.int32)


def _farthest_point_subset(points: np.ndarray, k: int) -> np.ndarray:
    """Deterministic farthest-point subset of ``k`` indices (start: farthest from the centroid)."""
    d_c = np.linalg.norm(points - points.mean(axis=0), axis=1)
    chosen = [int(np.argmax(d_c))]
    dist = np.linalg.norm(points - points[chosen[0]], axis=1)
    for _ in range(k - 1):
        nxt = int(np.argmax(dist))
        chosen.append(nxt)
        dist = np.minimum(dist, np.linalg.norm(points - points[nxt], axis=1))
    return np.sort(np.asarray(chosen, dtype=np.int64))


def _clean_hull(vertices: np.ndarray, max_vertices: int) -> tuple[np.ndarray, np.ndarray] | None:
    """Canonical convex hull with <= ``max_vertices`` vertices, or None if degenerate/non-finite."""
    v = np.asarray(vertices, dtype=np.float64).reshape(-1, 3)
    if len(v) < 4 or not np.isfinite(v).all():
        return None
    try:
        verts, faces = _outward_hull(v)
        if len(verts) > max_vertices:
            verts, faces = _outward_hull(verts[_farthest_point_subset(verts, max_vertices)])
    except (QhullError, ValueError):
        return None
    if len(verts) < 4 or len(verts) > max_vertices:
        return None
    return verts, faces


def _check_hulls(vertices: list[np.ndarray], faces: list[np.ndarray], max_vertices: int) -> bool:
    """True if every hull has 4..max_vertices finite vertices and in-range triangle faces."""
    if not vertices or len(vertices) != len(faces):
        return False
    for v, f in zip(vertices, faces, strict=False):
        if v.ndim != 2 or v.shape[1] != 3 or not (4 <= len(v) <= max_vertices) or not np.isfinite(v).all():
            return False
        if f.ndim != 2 or f.shape[1] != 3 or len(f) < 4 or f.min() < 0 or f.max() >= len(v):
            return False
    return True


# --------------------------------------------------------------------------- packing


def pack_hulls(hs: HullSet) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Flatten hulls for storage: (vertices (N,3) f32, faces (M,3) i32 with hull-local indices,
    vertex_offsets (H+1,) i64, face_offsets (H+1,) i64)."""
    nv = [len(v) for v in hs.vertices]
    nf = [len(f) for f in hs.faces]
    vertex_offsets = np.concatenate([[0], np.cumsum(nv)]).astype(np.int64)
    face_offsets = np.concatenate([[0], np.cumsum(nf)]).astype(np.int64)
    verts = (np.concatenate(hs.vertices) if nv else np.zeros((0, 3))).astype(np.float32)
    faces = (np.concatenate(hs.faces) if nf else np.zeros((0, 3))).astype(np.int32)
    return verts.reshape(-1, 3), faces.reshape(-1, 3), vertex_offsets, face_offsets


def _check_offsets(offsets: np.ndarray, total: int, key: str) -> np.ndarray:
    o = np.asarray(offsets)
    if o.ndim != 1 or len(o) < 1 or not np.issubdtype(o.dtype, np.integer):
        raise InputError(None, key, f"bad offsets array shape {o.shape} dtype {o.dtype}", "1-D integer (H+1,)")
    if o[0] != 0 or o[-1] != total or np.any(np.diff(o) < 0):
        raise InputError(None, key, "offsets not monotone from 0 to the array length", f"0 ... {total}")
    return o.astype(np.int64)


def unpack_hulls(
    vertices: np.ndarray, faces: np.ndarray, vertex_offsets: np.ndarray, face_offsets: np.ndarray
) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """Inverse of :func:`pack_hulls`: per-hull float64 vertices and int32 (hull-local) faces."""
    v = np.asarray(vertices)
    f = np.asarray(faces)
    if v.ndim != 2 or v.shape[1] != 3:
        raise InputError(None, "vertices", f"shape {v.shape}", "(N, 3)")
    if f.ndim != 2 or f.shape[1] != 3:
        raise InputError(None, "faces", f"shape {f.shape}", "(M, 3)")
    vo = _check_offsets(vertex_offsets, len(v), "vertex_offsets")
    fo = _check_offsets(face_offsets, len(f), "face_offsets")
    if len(vo) != len(fo):
        raise InputError(None, "face_offsets", f"{len(fo) - 1} hulls vs {len(vo) - 1} in vertex_offsets")
    out_v: list[np.ndarray] = []
    out_f: list[np.ndarray] = []
    for i in range(len(vo) - 1):
        hv = np.array(v[vo[i] : vo[i + 1]], dtype=np.float64)
        hf = np.array(f[fo[i] : fo[i + 1]], dtype=np.int32)
        if len(hf) and (hf.min() < 0 or hf.max() >= len(hv)):
            raise InputError(None, f"faces[hull {i}]", "index out of the hull's vertex range", f"0..{len(hv) - 1}")
        out_v.append(hv)
        out_f.append(hf)
    return out_v, out_f


# --------------------------------------------------------------------------- cache


def _cache_path(cache_dir: Path, key: str) -> Path:
    return cache_dir / f"{key}.npz"


def _read_cache(
    path: Path, key: str, mesh_hash: str, params: HullParams, version: str
) -> tuple[list[np.ndarray], list[np.ndarray]] | None:
    """Hulls from a cache file, or None if it is missing, unreadable or does not match."""
    try:
        with np.load(path, allow_pickle=False) as z:
            meta = json.loads(str(z["meta"]))
            arrays = [z[k] for k in ("vertices", "faces", "vertex_offsets", "face_offsets")]
        if (
            meta.get("cache_key") != key
            or meta.get("mesh_sha256") != mesh_hash
            or meta.get("coacd_version") != version
            or HullParams.from_dict(meta.get("params")) != params
        ):
            return None
        verts, faces = unpack_hulls(*arrays)
    except Exception:  # noqa: BLE001 - any damage to a cache file means "recompute"
        return None
    if not _check_hulls(verts, faces, params.max_ch_vertex):
        return None
    return verts, faces


def _write_cache(path: Path, key: str, mesh_hash: str, params: HullParams, version: str, hs: HullSet) -> None:
    """Write the cache file atomically with :func:`~wristmimic.safe_io.atomic_output`.

    Its temporary file names the writing process, so one left by a killed conversion is removed by the next
    write of the same key; temporaries of the older naming (``.<key[:16]>.<random>.tmp``) are removed once
    untouched for :data:`~wristmimic.safe_io.STALE_AFTER_S`.
    """
    path.parent.mkdir(parents=True, exist_ok=True)
    v = np.concatenate(hs.vertices).astype(np.float64)
    f = np.concatenate(hs.faces).astype(np.int32)
    vo = np.concatenate([[0], np.cumsum([len(x) for x in hs.vertices])]).astype(np.int64)
    fo = np.concatenate([[0], np.cumsum([len(x) for x in hs.faces])]).astype(np.int64)
    meta = json.dumps(
        {
            "cache_key": key,
            "mesh_sha256": mesh_hash,
            "coacd_version": version,
            "params": params.to_dict(),
            "postprocess_version": _POSTPROCESS_VERSION,
            "seconds": hs.seconds,
        },
        sort_keys=True,
    )
    remove_stale_temporaries(path.parent / key[:16])  # the older naming: ".<key[:16]>.<random>.tmp"
    with atomic_output(path, ".npz") as tmp, open(tmp, "wb") as fh:  # a file object: np.savez adds no suffix
        np.savez(fh, vertices=v, faces=f, vertex_offsets=vo, face_offsets=fo, meta=np.array(meta))


# --------------------------------------------------------------------------- decomposition


def _validate_mesh(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    v = np.asarray(vertices)
    f = np.asarray(faces)
    if v.ndim != 2 or v.shape[1] != 3 or len(v) < 4:
        raise InputError(None, "vertices", f"shape {v.shape}", "(V, 3) with V >= 4")
    if f.ndim != 2 or f.shape[1] != 3 or len(f) < 1 or not np.issubdtype(f.dtype, np.integer):
        raise InputError(None, "faces", f"shape {f.shape} dtype {f.dtype}", "(F, 3) integer with F >= 1")
    v = np.ascontiguousarray(v, dtype=np.float64)
    if not np.isfinite(v).all():
        raise InputError(None, "vertices", "non-finite values", "finite coordinates")
    if f.min() < 0 or f.max() >= len(v):
        raise InputError(None, "faces", f"index out of range [0, {len(v)})", "valid vertex indices")
    return v, np.ascontiguousarray(f, dtype=np.int32)


def _run_coacd(vertices: np.ndarray, faces: np.ndarray, params: HullParams) -> list:
    coacd.set_log_level("error")
    mesh = coacd.Mesh(vertices, faces)
    return coacd.run_coacd(
        mesh,
        threshold=float(params.threshold),
        max_convex_hull=params.max_convex_hull,
        preprocess_mode=params.preprocess_mode,
        preprocess_resolution=params.preprocess_resolution,
        resolution=params.resolution,
        mcts_nodes=params.mcts_nodes,
        mcts_iterations=params.mcts_iterations,
        mcts_max_depth=params.mcts_max_depth,
        merge=params.merge,
        decimate=params.decimate,
        max_ch_vertex=params.max_ch_vertex,
        seed=params.seed,
    )


def convex_decompose(
    vertices: np.ndarray,
    faces: np.ndarray,
    params: HullParams,
    cache_dir: Path | None = None,
    *,
    use_cache: bool = True,
) -> HullSet:
    """Convex pieces of a triangle mesh with coacd, read from / written to the on-disk cache.

    Every hull coacd returns is replaced by the convex hull of its points (triangles, outward, hull-local
    indices); a hull with more than ``params.max_ch_vertex`` vertices is reduced to a deterministic
    farthest-point subset of its hull vertices; degenerate (flat, < 4 points, non-finite) hulls are dropped.
    ``cache_dir`` defaults to :func:`default_cache_dir`; a corrupt or mismatching cache file is recomputed
    and overwritten. Raises InputError for a malformed mesh or when no valid hull is left.
    """
    t0 = time.perf_counter()
    v, f = _validate_mesh(vertices, faces)
    version = coacd_version()
    mesh_hash = mesh_sha256(v, f)
    key = _cache_key(mesh_hash, params, version)
    path = _cache_path(Path(cache_dir) if cache_dir is not None else default_cache_dir(), key)

    if use_cache and path.is_file():
        cached = _read_cache(path, key, mesh_hash, params, version)
        if cached is not None:
            return HullSet(
                vertices=cached[0],
                faces=cached[1],
                params=params,
                coacd_version=version,
                cache_key=key,
                cache_hit=True,
                seconds=time.perf_counter() - t0,
                mesh_sha256=mesh_hash,
            )

    hull_v: list[np.ndarray] = []
    hull_f: list[np.ndarray] = []
    for part in _run_coacd(v, f, params):
        cleaned = _clean_hull(part[0], params.max_ch_vertex)
        if cleaned is not None:
            hull_v.append(cleaned[0])
            hull_f.append(cleaned[1])
    if not hull_v:
        raise InputError(None, "mesh", "coacd returned no non-degenerate convex hull", "a solid mesh")
    hs = HullSet(
        vertices=hull_v,
        faces=hull_f,
        params=params,
        coacd_version=version,
        cache_key=key,
        cache_hit=False,
        seconds=time.perf_counter() - t0,
        mesh_sha256=mesh_hash,
    )
    if use_cache:
        try:
            _write_cache(path, key, mesh_hash, params, version, hs)
        except OSError as exc:  # full disk, quota, read-only cache folder: one line, not a traceback
            raise OutputError.from_os(path, exc) from None
    return hs
