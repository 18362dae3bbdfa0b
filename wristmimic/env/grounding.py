"""Reference grounding: lower the humanoid's reference onto the simulated floor.

A mocap reference posed on a fitted humanoid need not stand on the floor: on ``sub2_largetable_000`` the lowest
humanoid geom (a foot box) is 1.5-2.9 cm above the floor in every frame (the table rests on it, -0.3 cm), and on
``s110_move_kettle`` 2.1-2.7 cm. Simulated, the humanoid drops onto the floor at every reset, so each body is
~2 cm below its reference for the rest of the episode, and the reference's swing foot, which rises only 2.6 cm
above its stance height when sub2 steps back carrying the table, barely clears the floor. With
``EnvConfig.ground_reference`` the humanoid's reference (root and every body; not the objects) is lowered by the
sequence's floor clearance: the median over frames of the lowest humanoid geom's height above the floor (at any
frame a foot stands, so the median is the standing feet's clearance; a jump does not move it). Computed once per
scene and reference with MuJoCo's geometry, deterministic; training, evaluation and ``view`` load the same.
"""

from __future__ import annotations

import mujoco
import numpy as np

from wristmimic.scene import Scene


def floor_clearance(scene: Scene, root_pos: np.ndarray, root_quat: np.ndarray, joint_angles: np.ndarray) -> float:
    """Median over frames of the humanoid's lowest geom height above the floor (m; negative: below it); 0.0 when
    the scene has no floor. Root pose (T, 3) / (T, 4) wxyz, hinge angles (T, J*3) in actuator order."""
    m = scene.model
    floors = [g for g in range(m.ngeom) if m.geom_bodyid[g] == 0 and m.geom_type[g] == mujoco.mjtGeom.mjGEOM_PLANE]
    if not floors:
        return 0.0
    human = set(int(b) for b in scene.body_ids)
    geoms = [g for g in range(m.ngeom) if m.geom_bodyid[g] in human and (m.geom_contype[g] or m.geom_conaffinity[g])]
    d = mujoco.MjData(m)
    qadr = scene.hinge_qposadr.reshape(-1)
    fromto = np.zeros(6)
    lowest = np.empty(len(joint_angles))
    for t in range(len(joint_angles)):
        d.qpos[:] = m.qpos0
        d.qpos[0:3], d.qpos[3:7] = root_pos[t], root_quat[t]
        d.qpos[qadr] = joint_angles[t]
        mujoco.mj_kinematics(m, d)
        lowest[t] = min(mujoco.mj_geomDistance(m, d, g, f, 1.0, fromto) for g in geoms for f in floors)
    return float(np.median(lowest))
