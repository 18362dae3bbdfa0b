"""Gravity feedforward: PD-target offsets that hold the reference pose against gravity.

A position actuator holds its target only where no load acts: under gravity each hinge settles where
``kp (target - q)`` balances the weight it carries, so a bent torso sags (on ``sub2_largetable_000`` the wrists
fall 1 -> 9 cm below their reference within four frames of bending over the table, with PD gains alone). With
``EnvConfig.gravity_feedforward`` the residual hinges of the upper body target ``q_ref + tau_g(q_ref) / kp``,
where ``tau_g`` is the generalised gravity force at the reference pose (MuJoCo's ``qfrc_bias`` at zero velocity):
a PD loop then balances gravity at exactly the reference pose, and the policy's residual only has to correct
what gravity compensation does not model (contacts, carried objects, dynamics).

Leg hinges (hip to toe) get no offset: a standing leg carries the body through its foot's ground contact, which
this free-body calculation does not see. Fingers get none either (no finger reference). Computed once per scene
and reference, deterministic, used the same way by training, evaluation and ``view`` (the environment applies it).

Measured on ``sub2_largetable_000`` (zero residual actions, object held at its reference, starts 0/20/40/60/90,
40 frames): mean wrist error 15.8/16.0/15.7/11.7/16.1 -> 12.9/13.0/11.0/7.9/9.4 cm, hand-table contact in
reference-contact frames 2/40 -> 23/40 (start 40) and 25/40 -> 39/40 (start 60); offsets up to 0.095 rad. Full
inverse dynamics (reference velocities, finite-difference accelerations) gave the same (12.8/12.4/11.1/7.8/9.5).
"""

from __future__ import annotations

import mujoco
import numpy as np

from wristmimic.scene import Scene


def leg_bodies(scene: Scene) -> list[int]:
    """Skeleton bodies of the legs: every foot body's ancestors below the root, and their subtrees."""
    skel = scene.skeleton
    out: set[int] = set()
    for foot in scene.humanoid.roles["feet"]:
        b = int(foot)
        while b > 0 and skel.parents[b] > 0:
            b = int(skel.parents[b])
        out.update(skel.subtree(b))
    return sorted(out)


def upper_body_hinges(scene: Scene) -> np.ndarray:
    """(J*3,) bool: hinges of the upper body (neither legs nor fingers), in actuator order."""
    excluded = set(int(b) for b in scene.humanoid.roles["fingers"]) | set(leg_bodies(scene))
    return np.repeat([int(b) not in excluded for b in scene.skeleton.joint_bodies], 3)


def gravity_offsets(scene: Scene, root_pos: np.ndarray, root_quat: np.ndarray, joint_angles: np.ndarray) -> np.ndarray:
    """(T, J*3) PD-target offsets ``tau_g / kp`` of every hinge at each reference frame (root pose (T, 3) /
    (T, 4) wxyz, hinge angles (T, J*3) in actuator order); zero on leg and finger hinges."""
    m = scene.model
    d = mujoco.MjData(m)
    keep = upper_body_hinges(scene)
    qadr, dadr = scene.hinge_qposadr.reshape(-1), scene.hinge_dofadr.reshape(-1)
    kp = scene.gains[:, 0]
    out = np.zeros((len(joint_angles), len(qadr)))
    tau = np.zeros(m.nv)
    for t in range(len(joint_angles)):
        d.qpos[:] = m.qpos0
        d.qpos[0:3], d.qpos[3:7] = root_pos[t], root_quat[t]
        d.qpos[qadr] = joint_angles[t]
        d.qvel[:] = 0.0
        mujoco.mj_kinematics(m, d)
        mujoco.mj_comPos(m, d)
        mujoco.mj_rne(m, d, 0, tau)  # flg_acc 0: bias forces, gravity alone at zero velocity
        out[t] = np.where(keep, tau[dadr] / kp, 0.0)
    return out
