"""Rotation conversions, vectorised over leading axes.

Convention inside the project: quaternions are **wxyz** (MuJoCo), unit norm, Hamilton product.
Sources differ: InterMimic and rerun use xyzw, SkillMimic ParaHome uses rotation vectors, raw ParaHome
uses 6D = the first two *rows* of R. Convert once, at the edge, with these functions.
"""

from __future__ import annotations

import numpy as np

_EPS = 1e-12


def xyzw_to_wxyz(q: np.ndarray) -> np.ndarray:
    """Reorder (..., 4) quaternions from xyzw (InterMimic, SciPy, rerun) to wxyz (MuJoCo)."""
    q = np.asarray(q)
    return np.concatenate([q[..., 3:4], q[..., 0:3]], axis=-1)


def wxyz_to_xyzw(q: np.ndarray) -> np.ndarray:
    """Reorder (..., 4) quaternions from wxyz to xyzw."""
    q = np.asarray(q)
    return np.concatenate([q[..., 1:4], q[..., 0:1]], axis=-1)


def quat_normalize(q: np.ndarray) -> np.ndarray:
    """Unit-normalise (..., 4) quaternions."""
    q = np.asarray(q, dtype=np.float64)
    return q / np.maximum(np.linalg.norm(q, axis=-1, keepdims=True), _EPS)


def quat_canonical(q: np.ndarray) -> np.ndarray:
    """Sign-canonical form (w >= 0), so that q and -q compare equal."""
    q = np.asarray(q, dtype=np.float64)
    return np.where(q[..., :1] < 0, -q, q)


def quat_conj(q: np.ndarray) -> np.ndarray:
    """Conjugate (= inverse for unit quaternions) of (..., 4) wxyz quaternions."""
    q = np.asarray(q, dtype=np.float64)
    return np.concatenate([q[..., :1], -q[..., 1:]], axis=-1)


def quat_mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product a * b of wxyz quaternions (broadcasting)."""
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    aw, ax, ay, az = np.moveaxis(a, -1, 0)
    bw, bx, by, bz = np.moveaxis(b, -1, 0)
    return np.stack(
        [
            aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
        ],
        axis=-1,
    )


def quat_rotate(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Rotate (..., 3) vectors by (..., 4) wxyz quaternions."""
    q = np.asarray(q, dtype=np.float64)
    v = np.asarray(v, dtype=np.float64)
    w = q[..., :1]
    u = q[..., 1:]
    t = 2.0 * np.cross(u, v)
    return v + w * t + np.cross(u, t)


def quat_angle(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Angle (rad) of the rotation between wxyz quaternions a and b."""
    d = np.abs(np.sum(quat_normalize(a) * quat_normalize(b), axis=-1))
    return 2.0 * np.arccos(np.clip(d, 0.0, 1.0))


def quat_to_matrix(q: np.ndarray) -> np.ndarray:
    """(..., 4) wxyz -> (..., 3, 3) rotation matrices."""
    w, x, y, z = np.moveaxis(quat_normalize(q), -1, 0)
    return np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
            np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
            np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
        ],
        axis=-2,
    )


def matrix_to_quat(m: np.ndarray) -> np.ndarray:
    """(..., 3, 3) rotation matrices -> (..., 4) wxyz unit quaternions with w >= 0 (Shepperd's method)."""
    m = np.asarray(m, dtype=np.float64)
    shape = m.shape[:-2]
    m = m.reshape(-1, 3, 3)
    tr = m[:, 0, 0] + m[:, 1, 1] + m[:, 2, 2]
    diag = np.stack([m[:, 0, 0], m[:, 1, 1], m[:, 2, 2]], axis=-1)
    case = np.argmax(np.concatenate([tr[:, None], diag], axis=-1), axis=-1)
    q = np.empty((m.shape[0], 4))
    # case 0: trace largest
    s = np.sqrt(np.maximum(1.0 + tr, _EPS)) * 2.0
    q0 = np.stack(
        [0.25 * s, (m[:, 2, 1] - m[:, 1, 2]) / s, (m[:, 0, 2] - m[:, 2, 0]) / s, (m[:, 1, 0] - m[:, 0, 1]) / s], -1
    )
    s1 = np.sqrt(np.maximum(1.0 + m[:, 0, 0] - m[:, 1, 1] - m[:, 2, 2], _EPS)) * 2.0
    q1 = np.stack(
        [(m[:, 2, 1] - m[:, 1, 2]) / s1, 0.25 * s1, (m[:, 0, 1] + m[:, 1, 0]) / s1, (m[:, 0, 2] + m[:, 2, 0]) / s1], -1
    )
    s2 = np.sqrt(np.maximum(1.0 + m[:, 1, 1] - m[:, 0, 0] - m[:, 2, 2], _EPS)) * 2.0
    q2 = np.stack(
        [(m[:, 0, 2] - m[:, 2, 0]) / s2, (m[:, 0, 1] + m[:, 1, 0]) / s2, 0.25 * s2, (m[:, 1, 2] + m[:, 2, 1]) / s2], -1
    )
    s3 = np.sqrt(np.maximum(1.0 + m[:, 2, 2] - m[:, 0, 0] - m[:, 1, 1], _EPS)) * 2.0
    q3 = np.stack(
        [(m[:, 1, 0] - m[:, 0, 1]) / s3, (m[:, 0, 2] + m[:, 2, 0]) / s3, (m[:, 1, 2] + m[:, 2, 1]) / s3, 0.25 * s3], -1
    )
    for k, qk in enumerate((q0, q1, q2, q3)):
        sel = case == k
        q[sel] = qk[sel]
    return quat_canonical(quat_normalize(q)).reshape(*shape, 4)


def rotvec_to_quat(r: np.ndarray) -> np.ndarray:
    """(..., 3) rotation vectors (axis * angle, rad; also called exp-maps) -> (..., 4) wxyz."""
    r = np.asarray(r, dtype=np.float64)
    angle = np.linalg.norm(r, axis=-1, keepdims=True)
    half = 0.5 * angle
    # sin(half)/angle, with its Taylor series near zero
    small = angle < 1e-8
    k = np.where(small, 0.5 - angle**2 / 48.0, np.sin(half) / np.where(small, 1.0, angle))
    return np.concatenate([np.cos(half), r * k], axis=-1)


def quat_to_rotvec(q: np.ndarray) -> np.ndarray:
    """(..., 4) wxyz -> (..., 3) rotation vectors with angle in [0, pi]."""
    q = quat_canonical(quat_normalize(q))
    v = q[..., 1:]
    s = np.linalg.norm(v, axis=-1, keepdims=True)
    angle = 2.0 * np.arctan2(s, q[..., :1])
    small = s < 1e-8
    k = np.where(small, 2.0 / np.maximum(q[..., :1], _EPS), angle / np.where(small, 1.0, s))
    return v * k


def _axis_quat(angle: np.ndarray, axis: int) -> np.ndarray:
    q = np.zeros(angle.shape + (4,))
    q[..., 0] = np.cos(0.5 * angle)
    q[..., 1 + axis] = np.sin(0.5 * angle)
    return q


def euler_xyz_to_quat(e: np.ndarray) -> np.ndarray:
    """Intrinsic XYZ Euler angles (..., 3) -> wxyz: q = Rx(e0) * Ry(e1) * Rz(e2).

    This is what three sequential MuJoCo hinges with axes x, y, z (in that order, in one body) produce.
    """
    e = np.asarray(e, dtype=np.float64)
    return quat_mul(quat_mul(_axis_quat(e[..., 0], 0), _axis_quat(e[..., 1], 1)), _axis_quat(e[..., 2], 2))


def quat_to_euler_xyz(q: np.ndarray) -> np.ndarray:
    """wxyz -> intrinsic XYZ Euler angles (..., 3), the inverse of :func:`euler_xyz_to_quat`.

    R = Rx(a) Ry(b) Rz(c) gives R[0,2] = sin b, R[1,2] = -sin a cos b, R[2,2] = cos a cos b,
    R[0,1] = -cos b sin c, R[0,0] = cos b cos c. b lies in [-pi/2, pi/2]; at gimbal lock c is set to 0.
    """
    m = quat_to_matrix(q)
    sb = np.clip(m[..., 0, 2], -1.0, 1.0)
    b = np.arcsin(sb)
    cb = np.sqrt(np.maximum(1.0 - sb * sb, 0.0))
    lock = cb < 1e-7
    a = np.where(lock, np.arctan2(m[..., 2, 1], m[..., 1, 1]), np.arctan2(-m[..., 1, 2], m[..., 2, 2]))
    c = np.where(lock, 0.0, np.arctan2(-m[..., 0, 1], m[..., 0, 0]))
    return np.stack([a, b, c], axis=-1)


def sixd_rows_to_matrix(d6: np.ndarray) -> np.ndarray:
    """ParaHome / PyTorch3D 6D (..., 6) = first two **rows** of R -> (..., 3, 3), Gram-Schmidt."""
    d6 = np.asarray(d6, dtype=np.float64)
    a1, a2 = d6[..., :3], d6[..., 3:]
    b1 = a1 / np.maximum(np.linalg.norm(a1, axis=-1, keepdims=True), _EPS)
    b2 = a2 - np.sum(b1 * a2, axis=-1, keepdims=True) * b1
    b2 = b2 / np.maximum(np.linalg.norm(b2, axis=-1, keepdims=True), _EPS)
    b3 = np.cross(b1, b2)
    return np.stack([b1, b2, b3], axis=-2)


def matrix_to_sixd_rows(m: np.ndarray) -> np.ndarray:
    """(..., 3, 3) -> 6D as the first two rows of R (ParaHome / PyTorch3D convention)."""
    m = np.asarray(m, dtype=np.float64)
    return np.concatenate([m[..., 0, :], m[..., 1, :]], axis=-1)
