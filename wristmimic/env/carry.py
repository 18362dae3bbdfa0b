"""Carry feedforward: PD-target offsets that hold up the weight of an object the reference carries.

A position actuator holds its target only where no load acts. Gravity feedforward (:mod:`wristmimic.env.gravity`)
balances the humanoid's own weight at the reference pose; a carried object adds its weight at the hands, and PD
then sags under it: on ``s110_move_kettle``, with the body held on its reference (root assist at gain 1, zero
residual actions, gravity feedforward) and the fingers posed as ParaHome's, the 1.27 kg kettle hangs 10-12 cm
below its reference through the carry, with the right wrist 4-9 cm off. The policy has to discover the extra
lift by exploration while the grip is still forming, and every trial of every lever tried ended there.

With ``EnvConfig.carry_feedforward``, in every reference frame where the object is off its supports (its
hulls more than :data:`LIFT_GAP` from the floor and every static object at the reference state) and a hand
touches it, each touching hand's arm and torso hinges (not legs, not fingers) also target ``J^T (m g / n) / kp``:
the joint torques that hold up an n-th share of the object's weight at the hand's contact point (the mean
reference position of that hand's bodies labelled in contact), over each hinge's stiffness. The offsets rise and
fall over a few frames at the ends of each carry. Reference-derived (pose, contact labels, the scene's mass),
computed once per scene and reference, deterministic, and applied the same way by training, evaluation and
``view`` (the environment adds them), as gravity feedforward is.
"""

from __future__ import annotations

import mujoco
import numpy as np

from wristmimic.env.gravity import upper_body_hinges
from wristmimic.scene import Scene

LIFT_GAP = 0.005
"""m; an object whose hulls are farther than this from the floor and every static object is off its supports."""

RAMP = 5
"""Width of the centred moving average that blends a carry's offsets in and out."""

SUPPORT_SEARCH = 0.05
"""m; distances beyond this are not resolved (an object this far from every support is lifted)."""


def lifted_frames(scene: Scene, qpos: np.ndarray, frames: np.ndarray) -> np.ndarray:
    """(T, O) bool: each dynamic object is off its supports at the reference states ``qpos`` (T, nq), evaluated
    in ``frames`` (False elsewhere). Supports: every geom that belongs neither to the humanoid nor to a dynamic
    object (the floor, static objects)."""
    m = scene.model
    d = mujoco.MjData(m)
    humanoid = set(int(b) for b in scene.body_ids)
    objects = [o.body_id for o in scene.dynamic_objects]
    colliding = [g for g in range(m.ngeom) if m.geom_contype[g] or m.geom_conaffinity[g]]
    object_geoms = [[g for g in colliding if int(m.geom_bodyid[g]) == b] for b in objects]
    moving = humanoid | set(objects)
    supports = [g for g in colliding if int(m.geom_bodyid[g]) not in moving]
    out = np.zeros((len(qpos), len(objects)), dtype=bool)
    fromto = np.zeros(6)
    for t in frames:
        d.qpos[:] = qpos[t]
        mujoco.mj_kinematics(m, d)
        for k, geoms in enumerate(object_geoms):
            gap = min(
                (mujoco.mj_geomDistance(m, d, g, s, SUPPORT_SEARCH, fromto) for g in geoms for s in supports),
                default=SUPPORT_SEARCH,
            )
            out[t, k] = gap > LIFT_GAP
    return out


def _smooth(mask: np.ndarray) -> np.ndarray:
    """``mask`` (T,) as floats, ramped in and out over ``RAMP // 2`` frames at each end of a run of ones."""
    pad = RAMP // 2
    return mask * np.convolve(np.pad(mask.astype(float), pad), np.ones(RAMP) / RAMP, mode="valid")


def carry_offsets(scene: Scene, qpos: np.ndarray, labels: np.ndarray, hand: np.ndarray) -> np.ndarray:
    """(T, J*3) PD-target offsets that hold up each carried object's weight at the hands touching it, from the
    reference states ``qpos`` (T, nq: humanoid and objects), the per-body contact labels ``labels`` (T, B, > 0:
    in contact) and the hand contact ``hand`` (T, 2) bool; zero on leg and finger hinges and outside carries."""
    m = scene.model
    skel, roles = scene.skeleton, scene.humanoid.roles
    T = len(qpos)
    out = np.zeros((T, skel.num_joints * 3))
    if T == 0 or not scene.dynamic_objects:
        return out
    lifted = lifted_frames(scene, qpos, np.flatnonzero(hand.any(-1)))
    carried = lifted.any(-1) & hand.any(-1)
    share = np.where(carried[:, None], hand, False).astype(float)
    share /= np.maximum(share.sum(-1, keepdims=True), 1.0)
    share *= _smooth(carried)[:, None]
    # the weight of the lifted objects (the hand contact labels do not say which object a hand holds)
    mass = np.array([m.body_mass[o.body_id] for o in scene.dynamic_objects])
    weight = (lifted * mass).sum(-1) * -m.opt.gravity[2]
    keep = upper_body_hinges(scene)
    dofs = scene.hinge_dofadr.reshape(-1)
    kp = scene.gains[:, 0]
    hand_bodies = [np.asarray(roles[k], dtype=int) for k in ("left_hand", "right_hand")]
    wrists = [int(scene.body_ids[int(w)]) for w in roles["wrists"]]
    d = mujoco.MjData(m)
    jac = np.zeros((3, m.nv))
    up = np.array([0.0, 0.0, 1.0])
    for t in np.flatnonzero(share.sum(-1) > 0.0):
        d.qpos[:] = qpos[t]
        mujoco.mj_kinematics(m, d)
        mujoco.mj_comPos(m, d)
        for side in (0, 1):
            if share[t, side] <= 0.0:
                continue
            bodies = hand_bodies[side]
            touching = bodies[labels[t, bodies] > 0]
            ids = scene.body_ids[touching if len(touching) else [int(roles["wrists"][side])]]
            point = d.xpos[np.asarray(ids, dtype=int)].mean(0)
            mujoco.mj_jac(m, d, jac, None, point, wrists[side])
            tau = jac.T @ (weight[t] * share[t, side] * up)
            out[t] += np.where(keep, tau[dofs] / kp, 0.0)
    return out
