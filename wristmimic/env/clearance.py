"""A reference whose palms do not lie inside objects (``env.clear_hands``, off by default).

Mocap hands and simulated collision hulls disagree: posed on its reference, ``sub2_largetable_000``'s palms lie
up to 19 mm inside the table top through the carry (median 16 mm for the left palm over 105 frames; the flat
thumbs up to 44 mm), ``s110_move_kettle``'s fingers cross the handle's bar. Tracking such a reference means
pressing the hand into the object: simulated, the palm cannot go there, so the wrist error the policy is paid to
remove is only removed by pushing the object away.

:func:`clear_palms` bends each arm of the reference, frame by frame, so that its palm (the colliding geoms of the
wrist body) lies at most ``tol`` inside any object, support or wall (not the floor): damped least squares on the
arm's hinges (collar to wrist) moving the deepest palm point out along the contact normal while the wrist keeps its
reference orientation. The changed hinge angles are then smoothed over ``smooth`` frames (so the arm does not jump
where a contact window starts) and frames that penetrate again after smoothing are solved once more without it.
Fingers are left as recorded: they get no pose targets in this method, and their start angles have their own lever
(``env.starts.depenetrate``). Deterministic; computed once per scene, so training, evaluation and ``view`` load
the same reference.
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from wristmimic.env.grounding import _colliding, _pose
from wristmimic.humanoid.skeleton import Skeleton
from wristmimic.rotations import quat_to_matrix
from wristmimic.scene import Scene


@dataclass
class ClearanceStats:
    """What :func:`clear_palms` changed."""

    frames: int
    """Frames where at least one arm moved."""
    max_before: float
    """Deepest palm penetration over the clip before (m)."""
    max_after: float
    """Deepest palm penetration over the clip after (m)."""
    max_shift: float
    """Largest wrist displacement (m) over frames and hands."""


def arm_chains(scene: Scene) -> list[tuple[int, list[int]]]:
    """Per wrist: (its skeleton index, the skeleton bodies of its :func:`arm_chain`, the hinges that move it: wrist,
    elbow, shoulder and collar on SMPL-X)."""
    skel = scene.skeleton
    return [
        (int(w), [int(skel.joint_bodies[j]) for j in arm_chain(skel, int(w))])
        for w in np.asarray(scene.humanoid.roles["wrists"]).tolist()
    ]


class _Palm:
    """Deepest penetration of one palm into non-humanoid geoms (the floor excluded) in the posed ``MjData``."""

    def __init__(self, scene: Scene, wrist: int):
        m = scene.model
        self.model = m
        self.body = int(scene.body_ids[wrist])
        self.geoms = set(_colliding(m, {self.body}))
        humanoid = np.zeros(m.nbody, dtype=bool)
        humanoid[scene.body_ids] = True
        humanoid[0] = True  # the floor and anything else on the world body
        self.foreign = ~humanoid

    def deepest(self, d: mujoco.MjData) -> tuple[float, np.ndarray, np.ndarray]:
        """(depth >= 0, the palm's point (3,), the unit direction out of the object (3,)); depth 0 if none."""
        m = self.model
        best, point, out = 0.0, np.zeros(3), np.zeros(3)
        for i in range(d.ncon):
            c = d.contact[i]
            if c.dist >= -best:
                continue
            if c.geom1 in self.geoms and self.foreign[m.geom_bodyid[c.geom2]]:
                sign = -1.0  # the normal points from geom1 (the palm) to geom2: the palm leaves along -n
            elif c.geom2 in self.geoms and self.foreign[m.geom_bodyid[c.geom1]]:
                sign = 1.0
            else:
                continue
            n = c.frame[:3]
            best, out = float(-c.dist), sign * n
            point = c.pos + out * (best / 2)  # contact.pos is midway between the two surfaces
        return best, point, out


def clear_palms(
    scene: Scene,
    root_pos: np.ndarray,
    root_quat: np.ndarray,
    joint_angles: np.ndarray,
    obj_pos: np.ndarray,
    obj_quat: np.ndarray,
    tol: float = 0.002,
    smooth: int = 7,
    iterations: int = 30,
) -> tuple[np.ndarray, ClearanceStats]:
    """Hinge angles (T, J*3) whose palms lie at most ``tol`` (m) inside any object (see the module), with
    statistics. Root pose (T, 3) / (T, 4) wxyz, hinge angles (T, J*3) in actuator order, the dynamic objects' poses
    (T, O, 3) / (T, O, 4) wxyz in ``scene.dynamic_objects`` order."""
    m = scene.model
    out = np.array(joint_angles, dtype=np.float64, copy=True)
    T = len(out)
    chains = arm_chains(scene)
    if not chains or T == 0:
        return out, ClearanceStats(0, 0.0, 0.0, 0.0)
    d = mujoco.MjData(m)
    col = {int(a): k for k, a in enumerate(scene.hinge_qposadr.reshape(-1))}
    joint_of = {int(b): j for j, b in enumerate(scene.skeleton.joint_bodies)}
    lo, hi = scene.skeleton.joint_range.reshape(-1, 2).T
    arms = []
    for wrist, chain in chains:
        joints = [joint_of[b] for b in chain if b in joint_of]
        qa = scene.hinge_qposadr[joints].reshape(-1)
        arms.append((_Palm(scene, wrist), np.array([col[int(a)] for a in qa]), scene.hinge_dofadr[joints].reshape(-1)))
    jacp, jacr = np.zeros((3, m.nv)), np.zeros((3, m.nv))

    adr = [int(o.qposadr) for o in scene.dynamic_objects]

    def posed(t: int, angles: np.ndarray) -> None:
        _pose(scene, d, root_pos[t], root_quat[t], angles)
        for k, a in enumerate(adr):
            d.qpos[a : a + 3], d.qpos[a + 3 : a + 7] = obj_pos[t, k], obj_quat[t, k]
        mujoco.mj_kinematics(m, d)
        mujoco.mj_comPos(m, d)  # mj_jac needs it
        mujoco.mj_collision(m, d)

    def wrist_quats(angles: np.ndarray) -> np.ndarray:
        q = np.empty((T, len(arms), 4))
        for t in range(T):
            _pose(scene, d, root_pos[t], root_quat[t], angles[t])
            q[t] = d.xquat[[a[0].body for a in arms]]
        return q

    def depths(angles: np.ndarray) -> np.ndarray:
        dep = np.zeros((T, len(arms)))
        for t in range(T):
            posed(t, angles[t])
            dep[t] = [a[0].deepest(d)[0] for a in arms]
        return dep

    target_quat = wrist_quats(out)
    before = depths(out)

    def solve(t: int, angles: np.ndarray, frames_moved: set[int]) -> None:
        """Move each penetrating arm of frame ``t`` of ``angles`` in place."""
        for k, (palm, cols, dofs) in enumerate(arms):
            posed(t, angles[t])
            depth, point, normal = palm.deepest(d)
            if depth <= tol:
                continue
            frames_moved.add(t)
            for _ in range(iterations):
                mujoco.mj_jac(m, d, jacp, None, point, palm.body)
                mujoco.mj_jacBody(m, d, None, jacr, palm.body)
                J = np.vstack([jacp[:, dofs], jacr[:, dofs]])
                rot = np.zeros(3)
                mujoco.mju_subQuat(rot, target_quat[t, k], d.xquat[palm.body])
                mat = d.xmat[palm.body].reshape(3, 3)
                err = np.concatenate([normal * (depth - tol / 2), mat @ rot])
                dq = J.T @ np.linalg.solve(J @ J.T + 1e-4 * np.eye(6), err)
                angles[t, cols] = np.clip(angles[t, cols] + dq, lo[cols], hi[cols])
                posed(t, angles[t])
                depth, point, normal = palm.deepest(d)
                if depth <= tol:
                    break

    moved: set[int] = set()
    for t in range(T):
        solve(t, out, moved)
    if moved and smooth > 1:
        delta = out - np.asarray(joint_angles, dtype=np.float64)
        pad = smooth // 2
        padded = np.pad(delta, ((pad, smooth - 1 - pad), (0, 0)), mode="edge")
        kernel = np.ones(smooth) / smooth
        smoothed = np.stack([np.convolve(padded[:, c], kernel, mode="valid") for c in range(delta.shape[1])], axis=1)
        out = np.clip(np.asarray(joint_angles, dtype=np.float64) + smoothed, lo, hi)
        again = depths(out)
        for t in np.flatnonzero(again.max(axis=1) > tol).tolist():
            solve(t, out, moved)
    after = depths(out)
    shift = 0.0
    if moved:
        ids = [a[0].body for a in arms]
        for t in sorted(moved | set(np.flatnonzero(np.abs(out - joint_angles).max(axis=1) > 0).tolist())):
            _pose(scene, d, root_pos[t], root_quat[t], np.asarray(joint_angles[t], dtype=np.float64))
            p0 = d.xpos[ids].copy()
            _pose(scene, d, root_pos[t], root_quat[t], out[t])
            shift = max(shift, float(np.linalg.norm(d.xpos[ids] - p0, axis=1).max()))
    changed = int((np.abs(out - joint_angles).max(axis=1) > 0).sum())
    return out, ClearanceStats(changed, float(before.max()), float(after.max()), shift)


ARM_BODIES = 4
"""Bodies of the arm chain, from the wrist up: wrist, elbow, shoulder, collar."""


@dataclass
class ArmOffsetMap:
    """Per frame and hand, the linear map from an object-frame wrist offset (m) to arm hinge angle changes."""

    qpos_index: np.ndarray  # (2, A) qpos addresses of each hand's arm hinges
    dof_index: np.ndarray  # (2, A) dof addresses of the same hinges
    maps: np.ndarray  # (T, 2, A, 3) world-frame offset -> hinge change
    obj_rot: np.ndarray  # (T, 3, 3) reference object rotation
    weight: np.ndarray  # (T, 2) contact ramp per hand
    fps: float

    def deltas(self, offsets: np.ndarray) -> np.ndarray:
        """(T, 2, A) hinge angle changes for ``offsets`` (2, 3): per hand, metres in the object's frame."""
        world = np.einsum("tij,hj->thi", self.obj_rot, np.asarray(offsets, dtype=np.float64))
        return self.weight[..., None] * np.einsum("thai,thi->tha", self.maps, world)

    def apply(self, qpos: np.ndarray, qvel: np.ndarray, offsets: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Refined copies of the reference ``qpos`` (T, nq) and ``qvel`` (T, nv): arm hinges moved, velocities of
        the moved hinges changed by the offsets' finite difference."""
        d = self.deltas(offsets)
        q, v = qpos.copy(), qvel.copy()
        q[:, self.qpos_index.reshape(-1)] += d.reshape(len(q), -1)
        dv = np.gradient(d, axis=0) * self.fps if len(d) > 1 else np.zeros_like(d)
        v[:, self.dof_index.reshape(-1)] += dv.reshape(len(v), -1)
        return q, v


def contact_ramp(touch: np.ndarray, ramp: int) -> np.ndarray:
    """(T, H) weight: 1 where ``touch`` (T, H) is true, falling linearly to 0 over ``ramp`` frames away from it."""
    T, H = touch.shape
    t = np.arange(T)
    out = np.zeros((T, H))
    for h in range(H):  # two hands, once per sequence
        frames = np.flatnonzero(touch[:, h])
        if frames.size:
            dist = np.abs(t[:, None] - frames[None, :]).min(axis=1)
            out[:, h] = np.clip(1.0 - dist / max(ramp, 1), 0.0, 1.0)
    return out


def arm_chain(skel: Skeleton, wrist_body: int) -> list[int]:
    """Joint indices of the arm chain ending at ``wrist_body``: the wrist and its ``ARM_BODIES - 1`` ancestors."""
    chain, b = [], wrist_body
    for _ in range(ARM_BODIES):
        j = np.flatnonzero(skel.joint_bodies == b)
        if not j.size:
            break
        chain.append(int(j[0]))
        b = int(skel.parents[b])
    return chain


def arm_offset_map(
    scene: Scene,
    ref_qpos: np.ndarray,
    obj_quat: np.ndarray,
    touch: np.ndarray,
    fps: float,
    ramp: int = 10,
    damping: float = 0.02,
) -> ArmOffsetMap:
    """The :class:`ArmOffsetMap` of a scene's humanoid along the reference ``ref_qpos`` (T, nq); ``obj_quat``
    (T, 4) wxyz is the carried object's reference orientation, ``touch`` (T, 2) each hand's reference contact."""
    m, skel, roles = scene.model, scene.skeleton, scene.humanoid.roles
    d = mujoco.MjData(m)
    wrists = [int(np.atleast_1d(roles[f"{s}_hand"])[0]) for s in ("left", "right")]
    chains = [arm_chain(skel, w) for w in wrists]
    qidx = np.stack([scene.hinge_qposadr[c].reshape(-1) for c in chains])
    didx = np.stack([scene.hinge_dofadr[c].reshape(-1) for c in chains])
    T, A = len(ref_qpos), qidx.shape[1]
    maps = np.zeros((T, 2, A, 3))
    jacp, jacr = np.zeros((3, m.nv)), np.zeros((3, m.nv))
    for t in range(T):  # preprocessing, once per sequence
        d.qpos[:] = ref_qpos[t]
        mujoco.mj_kinematics(m, d)
        mujoco.mj_comPos(m, d)
        for h, w in enumerate(wrists):
            mujoco.mj_jacBody(m, d, jacp, jacr, int(scene.body_ids[w]))
            J = np.concatenate([jacp[:, didx[h]], jacr[:, didx[h]]])  # (6, A)
            pinv = J.T @ np.linalg.inv(J @ J.T + damping**2 * np.eye(6))
            maps[t, h] = pinv[:, :3]
    return ArmOffsetMap(qidx, didx, maps, quat_to_matrix(obj_quat), contact_ramp(touch, ramp), fps)


def offset_wrists(
    scene: Scene,
    root_pos: np.ndarray,
    root_quat: np.ndarray,
    joint_angles: np.ndarray,
    obj_quat: np.ndarray,
    touch: np.ndarray,
    offsets: np.ndarray,
    fps: float,
) -> np.ndarray:
    """Hinge angles (T, J*3) with each hand moved by ``offsets`` (2, 3; left, right; m in the object's frame, whose
    wxyz orientation per frame is ``obj_quat`` (T, 4)) while ``touch`` (T, 2) says the reference hand touches the
    object: :class:`ArmOffsetMap` along the reference, as ``scripts/kinematic_grip_probe.py`` applies it."""
    m = scene.model
    qpos = np.tile(m.qpos0, (len(joint_angles), 1))
    qpos[:, 0:3], qpos[:, 3:7] = root_pos, root_quat
    qpos[:, scene.hinge_qposadr.reshape(-1)] = joint_angles
    arms = arm_offset_map(scene, qpos, obj_quat, touch, fps)
    col = {int(a): k for k, a in enumerate(scene.hinge_qposadr.reshape(-1))}
    cols = np.array([col[int(a)] for a in arms.qpos_index.reshape(-1)])
    out = np.array(joint_angles, dtype=np.float64, copy=True)
    out[:, cols] += arms.deltas(offsets).reshape(len(out), -1)
    return out
