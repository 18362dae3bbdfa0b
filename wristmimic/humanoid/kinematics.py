"""Joint rotations from global body rotations, and MuJoCo forward kinematics over a trajectory."""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from wristmimic.humanoid.skeleton import Skeleton
from wristmimic.rotations import (
    euler_xyz_to_quat,
    quat_conj,
    quat_mul,
    quat_normalize,
    quat_to_euler_xyz,
)


def local_from_global(skel: Skeleton, body_quat: np.ndarray) -> np.ndarray:
    """(T, B, 4) global body quaternions -> (T, J, 4) joint rotations ``rest^-1 * parent^-1 * child``."""
    body_quat = quat_normalize(body_quat)
    jb = skel.joint_bodies
    parent_q = body_quat[:, skel.parents[jb]]
    rel = quat_mul(quat_conj(parent_q), body_quat[:, jb])
    return quat_normalize(quat_mul(quat_conj(skel.rest_quat[jb])[None], rel))


def global_from_local(skel: Skeleton, root_quat: np.ndarray, joint_quat: np.ndarray) -> np.ndarray:
    """Inverse of :func:`local_from_global`: (T, 4) root + (T, J, 4) joints -> (T, B, 4) body quats."""
    T = root_quat.shape[0]
    out = np.zeros((T, skel.num_bodies, 4))
    out[:, 0] = quat_normalize(root_quat)
    slot = {int(b): j for j, b in enumerate(skel.joint_bodies)}
    for b in range(1, skel.num_bodies):  # parents precede children in MuJoCo order
        j = slot[b]
        out[:, b] = quat_mul(out[:, skel.parents[b]], quat_mul(skel.rest_quat[b][None], joint_quat[:, j]))
    return quat_normalize(out)


def hinge_angles(joint_quat: np.ndarray) -> np.ndarray:
    """(T, J, 4) joint rotations -> (T, J, 3) angles of the x, y, z hinges (intrinsic XYZ Euler)."""
    return quat_to_euler_xyz(joint_quat)


def joint_quat_from_hinges(angles: np.ndarray) -> np.ndarray:
    """(T, J, 3) hinge angles -> (T, J, 4) joint rotations."""
    return euler_xyz_to_quat(angles)


def qpos_from(skel: Skeleton, root_pos: np.ndarray, root_quat: np.ndarray, angles: np.ndarray) -> np.ndarray:
    """Assemble (T, nq) MuJoCo qpos from root position, root quaternion (wxyz) and hinge angles."""
    T = root_pos.shape[0]
    qpos = np.zeros((T, skel.nq))
    qpos[:, 0:3] = root_pos
    qpos[:, 3:7] = quat_normalize(root_quat)
    qpos[:, skel.hinge_qposadr.reshape(-1)] = angles.reshape(T, -1)
    return qpos


@dataclass
class FKResult:
    """World poses over a trajectory; bodies exclude the world body."""

    body_pos: np.ndarray  # (T, B, 3)
    body_quat: np.ndarray  # (T, B, 4) wxyz
    geom_pos: np.ndarray | None = None  # (T, G, 3), all model geoms
    geom_mat: np.ndarray | None = None  # (T, G, 3, 3)


def forward_kinematics(model: mujoco.MjModel, qpos: np.ndarray, *, geoms: bool = False) -> FKResult:
    """MuJoCo ``mj_kinematics`` for every row of ``qpos`` (T, nq)."""
    data = mujoco.MjData(model)
    T = qpos.shape[0]
    nb = model.nbody - 1
    pos = np.empty((T, nb, 3))
    quat = np.empty((T, nb, 4))
    gpos = np.empty((T, model.ngeom, 3)) if geoms else None
    gmat = np.empty((T, model.ngeom, 3, 3)) if geoms else None
    for t in range(T):  # conversion-time only (not a simulation hot path)
        data.qpos[:] = qpos[t]
        mujoco.mj_kinematics(model, data)
        pos[t] = data.xpos[1:]
        quat[t] = data.xquat[1:]
        if geoms:
            gpos[t] = data.geom_xpos
            gmat[t] = data.geom_xmat.reshape(-1, 3, 3)
    return FKResult(pos, quat, gpos, gmat)
