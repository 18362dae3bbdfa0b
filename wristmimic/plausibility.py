"""Physical plausibility of a canonical sequence (a reference or an exported rollout), from MuJoCo geometry.

The sequence's scene is built once (:func:`wristmimic.scene.build_scene`, without visual meshes); for every
frame the humanoid (root pose, hinge angles) and the dynamic objects are posed, ``mj_kinematics`` and
``mj_collision`` run, and the contacts are grouped by geom pair. Geom margins are raised for this analysis only
(nothing is simulated), so one collision pass also returns the distances the metrics need: hand geoms see
dynamic objects up to ``gap_max_m``, feet see the floor up to ``foot_contact_m``, dynamic objects see anything
within ``touch_m``. A contact distance below zero is a penetration depth.

Metrics (definitions, units and thresholds: ``docs/plausibility.md``):

- penetration depth per frame: hand-object (hand bodies vs dynamic objects), body-floor (any humanoid body vs
  the floor), object-support (dynamic objects vs static objects and the floor);
- foot skating: horizontal speed of the material point of a foot body nearest the floor, while that point is
  within ``foot_contact_m`` of the floor;
- object float: a dynamic object's centre moves faster than ``float_speed_m_s`` while nothing (no humanoid body,
  support, floor or other dynamic object) is within ``touch_m`` of it;
- hand-object gap: distance from each hand body whose ``contacts/labels`` is 1 to the nearest dynamic object;
- jerk: third finite difference of body and object-centre positions.

>>> with open_dataset("bench/omomo.h5") as ds:
...     plausibility(ds, "sub2_largetable_000")["hand_object_depth_max_mm"]
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import asdict, dataclass, field

import mujoco
import numpy as np

from wristmimic.format.reader import Dataset
from wristmimic.rotations import quat_rotate
from wristmimic.scene import SceneConfig, build_scene

PENETRATION_GROUPS = ("hand_object", "body_floor", "object_support")
FOOT_SEARCH_M = 0.5
"""Foot heights above the floor are resolved up to this (higher feet read as this)."""


@dataclass(frozen=True)
class PlausibilityParams:
    """Thresholds and search distances (SI units). ``docs/plausibility.md`` gives the reason for each."""

    penetration_m: float = 0.005
    """A frame counts as penetrating when the deepest contact of a group is deeper than this."""
    foot_contact_m: float = 0.02
    """A foot body is in floor contact when its geoms come within this of the floor (or penetrate it)."""
    skate_speed_m_s: float = 0.10
    """A foot in floor contact skates when its contact point moves horizontally faster than this."""
    touch_m: float = 0.02
    """Object float: something touches a dynamic object when it comes within this distance."""
    float_speed_m_s: float = 0.05
    """Object float: a dynamic object moves when its centre is faster than this."""
    gap_m: float = 0.02
    """A hand body labelled in contact is separated when its distance to the nearest object exceeds this."""
    gap_max_m: float = 0.2
    """Gaps are searched up to this distance; farther ones are reported as this value."""
    jerk_m_s3: float = 9.81 * 30.0
    """A body (or object) is jerky at a frame when its jerk exceeds this (m/s^3): its acceleration changes by
    more than 1 g within one 30 fps frame."""

    def to_dict(self) -> dict[str, float]:
        return asdict(self)


@dataclass
class PlausibilityFrames:
    """Per-frame measurements of one sequence (T frames, B bodies, F foot bodies, H hand bodies, O dynamic
    objects)."""

    sequence_id: str
    fps: float
    params: PlausibilityParams
    depth: dict[str, np.ndarray]
    """Group -> (T,) deepest penetration (m, >= 0; 0 when nothing penetrates)."""
    foot_height: np.ndarray
    """(T, F) signed distance (m) from each foot body's geoms to the floor (negative: below it), resolved up to
    :data:`FOOT_SEARCH_M`."""
    foot_speed: np.ndarray
    """(T, F) horizontal speed (m/s) of each foot's contact point; NaN unless the foot is on the floor at the
    frame before, the frame and the frame after."""
    gap: np.ndarray
    """(T, H) distance (m, >= 0, capped at ``gap_max_m``) of each hand body to the nearest dynamic object; NaN
    where the body is not labelled in contact."""
    object_speed: np.ndarray
    """(T, O) speed of each dynamic object's centre (m/s)."""
    object_touched: np.ndarray
    """(T, O) something is within ``touch_m`` of the object."""
    body_jerk: np.ndarray
    """(T, B) jerk magnitude of each humanoid body (m/s^3); NaN at the first frame and the last two."""
    object_jerk: np.ndarray
    """(T, O) jerk magnitude of each dynamic object's centre (m/s^3); NaN as above."""
    seconds: float = 0.0
    """Time the measurement took."""
    names: dict[str, list[str]] = field(default_factory=dict)
    """Names of the feet, hand bodies and objects (columns of the (T, n) arrays)."""

    @property
    def num_frames(self) -> int:
        return len(self.body_jerk)

    @property
    def object_float(self) -> np.ndarray:
        """(T, O) the object moves and nothing touches it."""
        return (self.object_speed > self.params.float_speed_m_s) & ~self.object_touched

    def series(self) -> dict[str, np.ndarray]:
        """One (T,) float array per metric, for a viewer: depths (m), the lowest foot's height (m), the fastest
        skating foot (m/s, NaN when no foot stands), floating objects (count), the largest labelled hand gap (m,
        NaN when no hand body is labelled) and the largest body and object jerk (m/s^3)."""
        out = {f"{g}_depth_m": self.depth[g].astype(np.float64) for g in PENETRATION_GROUPS}
        out |= {
            "foot_height_m": -_nanmax(-self.foot_height, axis=1),
            "foot_skate_speed_m_s": _nanmax(self.foot_speed, axis=1),
            "object_float": self.object_float.sum(axis=1).astype(np.float64),
            "hand_gap_m": _nanmax(self.gap, axis=1),
            "body_jerk_m_s3": _nanmax(self.body_jerk, axis=1),
            "object_jerk_m_s3": _nanmax(self.object_jerk, axis=1),
        }
        return out

    def summary(self) -> dict[str, float]:
        """The metrics of the sequence as floats (NaN where a metric has nothing to measure); keys: ``frames``
        and :data:`SUMMARY_KEYS`."""
        p = self.params
        out: dict[str, float] = {"frames": float(self.num_frames)}
        for g in PENETRATION_GROUPS:
            d = self.depth[g]
            out[f"{g}_depth_max_mm"] = 1000.0 * _stat(d, np.max)
            out[f"{g}_depth_mean_mm"] = 1000.0 * _stat(d, np.mean)
            out[f"{g}_over_pct"] = _pct(d > p.penetration_m)
        low = -_nanmax(-self.foot_height, axis=1)
        out["foot_height_min_mm"] = 1000.0 * _stat(low, np.min)
        out["foot_height_median_mm"] = 1000.0 * _stat(low, np.median)
        fs = self.foot_speed[np.isfinite(self.foot_speed)]
        out["foot_stance_pct"] = 100.0 * fs.size / self.foot_speed.size if self.foot_speed.size else math.nan
        out["foot_skate_mean_cm_s"] = 100.0 * _stat(fs, np.mean)
        out["foot_skate_max_cm_s"] = 100.0 * _stat(fs, np.max)
        out["foot_skate_over_pct"] = _pct(fs > p.skate_speed_m_s)
        fl = self.object_float.any(axis=1) if self.object_float.shape[1] else np.zeros(self.num_frames, bool)
        out["object_float_frames"] = float(fl.sum())
        out["object_float_pct"] = _pct(fl) if self.object_float.shape[1] else math.nan
        gp = self.gap[np.isfinite(self.gap)]
        out["hand_gap_pairs"] = float(gp.size)
        out["hand_gap_mean_mm"] = 1000.0 * _stat(gp, np.mean)
        out["hand_gap_max_mm"] = 1000.0 * _stat(gp, np.max)
        out["hand_gap_over_pct"] = _pct(gp > p.gap_m)
        for name, j in (("body", self.body_jerk), ("object", self.object_jerk)):
            v = j[np.isfinite(j)]
            out[f"{name}_jerk_mean"] = _stat(v, np.mean)
            out[f"{name}_jerk_max"] = _stat(v, np.max)
            out[f"{name}_jerk_over_pct"] = _pct(v > p.jerk_m_s3)
        return out


SUMMARY_KEYS = (
    *(f"{g}_{s}" for g in PENETRATION_GROUPS for s in ("depth_max_mm", "depth_mean_mm", "over_pct")),
    "foot_height_min_mm",
    "foot_height_median_mm",
    "foot_stance_pct",
    "foot_skate_mean_cm_s",
    "foot_skate_max_cm_s",
    "foot_skate_over_pct",
    "object_float_frames",
    "object_float_pct",
    "hand_gap_pairs",
    "hand_gap_mean_mm",
    "hand_gap_max_mm",
    "hand_gap_over_pct",
    "body_jerk_mean",
    "body_jerk_max",
    "body_jerk_over_pct",
    "object_jerk_mean",
    "object_jerk_max",
    "object_jerk_over_pct",
)
"""Keys of :meth:`PlausibilityFrames.summary` after ``frames``, in table order."""


def _stat(v: np.ndarray, f: Callable[[np.ndarray], np.floating]) -> float:
    return float(f(v)) if v.size else math.nan


def _pct(mask: np.ndarray) -> float:
    return 100.0 * float(mask.mean()) if mask.size else math.nan


def _nanmax(a: np.ndarray, axis: int) -> np.ndarray:
    """``np.nanmax`` that gives NaN for all-NaN (or empty) rows without a warning."""
    if a.shape[axis] == 0:
        return np.full(a.shape[1 - axis], np.nan)
    filled = np.where(np.isnan(a), -np.inf, a).max(axis=axis)
    return np.where(np.isneginf(filled), np.nan, filled)


def jerk(pos: np.ndarray, fps: float) -> np.ndarray:
    """Jerk magnitude (m/s^3) of positions (T, ..., 3) by the third finite difference
    ``(x[t+2] - 3 x[t+1] + 3 x[t] - x[t-1]) * fps^3``, placed at frame t; NaN at frames 0, T-2, T-1."""
    pos = np.asarray(pos, np.float64)
    out = np.full(pos.shape[:-1], np.nan)
    if len(pos) >= 4:
        d3 = pos[3:] - 3.0 * pos[2:-1] + 3.0 * pos[1:-2] - pos[:-3]
        out[1:-2] = np.linalg.norm(d3, axis=-1) * fps**3
    return out


def _velocity(pos: np.ndarray, fps: float) -> np.ndarray:
    """Central finite difference of (T, ..., 3) positions (one-sided at the ends; zero for one frame)."""
    if len(pos) < 2:
        return np.zeros_like(pos)
    return np.gradient(np.asarray(pos, np.float64), axis=0) * fps


def measure(ds: Dataset, sequence_id: str, params: PlausibilityParams | None = None) -> PlausibilityFrames:
    """Per-frame plausibility measurements of one sequence of an open canonical file."""
    import time

    t0 = time.perf_counter()
    p = params or PlausibilityParams()
    scene = build_scene(ds, sequence_id, SceneConfig(visual_meshes=False))
    m, d = scene.model, mujoco.MjData(scene.model)
    seq = ds.sequence(sequence_id)
    fps = float(ds.attrs.get("fps", 30.0))
    root_pos, root_quat = seq.array("root_pos"), seq.array("root_quat")
    angles = seq.array("joint_angles").reshape(seq.num_frames, -1)
    obj_pos, obj_quat = seq.array("object_pos"), seq.array("object_quat")
    labels = seq.array("contacts/labels")
    roles = scene.humanoid.roles
    T, B = seq.num_frames, len(scene.body_ids)

    # geom -> humanoid body index / dynamic object index; role masks per humanoid body
    body_of = np.full(m.nbody, -1)
    body_of[scene.body_ids] = np.arange(B)
    dyn = scene.dynamic_objects
    dyn_k = [k for k, o in enumerate(scene.objects) if o.dynamic]
    obj_of_body = np.full(m.nbody, -1)
    for i, o in enumerate(dyn):
        obj_of_body[o.body_id] = i
    static_bodies = {o.body_id for o in scene.objects if not o.dynamic}
    collide = m.geom_contype != 0
    g_body = np.where(collide, body_of[m.geom_bodyid], -1)  # (G,) humanoid body index or -1
    g_obj = np.where(collide, obj_of_body[m.geom_bodyid], -1)  # (G,) dynamic object index or -1
    g_floor = np.array([mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_GEOM, g) == "floor" for g in range(m.ngeom)])
    g_static = collide & np.isin(m.geom_bodyid, list(static_bodies))
    g_support = g_floor | g_static
    hands = np.concatenate([roles["left_hand"], roles["right_hand"]]).astype(int)
    feet = np.asarray(roles["feet"], int)
    is_hand = np.zeros(B, bool)
    is_hand[hands] = True
    hand_col = np.full(B, -1)
    hand_col[hands] = np.arange(len(hands))
    foot_col = np.full(B, -1)
    foot_col[feet] = np.arange(len(feet))
    g_hand = (g_body >= 0) & is_hand[np.maximum(g_body, 0)]
    g_foot = (g_body >= 0) & (foot_col[np.maximum(g_body, 0)] >= 0)
    # Two collision passes per frame. Without margins MuJoCo gives exact penetration depths. With the analysis
    # margins it also returns separated pairs up to each margin, but its capsule-mesh distance is wrong for a
    # capsule whose axis is inside the mesh (measured: +3.6 mm for a 14 mm penetration at a 0.2 m margin), so
    # distances come from the second pass only for pairs the first found separated.
    margins = np.zeros(m.ngeom)
    margins[g_obj >= 0] = p.touch_m
    margins[g_foot] = FOOT_SEARCH_M
    margins[g_hand] = p.gap_max_m
    body_margins = np.zeros(m.nbody)  # the broad and mid phase test body bounds grown by the body margin
    np.maximum.at(body_margins, m.geom_bodyid, margins)

    depth = {g: np.zeros(T) for g in PENETRATION_GROUPS}
    hand_dist = np.full((T, len(hands)), p.gap_max_m)
    foot_dist = np.full((T, len(feet)), FOOT_SEARCH_M)
    foot_point = np.zeros((T, len(feet), 3))  # lowest contact point in the foot body's frame
    touched = np.zeros((T, len(dyn)), bool)
    xpos = np.zeros((T, len(feet), 3))
    xmat = np.zeros((T, len(feet), 3, 3))
    foot_bid = scene.body_ids[feet]
    hinge = scene.hinge_qposadr.ravel()
    is_foot = foot_col >= 0
    for t in range(T):
        d.qpos[0:3], d.qpos[3:7] = root_pos[t], root_quat[t]
        d.qpos[hinge] = angles[t]
        for i, o in enumerate(dyn):
            d.qpos[o.qposadr : o.qposadr + 3] = obj_pos[t, dyn_k[i]]
            d.qpos[o.qposadr + 3 : o.qposadr + 7] = obj_quat[t, dyn_k[i]]
        mujoco.mj_kinematics(m, d)
        xpos[t], xmat[t] = d.xpos[foot_bid], d.xmat[foot_bid].reshape(-1, 3, 3)
        penetrating: set[tuple[int, int]] = set()  # (geom, geom) pairs of the exact pass
        for exact in (True, False):
            m.geom_margin[:] = 0.0 if exact else margins
            m.body_margin[:] = 0.0 if exact else body_margins
            mujoco.mj_collision(m, d)
            if d.ncon == 0:
                continue
            c = d.contact
            g1, g2, dist = c.geom1.copy(), c.geom2.copy(), c.dist.copy()
            cpos = c.pos.copy()
            # orient every pair so that a humanoid geom, else a dynamic object geom, comes first
            swap = (g_body[g2] >= 0) | ((g_body[g1] < 0) & (g_obj[g2] >= 0))
            g1, g2 = np.where(swap, g2, g1), np.where(swap, g1, g2)
            if exact:
                penetrating = set(zip(g1.tolist(), g2.tolist(), strict=True))
            else:
                keep = np.array([(a, b) not in penetrating for a, b in zip(g1.tolist(), g2.tolist(), strict=True)])
                g1, g2, dist, cpos = g1[keep], g2[keep], dist[keep], cpos[keep]
            b1, o1, o2 = g_body[g1], g_obj[g1], g_obj[g2]
            hb = np.maximum(b1, 0)
            hand_obj = (b1 >= 0) & is_hand[hb] & (o2 >= 0)
            if exact:
                groups = {
                    "hand_object": hand_obj,
                    "body_floor": (b1 >= 0) & g_floor[g2],
                    "object_support": (o1 >= 0) & g_support[g2],
                }
                for name, sel in groups.items():
                    if sel.any():
                        depth[name][t] = max(0.0, float(-dist[sel].min()))
            if hand_obj.any():
                np.minimum.at(hand_dist[t], hand_col[b1[hand_obj]], dist[hand_obj])
            # objects: anything within touch_m (hand pairs come with a larger margin, hence the distance test)
            near = dist <= p.touch_m
            for sel, oi in (((o1 >= 0) & near, o1), ((o2 >= 0) & near & (o1 != o2), o2)):
                touched[t, oi[sel]] = True
            for k in np.flatnonzero((b1 >= 0) & g_floor[g2] & is_foot[hb]):
                f = foot_col[b1[k]]
                if dist[k] < foot_dist[t, f]:
                    foot_dist[t, f] = dist[k]
                    foot_point[t, f] = xmat[t, f].T @ (cpos[k] - xpos[t, f])

    # foot skating: velocity of the lowest contact point as a point of the foot body (central differences), on
    # frames where the foot is on the floor at t - 1, t and t + 1 (a landing foot still moves at swing speed)
    on = foot_dist <= p.foot_contact_m
    foot_speed = np.full((T, len(feet)), np.nan)
    if T >= 3:
        t_in = np.arange(1, T - 1)
        w_prev = np.einsum("tfij,tfj->tfi", xmat[t_in - 1], foot_point[t_in]) + xpos[t_in - 1]
        w_next = np.einsum("tfij,tfj->tfi", xmat[t_in + 1], foot_point[t_in]) + xpos[t_in + 1]
        speed = np.linalg.norm((w_next - w_prev)[..., :2], axis=-1) * fps / 2.0
        stance = on[t_in - 1] & on[t_in] & on[t_in + 1]
        foot_speed[t_in] = np.where(stance, speed, np.nan)
    gap = np.where(labels[:, hands] == 1, np.maximum(hand_dist, 0.0), np.nan)

    body_pos = seq.array("body_pos")
    centres = np.zeros((T, len(dyn), 3))
    for i, o in enumerate(dyn):
        c0 = np.asarray(o.record.surface_points, np.float64).mean(axis=0)
        q = np.asarray(obj_quat[:, dyn_k[i]], np.float64)
        centres[:, i] = np.asarray(obj_pos[:, dyn_k[i]], np.float64) + quat_rotate(q, np.broadcast_to(c0, (T, 3)))
    obj_speed = np.linalg.norm(_velocity(centres, fps), axis=-1)
    names = scene.skeleton.body_names
    return PlausibilityFrames(
        sequence_id=sequence_id,
        fps=fps,
        params=p,
        depth=depth,
        foot_height=foot_dist,
        foot_speed=foot_speed,
        gap=gap,
        object_speed=obj_speed,
        object_touched=touched,
        body_jerk=jerk(body_pos, fps),
        object_jerk=jerk(centres, fps),
        seconds=time.perf_counter() - t0,
        names={"feet": [names[b] for b in feet], "hands": [names[b] for b in hands], "objects": [o.id for o in dyn]},
    )


def plausibility(ds: Dataset, sequence_id: str, params: PlausibilityParams | None = None) -> dict[str, float]:
    """The plausibility metrics of one sequence (:meth:`PlausibilityFrames.summary`)."""
    return measure(ds, sequence_id, params).summary()


def plausibility_series(
    ds: Dataset, sequence_id: str, params: PlausibilityParams | None = None
) -> dict[str, np.ndarray]:
    """One (T,) array per metric per frame (:meth:`PlausibilityFrames.series`), for a viewer."""
    return measure(ds, sequence_id, params).series()
