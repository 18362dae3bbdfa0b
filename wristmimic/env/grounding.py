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


def _pose(scene: Scene, d: mujoco.MjData, root_pos: np.ndarray, root_quat: np.ndarray, angles: np.ndarray) -> None:
    """Pose the humanoid of ``d`` (root position, wxyz quaternion, hinge angles in actuator order); kinematics only."""
    m = scene.model
    d.qpos[:] = m.qpos0
    d.qpos[0:3], d.qpos[3:7] = root_pos, root_quat
    d.qpos[scene.hinge_qposadr.reshape(-1)] = angles
    mujoco.mj_kinematics(m, d)


def _floors(m: mujoco.MjModel) -> list[int]:
    """Geoms of the world body that are planes (the floor)."""
    return [g for g in range(m.ngeom) if m.geom_bodyid[g] == 0 and m.geom_type[g] == mujoco.mjtGeom.mjGEOM_PLANE]


def _colliding(m: mujoco.MjModel, bodies: set[int]) -> list[int]:
    """Geoms of the model bodies ``bodies`` that take part in collisions."""
    return [g for g in range(m.ngeom) if m.geom_bodyid[g] in bodies and (m.geom_contype[g] or m.geom_conaffinity[g])]


def floor_clearance(scene: Scene, root_pos: np.ndarray, root_quat: np.ndarray, joint_angles: np.ndarray) -> float:
    """Median over frames of the humanoid's lowest geom height above the floor (m; negative: below it); 0.0 when
    the scene has no floor. Root pose (T, 3) / (T, 4) wxyz, hinge angles (T, J*3) in actuator order."""
    m = scene.model
    floors = _floors(m)
    if not floors:
        return 0.0
    human = set(int(b) for b in scene.body_ids)
    geoms = _colliding(m, human)
    d = mujoco.MjData(m)
    fromto = np.zeros(6)
    lowest = np.empty(len(joint_angles))
    for t in range(len(joint_angles)):
        _pose(scene, d, root_pos[t], root_quat[t], joint_angles[t])
        lowest[t] = min(mujoco.mj_geomDistance(m, d, g, f, 1.0, fromto) for g in geoms for f in floors)
    return float(np.median(lowest))


def foot_floor_contact(
    scene: Scene,
    root_pos: np.ndarray,
    root_quat: np.ndarray,
    joint_angles: np.ndarray,
    feet: np.ndarray,
    margin: float = 0.02,
) -> np.ndarray:
    """(T, F) bool: foot body ``feet[i]`` of the reference stands on the floor at frame t, i.e. its lowest collision
    geom lies within ``margin`` (m) of the standing height (:func:`floor_clearance`: a mocap reference floats or
    sinks by a few cm on the simulated floor). A swinging foot of sub2 or the kettle clears it by 3-9 cm at the
    ball of the foot. No floor: every foot is off it."""
    m = scene.model
    T, F = len(joint_angles), len(feet)
    floors = _floors(m)
    if not floors or F == 0:
        return np.zeros((T, F), bool)
    body_ids = [int(scene.body_ids[int(b)]) for b in feet]
    geoms = [_colliding(m, {b}) for b in body_ids]
    if any(not g for g in geoms):
        raise ValueError("a foot body has no collision geom")
    stand = floor_clearance(scene, root_pos, root_quat, joint_angles)
    d, fromto = mujoco.MjData(m), np.zeros(6)
    out = np.zeros((T, F), bool)
    for t in range(T):
        _pose(scene, d, root_pos[t], root_quat[t], joint_angles[t])
        for i, gs in enumerate(geoms):
            low = min(mujoco.mj_geomDistance(m, d, g, f, 1.0, fromto) for g in gs for f in floors)
            out[t, i] = low < stand + margin
    return out


SWING_SPEED = 0.15
"""m/s: a foot whose ankle moves faster than this over the ground (horizontally) is swinging."""


def _foot_chains(scene: Scene) -> list[tuple[list[int], np.ndarray, np.ndarray, int]]:
    """Per side: (the foot's colliding geoms, the leg's hinge qpos addresses, their dof addresses, the foot body
    nearest the root (the ankle), a skeleton index); the leg is every joint from the hip down to the toe. Empty
    where the roles name no feet."""
    m, skel = scene.model, scene.skeleton
    feet = [int(b) for b in scene.humanoid.roles.get("feet", [])]
    out = []
    for prefix in ("L_", "R_"):
        side = [b for b in feet if skel.body_names[b].startswith(prefix)]
        if not side:
            continue
        chain = set(side)
        b = min(side, key=lambda x: sum(1 for _ in _ancestors(skel.parents, x)))  # the foot body nearest the root
        chain.update(a for a in _ancestors(skel.parents, b) if skel.parents[a] >= 0)  # up to (not incl.) the root
        joints = [j for j, jb in enumerate(skel.joint_bodies) if int(jb) in chain]
        geoms = [
            g
            for bb in side
            for g in range(
                m.body_geomadr[scene.body_ids[bb]],
                m.body_geomadr[scene.body_ids[bb]] + m.body_geomnum[scene.body_ids[bb]],
            )
            if m.geom_contype[g] or m.geom_conaffinity[g]
        ]
        out.append((geoms, scene.hinge_qposadr[joints].reshape(-1), scene.hinge_dofadr[joints].reshape(-1), b))
    return out


def _ancestors(parents: np.ndarray, b: int):
    while b >= 0:
        b = int(parents[b])
        if b >= 0:
            yield b


def lift_feet(
    scene: Scene,
    root_pos: np.ndarray,
    root_quat: np.ndarray,
    joint_angles: np.ndarray,
    clearance: float,
    fps: float,
    iterations: int = 20,
) -> tuple[np.ndarray, int]:
    """Hinge angles (T, J*3) whose feet clear the floor: a swinging foot (ankle faster than :data:`SWING_SPEED`
    over the ground) keeps its lowest point ``clearance`` above it, a standing foot at least on it, by damped
    least squares on that leg's hinges (hip to toe) moving the lowest point straight up. The target height is the
    swing indicator smoothed over 7 frames times ``clearance``, so it rises and falls with the step. Returns the
    angles and how many foot-frames changed."""
    m = scene.model
    floors = _floors(m)
    chains = _foot_chains(scene)
    out = np.array(joint_angles, dtype=np.float64, copy=True)
    if not floors or not chains or clearance < 0:
        return out, 0
    d = mujoco.MjData(m)
    col = {int(a): k for k, a in enumerate(scene.hinge_qposadr.reshape(-1))}
    T = len(out)

    def pose(t: int) -> None:
        _pose(scene, d, root_pos[t], root_quat[t], out[t])
        mujoco.mj_comPos(m, d)  # mj_jac needs it

    def lowest(geoms: list[int]) -> tuple[float, np.ndarray, int]:
        best, point, body, ft = np.inf, np.zeros(3), 0, np.zeros(6)
        for g in geoms:
            for f in floors:
                dist = mujoco.mj_geomDistance(m, d, g, f, 1.0, ft)
                if dist < best:
                    best, point, body = dist, ft[:3].copy(), int(m.geom_bodyid[g])
        return best, point, body

    # swing indicator per side from the ankle's horizontal speed
    ankles = forward_bodies(scene, root_pos, root_quat, out)[0][:, [c[3] for c in chains], :2]  # (T, sides, 2)
    speed = np.zeros(ankles.shape[:2])
    if T > 1:
        speed[:-1] = np.linalg.norm(np.diff(ankles, axis=0), axis=-1) * fps
        speed[-1] = speed[-2]
    swing = np.pad((speed > SWING_SPEED).astype(np.float64), ((3, 3), (0, 0)), mode="edge")
    heights = [clearance * np.convolve(swing[:, k], np.ones(7) / 7, mode="valid") for k in range(len(chains))]
    lo, hi = scene.skeleton.joint_range.reshape(-1, 2).T
    jacp = np.zeros((3, m.nv))
    changed = 0
    for t in range(T):
        for (geoms, qa, da, _), h in zip(chains, heights, strict=True):
            pose(t)
            dist, point, body = lowest(geoms)
            if dist >= h[t] - 1e-4:
                continue
            changed += 1
            cols = [col[int(a)] for a in qa]
            for _ in range(iterations):
                mujoco.mj_jac(m, d, jacp, None, point, body)
                J = jacp[:, da]
                err = np.array([0.0, 0.0, h[t] - dist])
                dq = J.T @ np.linalg.solve(J @ J.T + 1e-4 * np.eye(3), err)
                out[t, cols] = np.clip(out[t, cols] + dq, lo[cols], hi[cols])
                pose(t)
                dist, point, body = lowest(geoms)
                if dist >= h[t] - 1e-4:
                    break
    return out, changed


def forward_bodies(scene: Scene, root_pos: np.ndarray, root_quat: np.ndarray, joint_angles: np.ndarray):
    """MuJoCo forward kinematics of the humanoid: body positions (T, B, 3) and wxyz quaternions (T, B, 4)."""
    m = scene.model
    d = mujoco.MjData(m)
    T, ids = len(joint_angles), scene.body_ids
    pos, quat = np.empty((T, len(ids), 3)), np.empty((T, len(ids), 4))
    for t in range(T):
        _pose(scene, d, root_pos[t], root_quat[t], joint_angles[t])
        pos[t], quat[t] = d.xpos[ids], d.xquat[ids]
    return pos, quat
