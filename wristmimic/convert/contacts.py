"""Per-body contact labels from geometry, the first contact frame per hand and the contact window.

Recipe (after InterAct's, ``omomo-intermimic.md`` §2.4, with the humanoid's own collision geoms in place of
SMPL-X surface vertices): sample points on every humanoid geom surface, pose them by forward kinematics,
express them in each object's local frame and take the nearest of the object's surface samples
(``cKDTree`` built once per object). Per frame and body the minimum distance gives the label:
``1`` contact (< ``contact_m``), ``-1`` must-not-touch (> ``no_touch_m``), ``0`` otherwise; a foot that
stands on the ground is never ``-1``. The contact window is ``[t_c - t_b, t_c + t_a]`` around the first
contact frame ``t_c`` of the grasping hand(s) (paper, "contact window"; t_b = 10, t_a = 15).

Shapes: T frames, B humanoid bodies (MuJoCo body id - 1, world excluded), G model geoms, O objects.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import mujoco
import numpy as np
from scipy.spatial import cKDTree

from wristmimic.errors import InputError
from wristmimic.humanoid.kinematics import FKResult, forward_kinematics
from wristmimic.rotations import quat_to_matrix

# Distances beyond no_touch_m + this margin are not resolved: they are reported as +inf.
REPORT_MARGIN_M = 0.05
# Upper bound on posed body points handled at once (memory: ~10 arrays of this many float64 triples).
_CHUNK_POINTS = 1_000_000
# Coarse-to-fine search: a coarse subset of the object points (one per voxel) bounds every body's distance
# from above; only points that can beat that bound are looked up among all object points.
_COARSE_VOXEL_M = 0.01
_GOLDEN_ANGLE = np.pi * (3.0 - np.sqrt(5.0))

_G = mujoco.mjtGeom


@dataclass(frozen=True)
class ContactParams:
    """Thresholds and sampling of the geometric contact labels (metres, frames)."""

    contact_m: float = 0.02  # label 1 when a body's geoms come closer than this to the object surface
    no_touch_m: float = 0.10  # label -1 ("must not touch") when every point of the body is farther than this
    point_spacing_m: float = 0.01  # spacing of the sample points on each body geom's surface
    object_points: int = 50000  # area-weighted surface samples of each object mesh (plus its vertices)
    seed: int = 0
    min_run: int = 3  # first contact frame = first frame of a run of >= min_run contact frames
    t_b: int = 10  # contact window: frames before first contact
    t_a: int = 15  # frames after
    foot_ground_m: float = 0.10  # a foot whose lowest point is at most this high is on the ground (never -1)

    def to_dict(self) -> dict:
        return asdict(self)


# ----------------------------------------------------------------------------------------------------------
# sample points on geom surfaces


def _fibonacci_sphere(n: int) -> np.ndarray:
    """(n, 3) nearly uniform unit vectors (Fibonacci lattice), deterministic."""
    i = np.arange(n, dtype=np.float64)
    z = 1.0 - (2.0 * i + 1.0) / n
    r = np.sqrt(np.maximum(1.0 - z * z, 0.0))
    phi = i * _GOLDEN_ANGLE
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=-1)


def _disk(n: int, radius: float) -> np.ndarray:
    """(n, 2) nearly uniform points in a disk (Vogel spiral)."""
    i = np.arange(n, dtype=np.float64)
    rr = radius * np.sqrt((i + 0.5) / n)
    phi = i * _GOLDEN_ANGLE
    return np.stack([rr * np.cos(phi), rr * np.sin(phi)], axis=-1)


def _side(radius: float, half: float, h: float) -> np.ndarray:
    """Rings on the side of a z-aligned cylinder of the given radius and half-length (ends included)."""
    nz = max(int(np.ceil(2.0 * half / h)), 1) + 1
    nt = max(int(np.ceil(2.0 * np.pi * radius / h)), 6)
    z = np.linspace(-half, half, nz)
    th = np.arange(nt) * (2.0 * np.pi / nt)
    zz, tt = np.meshgrid(z, th, indexing="ij")
    return np.stack([radius * np.cos(tt), radius * np.sin(tt), zz], axis=-1).reshape(-1, 3)


def _box_faces(half: np.ndarray, h: float) -> np.ndarray:
    """Grids on the six faces of a box with the given half sizes (edges included, duplicates removed)."""
    out = []
    for ax in range(3):
        u, v = [a for a in range(3) if a != ax]
        nu = max(int(np.ceil(2.0 * half[u] / h)), 1) + 1
        nv = max(int(np.ceil(2.0 * half[v] / h)), 1) + 1
        gu, gv = np.meshgrid(np.linspace(-half[u], half[u], nu), np.linspace(-half[v], half[v], nv), indexing="ij")
        for s in (-1.0, 1.0):
            p = np.empty((gu.size, 3))
            p[:, ax] = s * half[ax]
            p[:, u] = gu.ravel()
            p[:, v] = gv.ravel()
            out.append(p)
    return np.unique(np.concatenate(out), axis=0)


def _shape_points(gtype: int, size: np.ndarray, h: float) -> np.ndarray | None:
    """Surface points of one primitive in its own frame, or None for an unsupported type."""
    if gtype == _G.mjGEOM_SPHERE:
        r = size[0]
        return r * _fibonacci_sphere(max(int(np.ceil(4.0 * np.pi * r * r / (h * h))), 12))
    if gtype == _G.mjGEOM_CAPSULE:
        r, half = size[0], size[1]
        caps = r * _fibonacci_sphere(max(int(np.ceil(4.0 * np.pi * r * r / (h * h))), 12))
        caps[:, 2] += np.where(caps[:, 2] >= 0.0, half, -half)
        return np.concatenate([caps, _side(r, half, h)])
    if gtype == _G.mjGEOM_CYLINDER:
        r, half = size[0], size[1]
        d = _disk(max(int(np.ceil(np.pi * r * r / (h * h))), 1), r)
        caps = [np.column_stack([d, np.full(len(d), s * half)]) for s in (-1.0, 1.0)]
        return np.concatenate([_side(r, half, h), *caps])
    if gtype == _G.mjGEOM_BOX:
        return _box_faces(np.asarray(size[:3], dtype=np.float64), h)
    if gtype == _G.mjGEOM_ELLIPSOID:
        a, b, c = size[:3]
        p = 1.6075  # Knud Thomsen's approximation of the ellipsoid's area
        area = 4.0 * np.pi * (((a * b) ** p + (a * c) ** p + (b * c) ** p) / 3.0) ** (1.0 / p)
        return _fibonacci_sphere(max(int(np.ceil(area / (h * h))), 12)) * np.array([a, b, c])
    return None


def geom_surface_points(model: mujoco.MjModel, spacing: float) -> tuple[np.ndarray, np.ndarray]:
    """Points on the surface of every non-world geom, in each geom's local frame.

    Returns ``(points (P, 3) float64, geom_index (P,) int32)`` with the MuJoCo geom id of each point, sorted
    by geom id. Spheres, capsules, cylinders, boxes and ellipsoids are supported (deterministic lattices,
    about one point per ``spacing``² of area); any other type on a non-world body raises :class:`InputError`.
    """
    if not spacing > 0:
        raise InputError(None, "point_spacing_m", f"{spacing}", "a positive spacing")
    pts, idx = [], []
    for g in range(model.ngeom):
        if model.geom_bodyid[g] == 0:
            continue
        p = _shape_points(int(model.geom_type[g]), model.geom_size[g], float(spacing))
        if p is None:
            name = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_GEOM, g) or f"#{g}"
            raise InputError(
                None,
                f"geom {name}",
                f"unsupported geom type {_G(model.geom_type[g]).name}",
                "sphere, capsule, cylinder, box or ellipsoid",
            )
        pts.append(p)
        idx.append(np.full(len(p), g, dtype=np.int32))
    if not pts:
        return np.zeros((0, 3)), np.zeros(0, dtype=np.int32)
    return np.concatenate(pts), np.concatenate(idx)


# ----------------------------------------------------------------------------------------------------------
# object surface samples


@dataclass(frozen=True)
class _ObjectTree:
    tree: cKDTree  # all points: vertices + surface samples
    coarse: cKDTree  # a subset of them, one per voxel of _COARSE_VOXEL_M
    cover: float  # every point of `tree` lies within this distance of a point of `coarse`
    normals: np.ndarray | None  # (N, 3) outward normals of the tree points when the mesh is a closed solid
    lo: np.ndarray  # (3,) local AABB
    hi: np.ndarray


def _object_tree(vertices: np.ndarray, faces: np.ndarray, params: ContactParams, k: int) -> _ObjectTree:
    """KD-tree over the mesh vertices and area-weighted surface samples, in the object's local frame."""
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    if v.ndim != 2 or v.shape[1] != 3 or len(v) == 0:
        raise InputError(None, f"objects[{k}].vertices", f"shape {v.shape}", "(V, 3) with V > 0")
    if f.ndim != 2 or f.shape[1] != 3 or (f.size and (f.min() < 0 or f.max() >= len(v))):
        raise InputError(
            None, f"objects[{k}].faces", f"shape {f.shape} or out-of-range indices", "(F, 3) vertex indices"
        )
    tri = v[f]  # (F, 3, 3)
    cross = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    area2 = np.linalg.norm(cross, axis=1)
    points, normals = [v], None
    if len(f) and area2.sum() > 0 and params.object_points > 0:
        rng = np.random.default_rng(params.seed + k)
        fi = rng.choice(len(f), size=params.object_points, p=area2 / area2.sum())
        r1, r2 = rng.random(params.object_points), rng.random(params.object_points)
        s = np.sqrt(r1)
        bary = np.stack([1.0 - s, s * (1.0 - r2), s * r2], axis=-1)
        points.append(np.einsum("nk,nkd->nd", bary, tri[fi]))
        solid = _closed_orientation(v, f)
        if solid != 0:
            fn = solid * cross / np.maximum(area2, 1e-30)[:, None]
            vn = np.zeros_like(v)
            np.add.at(vn, f.reshape(-1), np.repeat(solid * cross, 3, axis=0))  # area-weighted vertex normals
            vn /= np.maximum(np.linalg.norm(vn, axis=1, keepdims=True), 1e-30)
            normals = np.concatenate([vn, fn[fi]])
    allp = np.concatenate(points)
    _, keep = np.unique(np.floor(allp / _COARSE_VOXEL_M).astype(np.int64), axis=0, return_index=True)
    coarse = cKDTree(allp[np.sort(keep)])
    cover = float(coarse.query(allp, k=1, workers=-1)[0].max())
    return _ObjectTree(cKDTree(allp), coarse, cover, normals, allp.min(0), allp.max(0))


def _closed_orientation(vertices: np.ndarray, faces: np.ndarray) -> int:
    """+1 (outward) / -1 (inward) if the mesh is a closed, consistently wound surface, else 0.

    Vertices at the same position are merged first (OBJ seams). Closed: every undirected edge is used by
    exactly two faces, once in each direction; the sign is that of the enclosed volume.
    """
    _, inv = np.unique(vertices, axis=0, return_inverse=True)
    f = inv.reshape(-1)[faces]
    d = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])  # directed edges
    if np.any(d[:, 0] == d[:, 1]):
        return 0
    _, dcount = np.unique(d, axis=0, return_counts=True)
    _, ucount = np.unique(np.sort(d, axis=1), axis=0, return_counts=True)
    if not (np.all(dcount == 1) and np.all(ucount == 2)):
        return 0
    tri = vertices[faces]
    vol = np.einsum("ni,ni->", tri[:, 0], np.cross(tri[:, 1], tri[:, 2])) / 6.0
    return 1 if vol > 0 else (-1 if vol < 0 else 0)


# ----------------------------------------------------------------------------------------------------------
# distances


def _fk(model: mujoco.MjModel, qpos: np.ndarray, fk: FKResult | None) -> FKResult:
    qpos = np.asarray(qpos, dtype=np.float64)
    if qpos.ndim != 2 or qpos.shape[1] != model.nq:
        raise InputError(None, "qpos", f"shape {qpos.shape}", f"(T, {model.nq})")
    if fk is None or fk.geom_pos is None:
        return forward_kinematics(model, qpos, geoms=True)
    if fk.geom_pos.shape != (qpos.shape[0], model.ngeom, 3):
        raise InputError(None, "fk", f"geom_pos shape {fk.geom_pos.shape}", f"({qpos.shape[0]}, {model.ngeom}, 3)")
    return fk


def body_object_distance(
    model: mujoco.MjModel,
    qpos: np.ndarray,
    objects: list[tuple[np.ndarray, np.ndarray]],
    obj_pos: np.ndarray,
    obj_quat: np.ndarray,
    params: ContactParams = ContactParams(),
    *,
    fk: FKResult | None = None,
) -> np.ndarray:
    """Per frame and body, the minimum distance from the body's geom surfaces to any object's surface.

    ``qpos`` (T, nq); ``objects`` O pairs (vertices (V, 3), faces (F, 3)) in the object's local frame;
    ``obj_pos`` (T, O, 3), ``obj_quat`` (T, O, 4) wxyz world poses. ``fk`` may pass a precomputed
    :func:`forward_kinematics` result (with geoms). Returns (T, B) float32 metres.

    Distances are point-to-sample distances: each object is represented by its vertices plus
    ``params.object_points`` area-weighted surface samples (seeded), so they overestimate the true distance
    by at most about half the sample spacing. Beyond ``no_touch_m + REPORT_MARGIN_M`` the value is ``inf``
    (not resolved); a body without geoms is ``inf``. Body points inside a closed, consistently wound object
    mesh count as distance 0 (sign of the nearest sample's outward normal); for open meshes (most scanned
    meshes) this test is skipped, which matters only for a body entirely buried in an object: a body that
    crosses the surface has points within about half the point spacing of it anyway.
    """
    fk = _fk(model, qpos, fk)
    T, B = qpos.shape[0], model.nbody - 1
    obj_pos = np.asarray(obj_pos, dtype=np.float64)
    obj_quat = np.asarray(obj_quat, dtype=np.float64)
    O = len(objects)
    if obj_pos.shape != (T, O, 3) or obj_quat.shape != (T, O, 4):
        raise InputError(
            None, "obj_pos/obj_quat", f"shapes {obj_pos.shape}, {obj_quat.shape}", f"({T}, {O}, 3) and ({T}, {O}, 4)"
        )
    out = np.full((T, B), np.inf, dtype=np.float64)
    pts, gidx = geom_surface_points(model, params.point_spacing_m)
    if len(pts) == 0 or O == 0 or T == 0:
        return out.astype(np.float32)
    geoms = np.unique(gidx)  # geoms with points, ascending; points are grouped by geom
    first = np.searchsorted(gidx, geoms)
    count = np.diff(np.append(first, len(gidx)))
    body_of = model.geom_bodyid[geoms].astype(np.int64) - 1  # (Gp,)
    gl = pts  # local points, grouped by geom
    rad = np.array([np.linalg.norm(gl[a : a + n], axis=1).max() for a, n in zip(first, count, strict=False)])  # (Gp,)
    gpos = fk.geom_pos[:, geoms]  # (T, Gp, 3)
    gmat = fk.geom_mat[:, geoms]  # (T, Gp, 3, 3)
    bound = params.no_touch_m + REPORT_MARGIN_M
    flat = out.reshape(-1)
    for k, (verts, faces) in enumerate(objects):
        ot = _object_tree(verts, faces, params, k)
        Ro = quat_to_matrix(obj_quat[:, k])  # (T, 3, 3)
        RoT = np.swapaxes(Ro, -1, -2)
        rel_R = RoT[:, None] @ gmat  # (T, Gp, 3, 3): geom frame -> object frame
        rel_t = np.einsum("tij,tgj->tgi", RoT, gpos - obj_pos[:, k, None])  # (T, Gp, 3)
        # cull (frame, geom) pairs whose bounding sphere is farther than `bound` from the object's AABB
        gap = np.maximum(np.maximum(ot.lo - rel_t, rel_t - ot.hi), 0.0)
        tsel, gsel = np.nonzero(np.linalg.norm(gap, axis=-1) - rad[None] < bound)
        if len(tsel) == 0:
            continue
        n_pair = count[gsel]
        # chunks of whole frames, about _CHUNK_POINTS points each (a body's points stay in one chunk)
        frame_pts = np.bincount(tsel, weights=n_pair, minlength=T)
        chunk_of_frame = (np.cumsum(frame_pts) - frame_pts) // _CHUNK_POINTS
        chunk = chunk_of_frame[tsel]
        cuts = np.flatnonzero(np.diff(chunk)) + 1
        for lo_i, hi_i in zip(np.r_[0, cuts], np.r_[cuts, len(tsel)], strict=False):
            ts, gs, ns = tsel[lo_i:hi_i], gsel[lo_i:hi_i], n_pair[lo_i:hi_i]
            pair = np.repeat(np.arange(len(ts)), ns)  # pair of every point
            start = np.cumsum(ns) - ns
            pidx = first[gs][pair] + (np.arange(len(pair)) - start[pair])  # point index into gl
            p = np.einsum("nij,nj->ni", rel_R[ts, gs][pair], gl[pidx]) + rel_t[ts, gs][pair]
            key = ts[pair] * B + body_of[gs][pair]  # flat (frame, body) of every point
            _nearest(ot, p, key, flat, bound)
    return out.astype(np.float32)


def _nearest(ot: _ObjectTree, p: np.ndarray, key: np.ndarray, flat: np.ndarray, bound: float) -> None:
    """Lower ``flat[key]`` to the distance of each point ``p`` (N, 3) (object frame) to the object points.

    Exact w.r.t. the full point set: the coarse distance ``dc`` of every point bounds its (frame, body)
    minimum ``U`` from above, and a point can only reach below ``U`` if ``dc - cover <= U``; those points are
    looked up in the full tree with a bound of about ``U`` (in bins), which keeps the searches short.
    """
    dc = ot.coarse.query(p, k=1, distance_upper_bound=bound + ot.cover, workers=-1)[0]
    upper = flat.copy()  # includes the objects done before
    np.minimum.at(upper, key, dc)
    u = upper[key]
    cand = np.flatnonzero(np.isfinite(dc) & (dc - ot.cover <= u))
    d = np.full(len(p), np.inf)
    nn = np.zeros(len(p), dtype=np.int64)
    edges = np.array([0.005, 0.01, 0.02, 0.04, 0.08, np.inf])
    bins = np.searchsorted(edges, u[cand])
    for b in np.unique(bins):
        sel = cand[bins == b]
        ub = min(float(edges[b]), bound) * (1.0 + 1e-9) + 1e-12
        d[sel], nn[sel] = ot.tree.query(p[sel], k=1, distance_upper_bound=ub, workers=-1)
    if ot.normals is not None:
        d[_inside(ot, p, d, nn, ~np.isfinite(dc))] = 0.0
    np.minimum.at(flat, key, d)


def _inside(ot: _ObjectTree, p: np.ndarray, d: np.ndarray, nn: np.ndarray, far: np.ndarray) -> np.ndarray:
    """(N,) bool: points ``p`` inside a closed mesh (distance 0).

    A point counts as inside when it lies within the object's bounding box and behind the outward normals of
    the majority of its 5 nearest surface samples. The bounding box and the vote matter near edges, where
    the single nearest sample can sit on the next face over and point the wrong way. ``d`` (looked-up
    distances, inf where not looked up) and ``far`` (beyond the query bound) choose which points to test:
    near ones, and far ones inside the bounding box (a body buried deep inside the object).
    """
    in_box = np.all((p >= ot.lo) & (p <= ot.hi), axis=1)
    cand = in_box & (np.isfinite(d) | far)
    out = np.zeros(len(p), dtype=bool)
    if not cand.any():
        return out
    k = min(5, len(ot.tree.data))
    _, idx = ot.tree.query(p[cand], k=k, workers=-1)
    idx = idx.reshape(len(idx), k)
    behind = np.einsum("nki,nki->nk", p[cand][:, None] - ot.tree.data[idx], ot.normals[idx]) < 0.0
    out[cand] = behind.sum(axis=1) * 2 > k
    return out


def body_lowest_z(
    model: mujoco.MjModel,
    qpos: np.ndarray,
    body_ids: np.ndarray,
    params: ContactParams = ContactParams(),
    *,
    fk: FKResult | None = None,
) -> np.ndarray:
    """(T, len(body_ids)) lowest world z over the geom surface points of each body (``inf`` if it has none).

    ``qpos`` (T, nq); ``body_ids`` humanoid body indices (MuJoCo id - 1). Points as in
    :func:`geom_surface_points` with ``params.point_spacing_m``.
    """
    fk = _fk(model, qpos, fk)
    body_ids = np.asarray(body_ids, dtype=np.int64).reshape(-1)
    pts, gidx = geom_surface_points(model, params.point_spacing_m)
    T = qpos.shape[0]
    out = np.full((T, len(body_ids)), np.inf)
    pbody = model.geom_bodyid[gidx] - 1
    for i, b in enumerate(body_ids):
        sel = pbody == b
        if not sel.any():
            continue
        g = gidx[sel]
        z = fk.geom_pos[:, g, 2] + np.einsum("tpj,pj->tp", fk.geom_mat[:, g, 2, :], pts[sel])
        out[:, i] = z.min(axis=1)
    return out


# ----------------------------------------------------------------------------------------------------------
# labels, hands, first contact, window


def labels_from_distance(
    dist: np.ndarray,
    params: ContactParams = ContactParams(),
    *,
    feet: np.ndarray | None = None,
    feet_height: np.ndarray | None = None,
) -> np.ndarray:
    """(T, B) distances -> (T, B) int8 labels: 1 if d < contact_m, -1 if d > no_touch_m, else 0.

    InterAct's foot rule: with ``feet`` (K,) body indices and ``feet_height`` (T, K) (lowest point z of
    each foot, :func:`body_lowest_z`), a foot at most ``foot_ground_m`` above the floor is 0 instead of -1.
    """
    dist = np.asarray(dist)
    if dist.ndim != 2:
        raise InputError(None, "dist", f"shape {dist.shape}", "(T, B)")
    lab = np.where(dist < params.contact_m, 1, np.where(dist > params.no_touch_m, -1, 0)).astype(np.int8)
    if (feet is None) != (feet_height is None):
        raise InputError(None, "feet/feet_height", "only one of them given", "both or neither")
    if feet is not None:
        feet = np.asarray(feet, dtype=np.int64).reshape(-1)
        fh = np.asarray(feet_height, dtype=np.float64)
        if fh.shape != (dist.shape[0], len(feet)):
            raise InputError(None, "feet_height", f"shape {fh.shape}", f"({dist.shape[0]}, {len(feet)})")
        sub = lab[:, feet]
        sub[(sub == -1) & (fh <= params.foot_ground_m)] = 0
        lab[:, feet] = sub
    return lab


def hand_contact(labels: np.ndarray, left_hand: np.ndarray, right_hand: np.ndarray) -> np.ndarray:
    """(T, 2) bool [left, right]: any body of the hand labelled 1 in (T, B) ``labels``."""
    labels = np.asarray(labels)
    left = (labels[:, np.asarray(left_hand, dtype=np.int64)] == 1).any(axis=1)
    right = (labels[:, np.asarray(right_hand, dtype=np.int64)] == 1).any(axis=1)
    return np.stack([left, right], axis=1)


def first_contact_frames(hand: np.ndarray, min_run: int) -> np.ndarray:
    """(2,) int32: first frame of the first run of >= ``min_run`` consecutive True per hand of (T, 2); -1 if none."""
    hand = np.asarray(hand, dtype=bool)
    if hand.ndim != 2:
        raise InputError(None, "hand", f"shape {hand.shape}", "(T, H)")
    out = np.full(hand.shape[1], -1, dtype=np.int32)
    for h in range(hand.shape[1]):
        x = np.concatenate([[0], hand[:, h].astype(np.int8), [0]])
        dx = np.diff(x)
        starts, ends = np.flatnonzero(dx == 1), np.flatnonzero(dx == -1)  # run = [start, end)
        ok = np.flatnonzero(ends - starts >= max(int(min_run), 1))
        if len(ok):
            out[h] = starts[ok[0]]
    return out


def contact_window(first: np.ndarray, num_frames: int, t_b: int, t_a: int) -> np.ndarray:
    """(2,) int32 inclusive [start, end] = [t_c - t_b, t_c + t_a] clipped to [0, num_frames - 1].

    ``t_c`` is the earliest first-contact frame over the hands that have one; [-1, -1] if none has.
    """
    first = np.asarray(first).reshape(-1)
    have = first[first >= 0]
    if len(have) == 0 or num_frames <= 0:
        return np.array([-1, -1], dtype=np.int32)
    tc = int(have.min())
    return np.array([max(tc - t_b, 0), min(tc + t_a, num_frames - 1)], dtype=np.int32)


def label_agreement(a: np.ndarray, b: np.ndarray, bodies: np.ndarray | None = None) -> dict:
    """Compare two (T, B) label arrays (optionally only the columns ``bodies``).

    Returns a JSON-friendly dict: ``n`` labels compared, ``agreement`` (fraction equal), ``confusion``
    {"<a>-><b>": count} for every pair of values in {-1, 0, 1}, and contact (label 1) agreement with b as
    the reference: ``contact_precision`` = P(b == 1 | a == 1), ``contact_recall`` = P(a == 1 | b == 1),
    ``contact_f1`` (None where undefined), ``contact_a``/``contact_b`` counts.
    """
    a = np.asarray(a)
    b = np.asarray(b)
    if a.shape != b.shape or a.ndim != 2:
        raise InputError(None, "labels", f"shapes {a.shape} and {b.shape}", "two equal (T, B) arrays")
    if bodies is not None:
        cols = np.asarray(bodies, dtype=np.int64).reshape(-1)
        a, b = a[:, cols], b[:, cols]
    a = a.reshape(-1).astype(np.int64)
    b = b.reshape(-1).astype(np.int64)
    n = int(a.size)
    conf = {f"{i}->{j}": int(np.count_nonzero((a == i) & (b == j))) for i in (-1, 0, 1) for j in (-1, 0, 1)}
    ca, cb = int(np.count_nonzero(a == 1)), int(np.count_nonzero(b == 1))
    both = conf["1->1"]
    prec = both / ca if ca else None
    rec = both / cb if cb else None
    f1 = 2 * prec * rec / (prec + rec) if prec is not None and rec is not None and prec + rec > 0 else None
    return {
        "n": n,
        "agreement": float(np.count_nonzero(a == b) / n) if n else None,
        "confusion": conf,
        "contact_a": ca,
        "contact_b": cb,
        "contact_precision": prec,
        "contact_recall": rec,
        "contact_f1": f1,
    }
