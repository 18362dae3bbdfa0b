"""Grip squeeze: PD-target offsets that press both hands into an object held between them.

PD tracking of a reference whose palms lie exactly on the object's faces holds the hands there with no normal
force, so nothing carries the object by friction: the policy has to discover, by exploration, a coordinated
inward push of both arms before it can lift anything (on the synthetic scenes the lift is found late, at a
seed-dependent time). With ``EnvConfig.grip_squeeze`` = F newtons, in every reference frame where both hands
touch the object from opposite sides (an antipodal two-handed hold), each arm's hinges (collar, shoulder, elbow,
wrist) also target ``J^T (F n) / kp``: the joint torques that press the wrist with F along ``n``, the direction
from the hand to its nearest object surface point, over each hinge's stiffness. Where the hand is stopped by the
object, PD then squeezes with about F; the policy's residual corrects the rest.

The offsets rise and fall over the first and last frames of each hold. One-handed contacts and hands on the
same side (a table lifted by its near edge, a kettle's handle) get none. Computed once per scene and reference,
deterministic, and applied the same way by training, evaluation and ``view`` (the environment adds them).

Which scenes get it: the synthetic box scenes hold the box between both palms from frame 42 (every two-handed
frame, presses 180 deg apart); ``sub2_largetable_000`` has both palms on the same side of the table top (presses
0-10 deg apart) and ``s110_move_kettle`` one hand, so neither gets any.

Measured on ``synth_turn`` seed 1 (2 threads, 400,384 frames, 256 quick frame-0 trials) at 40 N (offsets up to
0.038 rad): **0 % (0-1.5)**, as the recipe without it (its first >= 90 % periodic evaluation came at 409k frames,
this run's periodic evaluations stayed at 0 %, 127 of 176 frames at 368-389k); with zero actions from a
reference start at frame 48 of ``synth_default`` it raises the box 3-4 cm closer to its reference at frames 60-80
(10 cm short instead of 14), while the wrists trail theirs by 13-18 cm. Not in the recipe.
"""

from __future__ import annotations

import mujoco
import numpy as np

from wristmimic.scene import Scene

RAMP = 5
"""Width of the centred moving average that blends a hold's squeeze in and out."""

MAX_GAP = 0.1
"""m; a wrist farther than this from every object presses in no direction."""

OPPOSITION = -0.5
"""Two hands hold antipodally when the cosine between their press directions is below this (120 deg apart)."""


def arm_chain(scene: Scene, side: int) -> list[int]:
    """Skeleton bodies whose hinges move a wrist: collar (the shoulder's parent), shoulder, elbow and wrist."""
    roles, skel = scene.humanoid.roles, scene.skeleton
    arm = [int(b) for b in roles[("left_arm", "right_arm")[side]]]
    return sorted({int(skel.parents[arm[0]]), *arm, int(roles["wrists"][side])})


def press_directions(scene: Scene, qpos: np.ndarray, frames: np.ndarray) -> np.ndarray:
    """(T, 2, 3) unit directions in which each wrist (palm) body would press the nearest dynamic object at the
    reference states ``qpos`` (T, nq), from MuJoCo's closest points between the wrist's geoms and the objects'
    (the separating direction where they overlap); zero in frames not in ``frames``."""
    m = scene.model
    d = mujoco.MjData(m)
    roles = scene.humanoid.roles
    objects = {o.body_id for o in scene.dynamic_objects}
    object_geoms = [g for g in range(m.ngeom) if int(m.geom_bodyid[g]) in objects]
    wrist_geoms = [
        [g for g in range(m.ngeom) if int(m.geom_bodyid[g]) == int(scene.body_ids[int(w)])] for w in roles["wrists"]
    ]
    out = np.zeros((len(qpos), 2, 3))
    fromto = np.zeros(6)
    for t in frames:
        d.qpos[:] = qpos[t]
        mujoco.mj_kinematics(m, d)
        for side, geoms in enumerate(wrist_geoms):
            best, v = np.inf, np.zeros(3)
            for g in geoms:
                for o in object_geoms:
                    dist = mujoco.mj_geomDistance(m, d, g, o, MAX_GAP, fromto)
                    if dist < best:
                        best, v = dist, (fromto[3:] - fromto[:3]) * (1.0 if dist >= 0.0 else -1.0)
            norm = np.linalg.norm(v)
            if best < MAX_GAP and norm > 1e-9:
                out[t, side] = v / norm
    return out


def hold_weights(hand: np.ndarray, directions: np.ndarray) -> np.ndarray:
    """(T,) in [0, 1]: 1 in frames where both hands touch the object from opposite sides, rising over the first
    and falling over the last ``RAMP // 2`` frames of each such hold, 0 elsewhere."""
    opposed = (directions[:, 0] * directions[:, 1]).sum(-1) < OPPOSITION
    mask = (hand.all(-1) & opposed).astype(float)
    pad = RAMP // 2
    smooth = np.convolve(np.pad(mask, pad), np.ones(RAMP) / RAMP, mode="valid")
    return mask * smooth


def squeeze_offsets(scene: Scene, force: float, qpos: np.ndarray, hand: np.ndarray) -> np.ndarray:
    """(T, J*3) PD-target offsets that press each wrist with ``force`` N toward the object in antipodal
    two-handed holds, from the reference states ``qpos`` (T, nq: humanoid and objects) and the reference's hand
    contact ``hand`` (T, 2) bool; zero outside the arms' hinges and outside such holds."""
    m = scene.model
    skel, roles = scene.skeleton, scene.humanoid.roles
    T = len(qpos)
    out = np.zeros((T, skel.num_joints * 3))
    if force <= 0.0 or T == 0 or not scene.dynamic_objects:
        return out
    directions = press_directions(scene, qpos, np.flatnonzero(hand.all(-1)))
    weight = hold_weights(hand, directions)
    joint_of = {int(b): j for j, b in enumerate(skel.joint_bodies)}
    chains = [[joint_of[b] for b in arm_chain(scene, side)] for side in (0, 1)]
    wrists = [int(scene.body_ids[int(w)]) for w in roles["wrists"]]
    kp = scene.gains[:, 0]
    d = mujoco.MjData(m)
    jac = np.zeros((3, m.nv))
    for t in np.flatnonzero(weight > 0.0):
        d.qpos[:] = qpos[t]
        mujoco.mj_kinematics(m, d)
        mujoco.mj_comPos(m, d)
        for side in (0, 1):
            mujoco.mj_jacBody(m, d, jac, None, wrists[side])
            tau = jac.T @ (force * weight[t] * directions[t, side])
            for j in chains[side]:
                cols = slice(3 * j, 3 * j + 3)
                out[t, cols] = tau[scene.hinge_dofadr[j]] / kp[cols]
    return out
