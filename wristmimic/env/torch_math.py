"""Batched quaternion helpers in torch for the environment (wxyz, unit norm, Hamilton product, Z up).

The numpy reference implementation is :mod:`wristmimic.rotations`; these functions match it and broadcast
over leading axes. They are written for float32 tensors on any device and never loop in Python.
"""

from __future__ import annotations

import torch


def quat_conj(q: torch.Tensor) -> torch.Tensor:
    """Conjugate (= inverse for unit quaternions) of (..., 4) wxyz quaternions."""
    return torch.cat([q[..., :1], -q[..., 1:]], dim=-1)


def quat_mul(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """Hamilton product a * b of (..., 4) wxyz quaternions (broadcasting)."""
    aw, ax, ay, az = a.unbind(-1)
    bw, bx, by, bz = b.unbind(-1)
    return torch.stack(
        [
            aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
        ],
        dim=-1,
    )


def quat_rotate(q: torch.Tensor, v: torch.Tensor) -> torch.Tensor:
    """Rotate (..., 3) vectors by (..., 4) wxyz unit quaternions (broadcasting): v + 2w(u x v) + 2u x (u x v)."""
    u = q[..., 1:]
    u, v = torch.broadcast_tensors(u, v)
    t = 2.0 * torch.linalg.cross(u, v, dim=-1)
    return v + q[..., :1] * t + torch.linalg.cross(u, t, dim=-1)


def quat_angle(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """Angle (rad, in [0, pi]) of the rotation from a to b: 2 atan2(|v|, |w|) of conj(a) * b (sign-invariant)."""
    d = quat_mul(quat_conj(a), b)
    return 2.0 * torch.atan2(torch.linalg.vector_norm(d[..., 1:], dim=-1), d[..., 0].abs())


def heading_angle(q: torch.Tensor) -> torch.Tensor:
    """Yaw (rad, in (-pi, pi]) of (..., 4) wxyz orientations with Z up: direction of the rotated x axis in xy."""
    w, x, y, z = q.unbind(-1)
    # first column of the rotation matrix, x and y components (R[0, 0], R[1, 0])
    return torch.atan2(2.0 * (x * y + w * z), 1.0 - 2.0 * (y * y + z * z))


def heading_quat(q: torch.Tensor) -> torch.Tensor:
    """Yaw-only (about +Z) wxyz quaternion (..., 4) with the heading of q."""
    half = 0.5 * heading_angle(q)
    zero = torch.zeros_like(half)
    return torch.stack([torch.cos(half), zero, zero, torch.sin(half)], dim=-1)


def tan_norm_6d(q: torch.Tensor) -> torch.Tensor:
    """(..., 4) wxyz -> (..., 6) = [R00, R10, R20, R01, R11, R21]: rotated x axis, then rotated y axis.

    These are the first two *columns* of the rotation matrix, column by column; the identity gives
    [1, 0, 0, 0, 1, 0]. (ParaHome's raw 6D, see :mod:`wristmimic.rotations`, uses rows instead.)
    """
    w, x, y, z = q.unbind(-1)
    return torch.stack(
        [
            1.0 - 2.0 * (y * y + z * z),
            2.0 * (x * y + w * z),
            2.0 * (x * z - w * y),
            2.0 * (x * y - w * z),
            1.0 - 2.0 * (x * x + z * z),
            2.0 * (y * z + w * x),
        ],
        dim=-1,
    )


def quat_to_matrix(q: torch.Tensor) -> torch.Tensor:
    """(..., 4) wxyz unit quaternions -> (..., 3, 3) rotation matrices (``R @ v`` = :func:`quat_rotate`)."""
    w, x, y, z = q.unbind(-1)
    xx, yy, zz, xy, xz, yz, wx, wy, wz = x * x, y * y, z * z, x * y, x * z, y * z, w * x, w * y, w * z
    m = [
        [1.0 - 2.0 * (yy + zz), 2.0 * (xy - wz), 2.0 * (xz + wy)],
        [2.0 * (xy + wz), 1.0 - 2.0 * (xx + zz), 2.0 * (yz - wx)],
        [2.0 * (xz - wy), 2.0 * (yz + wx), 1.0 - 2.0 * (xx + yy)],
    ]
    return torch.stack([e for row in m for e in row], dim=-1).unflatten(-1, (3, 3))


def yaw_matrix(yaw: torch.Tensor) -> torch.Tensor:
    """(...,) angles -> (..., 3, 3) rotations about +Z by ``yaw``."""
    c, s = torch.cos(yaw), torch.sin(yaw)
    zero, one = torch.zeros_like(c), torch.ones_like(c)
    return torch.stack([c, -s, zero, s, c, zero, zero, zero, one], dim=-1).unflatten(-1, (3, 3))


def quat_to_rotvec(q: torch.Tensor) -> torch.Tensor:
    """(..., 4) wxyz -> (..., 3) rotation vector (axis * angle, angle in [0, pi]); the shorter way round."""
    q = torch.where(q[..., :1] < 0, -q, q)
    v = q[..., 1:]
    s = torch.linalg.vector_norm(v, dim=-1, keepdim=True)
    angle = 2.0 * torch.atan2(s, q[..., :1])
    scale = torch.where(s > 1e-8, angle / s.clamp_min(1e-8), torch.full_like(s, 2.0))  # small angles: 2 v
    return v * scale
