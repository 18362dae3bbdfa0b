"""Static support surfaces inferred from where an object rests.

SkillMimic ParaHome clips carry no static scene: the kettle starts at 0.79 m on a table that is not in the
file. Wherever the object is still, untouched and above the floor for a while, put an axis-aligned box under
it whose top is the object's bottom, a margin wider than the object's footprint, reaching down to the floor.

Shapes: T frames, V mesh vertices. Quaternions wxyz; world z up, floor at z = 0.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

import numpy as np

from wristmimic.errors import InputError
from wristmimic.rotations import quat_angle, quat_to_matrix

_FRAME_CHUNK = 64  # frames posed at once (memory: chunk x V x 3 floats)


@dataclass(frozen=True)
class SupportParams:
    """Thresholds of :func:`resting_intervals` and the box geometry of :func:`infer_supports`."""

    still_speed_m_s: float = 0.05  # object speed (central differences x fps) below this counts as still
    still_ang_rad_s: float = 0.3  # ... and angular speed below this
    min_frames: int = 5  # a resting interval must last at least this many frames
    floor_clearance_m: float = 0.03  # an object whose bottom is below this rests on the floor: no support
    margin_m: float = 0.10  # the support's top extends this far beyond the object's footprint on each side
    thickness_m: float | None = None  # None: the box reaches down to the floor (z = 0); else a slab
    merge_height_m: float = 0.03  # resting intervals whose tops are this close and footprints overlap merge
    fps: float = 30.0
    footprint_band_m: float = 0.01  # vertices this close above the bottom form the footprint
    # A hand grasping an object that still sits on its support: a still run (>= min_frames) with at least
    # min_untouched_frames untouched frames rests for its whole length, touched frames included.
    # False: only still and untouched frames rest.
    touched_rest: bool = True
    min_untouched_frames: int = 3

    def to_dict(self) -> dict:
        return asdict(self)


@dataclass
class InferredSupport:
    """An axis-aligned static box (identity orientation) the object rests on."""

    center: np.ndarray  # (3,) world position of the box centre
    half_extents: np.ndarray  # (3,) half sizes along world x, y, z
    top_z: float
    intervals: list[tuple[int, int]] = field(default_factory=list)  # inclusive frame ranges resting on it

    def box_mesh(self) -> tuple[np.ndarray, np.ndarray]:
        """(8, 3) float64 vertices in the box's local frame (centred at 0), (12, 3) int32 outward triangles."""
        signs = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], dtype=np.float64)
        v = signs * np.asarray(self.half_extents, dtype=np.float64)
        # vertex id = 4 * (x > 0) + 2 * (y > 0) + (z > 0); two triangles per face, counter-clockwise from outside
        f = np.array(
            [
                [0, 1, 3],
                [0, 3, 2],  # -x
                [4, 6, 7],
                [4, 7, 5],  # +x
                [0, 4, 5],
                [0, 5, 1],  # -y
                [2, 3, 7],
                [2, 7, 6],  # +y
                [0, 2, 6],
                [0, 6, 4],  # -z
                [1, 5, 7],
                [1, 7, 3],  # +z
            ],
            dtype=np.int32,
        )
        return v, f


def _check_traj(obj_pos: np.ndarray, obj_quat: np.ndarray, touched: np.ndarray) -> tuple[np.ndarray, ...]:
    p = np.asarray(obj_pos, dtype=np.float64)
    q = np.asarray(obj_quat, dtype=np.float64)
    t = np.asarray(touched, dtype=bool).reshape(-1)
    T = p.shape[0] if p.ndim == 2 else -1
    if p.ndim != 2 or p.shape[1] != 3 or q.shape != (T, 4) or t.shape != (T,):
        raise InputError(
            None, "obj_pos/obj_quat/touched", f"shapes {p.shape}, {q.shape}, {t.shape}", "(T, 3), (T, 4) and (T,)"
        )
    return p, q, t


def _speeds(p: np.ndarray, q: np.ndarray, fps: float) -> tuple[np.ndarray, np.ndarray]:
    """(T,) linear and angular speed by central differences (one-sided at the ends)."""
    T = len(p)
    if T < 2:
        return np.zeros(T), np.zeros(T)
    v = np.linalg.norm(np.gradient(p, axis=0), axis=1) * fps
    step = quat_angle(q[:-1], q[1:]) * fps  # (T-1,) between consecutive frames
    w = np.empty(T)
    w[0], w[-1] = step[0], step[-1]
    if T > 2:
        w[1:-1] = quat_angle(q[:-2], q[2:]) * fps / 2.0
    return v, w


def _runs(mask: np.ndarray, min_len: int) -> list[tuple[int, int]]:
    """Inclusive [start, end] of the runs of True at least ``min_len`` long."""
    dx = np.diff(np.concatenate([[0], mask.astype(np.int8), [0]]))
    starts, ends = np.flatnonzero(dx == 1), np.flatnonzero(dx == -1)
    return [(int(s), int(e) - 1) for s, e in zip(starts, ends, strict=False) if e - s >= max(min_len, 1)]


def resting_intervals(
    obj_pos: np.ndarray, obj_quat: np.ndarray, touched: np.ndarray, params: SupportParams = SupportParams()
) -> list[tuple[int, int]]:
    """Inclusive frame ranges where the object is still (linear and angular speed) and untouched.

    ``obj_pos`` (T, 3), ``obj_quat`` (T, 4) wxyz, ``touched`` (T,) bool. Runs shorter than
    ``params.min_frames`` are dropped. With ``params.touched_rest`` a still run that holds at least
    ``min_untouched_frames`` untouched frames is kept whole, touched frames included (the object is grasped
    but has not left its support yet); a run that is touched throughout (held still in the air) never rests.
    Ordered by start frame.
    """
    p, q, t = _check_traj(obj_pos, obj_quat, touched)
    v, w = _speeds(p, q, params.fps)
    still = (v < params.still_speed_m_s) & (w < params.still_ang_rad_s)
    if not params.touched_rest:
        return _runs(still & ~t, params.min_frames)
    need = max(int(params.min_untouched_frames), 1)
    return [(s, e) for s, e in _runs(still, params.min_frames) if np.count_nonzero(~t[s : e + 1]) >= need]


def _rest_geometry(verts: np.ndarray, p: np.ndarray, q: np.ndarray, band: float) -> tuple[float, np.ndarray]:
    """Bottom z (median over frames of the lowest posed vertex) and xy footprint [xmin, ymin, xmax, ymax]
    (union over frames of the bounding rectangle of the vertices within ``band`` above that frame's lowest)."""
    bottoms, lo, hi = [], np.full(2, np.inf), np.full(2, -np.inf)
    for a in range(0, len(p), _FRAME_CHUNK):
        R = quat_to_matrix(q[a : a + _FRAME_CHUNK])  # (n, 3, 3)
        w = np.einsum("nij,vj->nvi", R, verts) + p[a : a + _FRAME_CHUNK, None]  # (n, V, 3)
        zmin = w[..., 2].min(axis=1)  # (n,)
        bottoms.append(zmin)
        near = w[..., 2] <= zmin[:, None] + band  # (n, V)
        xy = w[..., :2]
        lo = np.minimum(lo, np.where(near[..., None], xy, np.inf).min(axis=(0, 1)))
        hi = np.maximum(hi, np.where(near[..., None], xy, -np.inf).max(axis=(0, 1)))
    return float(np.median(np.concatenate(bottoms))), np.concatenate([lo, hi])


def _overlap(a: np.ndarray, b: np.ndarray) -> bool:
    """Do two rectangles [xmin, ymin, xmax, ymax] overlap (touching counts)?"""
    return bool(a[0] <= b[2] and b[0] <= a[2] and a[1] <= b[3] and b[1] <= a[3])


def infer_supports(
    vertices: np.ndarray,
    faces: np.ndarray,
    obj_pos: np.ndarray,
    obj_quat: np.ndarray,
    touched: np.ndarray,
    params: SupportParams = SupportParams(),
) -> list[InferredSupport]:
    """Static boxes under the object wherever it rests above the floor.

    ``vertices`` (V, 3) / ``faces`` (F, 3) the object mesh in its local frame; ``obj_pos`` (T, 3),
    ``obj_quat`` (T, 4) wxyz; ``touched`` (T,) bool (any hand in contact). For each resting interval
    (:func:`resting_intervals`) whose bottom is above ``floor_clearance_m``: top z = the bottom, the top
    rectangle = the footprint grown by ``margin_m``, the box reaches down to z = 0 (or is a slab of
    ``thickness_m``). Intervals with tops within ``merge_height_m`` and overlapping top rectangles share one
    support (union of rectangles; top = the lowest of the merged tops, so that no resting object sinks into
    it). Ordered by first interval.
    """
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces)
    if v.ndim != 2 or v.shape[1] != 3 or len(v) == 0:
        raise InputError(None, "vertices", f"shape {v.shape}", "(V, 3) with V > 0")
    if f.ndim != 2 or f.shape[1] != 3:
        raise InputError(None, "faces", f"shape {f.shape}", "(F, 3)")
    p, q, t = _check_traj(obj_pos, obj_quat, touched)
    groups: list[dict] = []  # {"top": float, "rect": (4,), "intervals": [...]}, in order of first interval
    for s, e in resting_intervals(p, q, t, params):
        bottom, foot = _rest_geometry(v, p[s : e + 1], q[s : e + 1], params.footprint_band_m)
        if bottom <= params.floor_clearance_m:
            continue
        rect = foot + np.array([-1.0, -1.0, 1.0, 1.0]) * params.margin_m
        groups.append({"top": bottom, "rect": rect, "intervals": [(s, e)]})
    merged = True
    while merged:  # transitive merge; small lists
        merged = False
        for i in range(len(groups)):
            for j in range(i + 1, len(groups)):
                a, b = groups[i], groups[j]
                if abs(a["top"] - b["top"]) <= params.merge_height_m and _overlap(a["rect"], b["rect"]):
                    a["top"] = min(a["top"], b["top"])
                    a["rect"] = np.concatenate(
                        [np.minimum(a["rect"][:2], b["rect"][:2]), np.maximum(a["rect"][2:], b["rect"][2:])]
                    )
                    a["intervals"] = sorted(a["intervals"] + b["intervals"])
                    del groups[j]
                    merged = True
                    break
            if merged:
                break
    out = []
    for g in sorted(groups, key=lambda g: g["intervals"][0][0]):
        top = float(g["top"])
        base = 0.0 if params.thickness_m is None else top - float(params.thickness_m)
        x0, y0, x1, y1 = g["rect"]
        center = np.array([(x0 + x1) / 2.0, (y0 + y1) / 2.0, (top + base) / 2.0])
        half = np.array([(x1 - x0) / 2.0, (y1 - y0) / 2.0, (top - base) / 2.0])
        out.append(InferredSupport(center=center, half_extents=half, top_z=top, intervals=list(g["intervals"])))
    return out
