"""Whole-body inverse kinematics with MuJoCo Jacobians: damped least squares over the root and body hinges.

Each frame minimises, over the root's 6 DoF and the hinges of the 19 non-finger, non-toe bodies,

    sum_tasks || w_task * (J dq - e) ||^2 + sum_dofs || w_post * (q + dq - q_neutral) ||^2 + lambda^2 ||dq||^2

(Gauss-Newton steps of at most ``max_step``, each followed by clipping the hinges to anatomical limits;
optionally a pull towards a given joint-space path). Tasks: feet (ankle position and orientation: planted,
flat), hands (palm point position and wrist orientation), the centre of mass inside a small region over the
feet (with the carried share of a held object's mass added at its position) and the pelvis orientation.
Fingers and toes are set outside the IK (toes stay flat; fingers close by :func:`finger_closure`). Euler y
limits stay inside +-85 deg, so the hinge angles equal the intrinsic XYZ Euler angles of the joint rotations.
Arm clearance: points along the upper-arm and forearm capsules closer to an obstacle box (the held box) than
their radius plus a margin are pushed out along the box's distance gradient (a one-sided task, re-linearised every
step). Jacobians: ``mj_jac`` (palm points, arm points), ``mj_jacBody`` (feet, pelvis), ``mj_jacSubtreeCom``
(centre of mass).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import mujoco
import numpy as np

from wristmimic.humanoid.skeleton import Skeleton
from wristmimic.synth.humanoid import SIDES, SynthHumanoid

_D = np.deg2rad
# Left-side limits (deg) per body kind: (x, y, z) ranges; right side mirrors x and z. Anatomical, tighter
# than the MJCF's +-180 deg, so that the IK finds human-like poses. Euler y stays inside +-85 deg.
IK_LIMITS_DEG: dict[str, tuple[tuple[float, float], ...]] = {
    "Hip": ((-20, 40), (-110, 25), (-45, 45)),
    "Knee": ((-3, 3), (0, 140), (-5, 5)),
    "Ankle": ((-20, 20), (-25, 45), (-20, 20)),
    "Toe": ((0, 0), (0, 0), (0, 0)),
    "Torso": ((-15, 15), (-10, 30), (-20, 20)),
    "Spine": ((-15, 15), (-10, 30), (-20, 20)),
    "Chest": ((-15, 15), (-10, 30), (-20, 20)),
    "Neck": ((-20, 20), (-20, 30), (-30, 30)),
    "Head": ((-20, 20), (-20, 30), (-30, 30)),
    "Thorax": ((-10, 10), (-10, 10), (-10, 10)),
    "Shoulder": ((-150, 150), (-85, 85), (-130, 45)),
    "Elbow": ((-30, 30), (-85, 85), (-150, 0)),
    "Wrist": ((-70, 70), (-80, 80), (-45, 45)),
}
NEUTRAL_DEG: dict[str, tuple[float, float, float]] = {
    "Hip": (0, -4, 0),
    "Knee": (0, 8, 0),
    "Ankle": (0, -4, 0),
    "Shoulder": (-78, 0, 4),
    "Elbow": (0, 0, -12),
}
"""Left-side neutral posture (deg): standing, knees soft, arms hanging with palms towards the thighs."""
POSTURE_WEIGHT: dict[str, float] = {
    "Hip": 0.1,
    "Knee": 0.4,
    "Ankle": 0.4,
    "Torso": 0.4,
    "Spine": 0.4,
    "Chest": 0.4,
    "Neck": 0.6,
    "Head": 0.6,
    "Thorax": 0.6,
    "Shoulder": 0.15,
    "Elbow": 0.1,
    "Wrist": 0.2,
}
"""Posture regularisation weight (1/rad) per body kind: a stiff trunk and head, free limbs."""


@dataclass(frozen=True)
class IKWeights:
    """Residual weights (squared in the cost): metres for positions, radians for rotations."""

    foot_pos: float = 20.0
    foot_rot: float = 5.0
    hand_pos: float = 10.0
    hand_rot: float = 2.0
    com: float = 4.0
    pelvis_rot: float = 0.5
    max_step: float = 0.05
    """Largest change of any DoF (rad or m) in one Gauss-Newton step."""
    damping: float = 0.02
    """lambda: damping of each Gauss-Newton step."""
    clearance: float = 30.0
    """Weight of the arm-clearance task (one-sided: only points closer to the obstacle than their radius plus
    ``clearance_margin`` pull)."""
    clearance_margin: float = 0.002
    """Wanted gap (m) between the arm capsules (upper arm, forearm) and the obstacle box."""


@dataclass
class FrameTargets:
    """World targets of one frame. Hands may be absent (None): then the posture decides."""

    feet_pos: dict[str, np.ndarray]
    feet_mat: dict[str, np.ndarray]
    hands_pos: dict[str, np.ndarray] | None
    hands_mat: dict[str, np.ndarray] | None
    com_xy: np.ndarray
    """Centre of the region the centre of mass should stay in (x, y)."""
    held_mass: float = 0.0
    held_pos: np.ndarray = field(default_factory=lambda: np.zeros(3))
    pelvis_yaw: float = 0.0
    com_band: tuple[float, float] = (0.035, 0.03)
    """Half extents (x, y) of the centre-of-mass region around ``com_xy`` (inside it the CoM is free)."""
    obstacle: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
    """A box the arms must stay out of: (centre (3,), rotation (3, 3), half extents (3,)); None: no such task.
    The hands are not part of it (they hold the box)."""


def _kind(name: str) -> str:
    return name.split("_", 1)[-1] if "_" in name else name


def _mirror(rng: tuple[float, float], flip: bool) -> tuple[float, float]:
    return (-rng[1], -rng[0]) if flip else rng


class WholeBodyIK:
    """Damped least-squares IK on the synthetic humanoid (see the module docstring)."""

    def __init__(self, skel: Skeleton, humanoid: SynthHumanoid, weights: IKWeights | None = None):
        self.skel, self.h, self.w = skel, humanoid, weights or IKWeights()
        self.model = mujoco.MjModel.from_xml_string(humanoid.mjcf)
        self.data = mujoco.MjData(self.model)
        m = self.model
        self.bid = {n: mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, n) for n in skel.body_names}
        nv = m.nv
        lo, hi = np.full(nv, -np.inf), np.full(nv, np.inf)
        neutral = np.zeros(m.nq)
        neutral[3] = 1.0
        post = np.zeros(nv)
        active = list(range(6))
        for j, b in enumerate(skel.joint_bodies):
            name = skel.body_names[b]
            kind = _kind(name)
            dofs = skel.hinge_qposadr[j] - 1  # hinge dof = qpos address - 1 (the free joint has 7 qpos, 6 dofs)
            if kind in IK_LIMITS_DEG:
                right = name.startswith("R_")
                for k in range(3):
                    r = _mirror(IK_LIMITS_DEG[kind][k], right and k != 1)
                    lo[dofs[k]], hi[dofs[k]] = _D(r[0]), _D(r[1])
                    n = NEUTRAL_DEG.get(kind, (0.0, 0.0, 0.0))[k]
                    neutral[dofs[k] + 1] = _D(-n if right and k != 1 else n)
                    post[dofs[k]] = POSTURE_WEIGHT.get(kind, 0.0)
                if kind != "Toe":
                    active.extend(int(d) for d in dofs)
        self.lo, self.hi, self.post = lo, hi, post
        self.active = np.asarray(active)
        self.neutral = neutral
        self.mass = float(m.body_subtreemass[1])
        self._jp = np.zeros((3, nv))
        self._jr = np.zeros((3, nv))
        arm = [self.bid[f"{s}_{k}"] for s, _ in SIDES for k in ("Shoulder", "Elbow")]
        self.arm_geoms = [
            int(g)
            for g in np.flatnonzero(np.isin(m.geom_bodyid, arm))
            if m.geom_type[g] == mujoco.mjtGeom.mjGEOM_CAPSULE
        ]

    # -- helpers -----------------------------------------------------------------------------------------------
    def neutral_qpos(self, root_pos: np.ndarray) -> np.ndarray:
        q = self.neutral.copy()
        q[0:3] = root_pos
        return q

    def _rot_err(self, target: np.ndarray, b: int) -> np.ndarray:
        """World rotation vector taking body ``b``'s orientation to ``target`` (3x3)."""
        qt, qc, e = np.zeros(4), self.data.xquat[b].copy(), np.zeros(3)
        mujoco.mju_mat2Quat(qt, np.ascontiguousarray(target).ravel())
        mujoco.mju_subQuat(e, qt, qc)  # qc * quat(e) = qt, e in the body frame
        return self.data.xmat[b].reshape(3, 3) @ e

    @staticmethod
    def _com_err(tgt: FrameTargets, com: np.ndarray) -> np.ndarray:
        """How far the (x, y) centre of mass is outside its region (0 inside)."""
        band = np.asarray(tgt.com_band)
        return np.clip(com[:2], tgt.com_xy - band, tgt.com_xy + band) - com[:2]

    def palm_world(self, side: str) -> tuple[np.ndarray, np.ndarray]:
        """Palm point (world) and wrist rotation matrix of one hand at the current state."""
        b = self.bid[f"{side}_Wrist"]
        R = self.data.xmat[b].reshape(3, 3)
        return self.data.xpos[b] + R @ self.h.palm_point[side], R.copy()

    def arm_clearance(
        self, obstacle: tuple[np.ndarray, np.ndarray, np.ndarray], samples: int = 9
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Points along the arm capsule axes at the current state and their box clearance: (P, 3) points,
        (P,) body ids, (P,) capsule radii, (P,) signed distance of the axis point to the box (< 0 inside) and
        (P, 3) the box distance gradient (world, unit)."""
        m, d = self.model, self.data
        centre, R, half = obstacle
        u = np.linspace(-1.0, 1.0, samples)
        g = np.asarray(self.arm_geoms)
        axis = d.geom_xmat[g].reshape(-1, 3, 3)[:, :, 2]
        pts = (d.geom_xpos[g][:, None] + (u[None, :, None] * m.geom_size[g, 1][:, None, None]) * axis[:, None]).reshape(
            -1, 3
        )
        body = np.repeat(m.geom_bodyid[g], samples)
        rad = np.repeat(m.geom_size[g, 0], samples)
        loc = (pts - centre) @ R
        q = np.abs(loc) - half
        out = np.maximum(q, 0.0)
        norm = np.linalg.norm(out, axis=1)
        sdf = norm + np.minimum(q.max(axis=1), 0.0)
        grad = np.where(norm[:, None] > 0, out / np.maximum(norm, 1e-12)[:, None], np.eye(3)[q.argmax(axis=1)])
        grad = (grad * np.sign(loc + 1e-12)) @ R.T
        return pts, body, rad, sdf, grad

    def forward(self, q: np.ndarray) -> None:
        self.data.qpos[:] = q
        mujoco.mj_kinematics(self.model, self.data)
        mujoco.mj_comPos(self.model, self.data)

    # -- solve -------------------------------------------------------------------------------------------------
    def residuals(self, tgt: FrameTargets) -> dict[str, float]:
        """Task errors at the current state (m, rad)."""
        d, out = self.data, {}
        for s, _ in SIDES:
            b = self.bid[f"{s}_Ankle"]
            out[f"{s}_foot_pos"] = float(np.linalg.norm(tgt.feet_pos[s] - d.xpos[b]))
            out[f"{s}_foot_rot"] = float(np.linalg.norm(self._rot_err(tgt.feet_mat[s], b)))
            if tgt.hands_pos is not None and tgt.hands_mat is not None:
                p, _R = self.palm_world(s)
                out[f"{s}_hand_pos"] = float(np.linalg.norm(tgt.hands_pos[s] - p))
                out[f"{s}_hand_rot"] = float(np.linalg.norm(self._rot_err(tgt.hands_mat[s], self.bid[f"{s}_Wrist"])))
        com = (self.mass * d.subtree_com[1] + tgt.held_mass * tgt.held_pos) / (self.mass + tgt.held_mass)
        out["com_xy"] = float(np.linalg.norm(self._com_err(tgt, com)))
        return out

    def _rows(self, tgt: FrameTargets) -> tuple[list[np.ndarray], list[np.ndarray]]:
        """Weighted Jacobian rows (over all DoFs) and residuals of every task at the current state."""
        m, d, w = self.model, self.data, self.w
        rows: list[np.ndarray] = []
        errs: list[np.ndarray] = []

        def add(J: np.ndarray, e: np.ndarray, weight: float) -> None:
            rows.append(weight * J)
            errs.append(weight * e)

        for s, _ in SIDES:
            b = self.bid[f"{s}_Ankle"]
            mujoco.mj_jacBody(m, d, self._jp, self._jr, b)
            add(self._jp.copy(), tgt.feet_pos[s] - d.xpos[b], w.foot_pos)
            add(self._jr.copy(), self._rot_err(tgt.feet_mat[s], b), w.foot_rot)
            if tgt.hands_pos is not None and tgt.hands_mat is not None:
                b = self.bid[f"{s}_Wrist"]
                p, _R = self.palm_world(s)
                mujoco.mj_jac(m, d, self._jp, self._jr, p, b)
                add(self._jp.copy(), tgt.hands_pos[s] - p, w.hand_pos)
                add(self._jr.copy(), self._rot_err(tgt.hands_mat[s], b), w.hand_rot)
        mujoco.mj_jacSubtreeCom(m, d, self._jp, 1)
        tot = self.mass + tgt.held_mass
        com = (self.mass * d.subtree_com[1] + tgt.held_mass * tgt.held_pos) / tot
        add(self._jp[:2] * (self.mass / tot), self._com_err(tgt, com), w.com)
        if tgt.obstacle is not None:
            pts, body, rad, sdf, grad = self.arm_clearance(tgt.obstacle)
            for i in np.flatnonzero(sdf < rad + w.clearance_margin):
                mujoco.mj_jac(m, d, self._jp, self._jr, pts[i], int(body[i]))
                add(grad[i][None] @ self._jp, np.array([rad[i] + w.clearance_margin - sdf[i]]), w.clearance)
        c, sn = np.cos(tgt.pelvis_yaw), np.sin(tgt.pelvis_yaw)
        mujoco.mj_jacBody(m, d, self._jp, self._jr, 1)
        add(self._jr.copy(), self._rot_err(np.array([[c, -sn, 0.0], [sn, c, 0.0], [0.0, 0.0, 1.0]]), 1), w.pelvis_rot)
        return rows, errs

    def solve(
        self,
        q: np.ndarray,
        tgt: FrameTargets,
        iterations: int,
        tol: float = 1e-7,
        track: tuple[np.ndarray, float] | None = None,
    ) -> np.ndarray:
        """Gauss-Newton from ``q`` (nq,) towards ``tgt``; returns the new qpos. ``track = (q_path, weight)``
        adds a pull of every active hinge towards ``q_path`` (1/rad) on top of the neutral posture."""
        m, w, A = self.model, self.w, self.active
        q = q.copy()
        hq = A[6:] + 1  # qpos addresses of the active hinges
        post = self.post[A]
        tw = np.r_[np.zeros(6), np.full(len(A) - 6, track[1] if track is not None else 0.0)]
        hinge = np.arange(6, m.nv)
        for _ in range(iterations):
            self.forward(q)
            rows, errs = self._rows(tgt)
            J = np.concatenate(rows)[:, A]
            e = np.concatenate(errs)
            pull = np.zeros(len(A))
            pull[6:] = post[6:] ** 2 * (self.neutral[hq] - q[hq])
            if track is not None:
                pull[6:] += tw[6:] ** 2 * (track[0][hq] - q[hq])
            H = J.T @ J + np.diag(post**2 + tw**2 + w.damping**2)
            dq_a = np.linalg.solve(H, J.T @ e + pull)
            big = np.abs(dq_a).max()
            if big > w.max_step:
                dq_a *= w.max_step / big
            dq = np.zeros(m.nv)
            dq[A] = dq_a
            mujoco.mj_integratePos(m, q, dq, 1.0)
            q[hinge + 1] = np.clip(q[hinge + 1], self.lo[hinge], self.hi[hinge])
            if float(dq_a @ dq_a) < tol**2:
                break
        self.forward(q)
        return q


def _finger_chains(skel: Skeleton, wrist: int) -> list[list[int]]:
    """Body chains (base to tip) of the fingers of one hand."""
    out = []
    for start in skel.children(wrist):
        chain = [start]
        while skel.children(chain[-1]):
            chain.append(skel.children(chain[-1])[0])
        out.append(chain)
    return out


def _flexion(skel: Skeleton, chain: list[int], sign: float, theta: float) -> dict[int, np.ndarray]:
    """Hinge angles (per body) that flex one finger by ``theta`` towards the palm (-z of the hand)."""
    from wristmimic.rotations import quat_to_euler_xyz, rotvec_to_quat

    if "Thumb" in skel.body_names[chain[0]]:  # rotate the base about the in-palm axis across the thumb
        d = skel.rest_pos[chain[1]] / np.linalg.norm(skel.rest_pos[chain[1]])
        axis = -np.cross(d, [0.0, 0.0, 1.0])
        base = quat_to_euler_xyz(rotvec_to_quat(theta * axis / np.linalg.norm(axis)))
        return {chain[0]: base, chain[-1]: np.array([sign * theta, 0.0, 0.0])}
    return {b: np.array([sign * theta, 0.0, 0.0]) for b in chain}


def _lowest(model: mujoco.MjModel, data: mujoco.MjData, skel: Skeleton, wrist: int, chain, angles) -> float:
    """Lowest point (z relative to the wrist, rest pose otherwise) of a finger's capsules."""
    jslot = {int(b): j for j, b in enumerate(skel.joint_bodies)}
    data.qpos[:] = model.qpos0
    for b, a in angles.items():
        data.qpos[skel.hinge_qposadr[jslot[b]]] = a
    mujoco.mj_kinematics(model, data)
    low = np.inf
    for b in chain:
        for g in np.flatnonzero(model.geom_bodyid == b + 1):
            axis_z = data.geom_xmat[g].reshape(3, 3)[2, 2]
            zc = data.geom_xpos[g, 2] - data.xpos[wrist + 1, 2]
            low = min(low, zc - abs(axis_z) * model.geom_size[g, 1] - model.geom_size[g, 0])
    return low


def finger_closure(
    skel: Skeleton, humanoid: SynthHumanoid, face_z: float, press: float = 0.002
) -> dict[int, np.ndarray]:
    """Hinge angles (finger joint index -> (3,) rad) that flex each finger of both hands until its lowest
    geom point reaches ``face_z - press`` in the wrist frame (the palm's plane of contact lies at z = face_z
    < 0: palms face -z). Non-thumb fingers flex their three joints equally about x; the thumb rotates its base
    about the in-palm axis across it and its tip about x. Bisection on the angle, clipped to the joint ranges.
    """
    model = mujoco.MjModel.from_xml_string(humanoid.mjcf)
    data = mujoco.MjData(model)
    jslot = {int(b): j for j, b in enumerate(skel.joint_bodies)}
    out: dict[int, np.ndarray] = {}
    goal = face_z - press
    for s, y in SIDES:
        wrist = skel.index(f"{s}_Wrist")
        sign = -y  # left hand: flexion is a negative x rotation (fingers towards -z); right hand: positive
        for chain in _finger_chains(skel, wrist):

            def low(theta: float, chain: list[int] = chain, wrist: int = wrist, sign: float = sign) -> float:
                return _lowest(model, data, skel, wrist, chain, _flexion(skel, chain, sign, theta))

            lo_t, hi_t = 0.0, _D(50.0)
            if low(lo_t) <= goal:
                hi_t = 0.0
            else:
                for _ in range(30):
                    mid = 0.5 * (lo_t + hi_t)
                    lo_t, hi_t = (mid, hi_t) if low(mid) > goal else (lo_t, mid)
            for b, a in _flexion(skel, chain, sign, hi_t).items():
                j = jslot[b]
                out[j] = np.clip(a, skel.joint_range[j, :, 0], skel.joint_range[j, :, 1])
    return out
