"""Observation terms: the proprioceptive state and the goal (future reference minus current), batched.

Everything is expressed in the root heading frame (yaw only, about the root). Goal differences are arranged
so that a world whose state equals the reference at the target frame has a zero difference block:
rotations enter as ``6D(dq) - 6D(identity)``, contacts as ``label * ((label + 1) / 2 - contact)``.
Each piece's width is given in the comments (B bodies, K tracked bodies, R rotation-tracked bodies,
C contact bodies, O dynamic objects).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import torch

from wristmimic.env.torch_math import heading_angle, quat_conj, quat_mul, tan_norm_6d, yaw_matrix


@lru_cache(maxsize=8)
def _id6(device: torch.device, dtype: torch.dtype) -> torch.Tensor:
    """6D of the identity rotation on ``device`` (made once: no host-to-device copy per step)."""
    return torch.tensor([1.0, 0.0, 0.0, 0.0, 1.0, 0.0], dtype=dtype, device=device)


@dataclass
class SimState:
    """Simulated state of N worlds (torch, float32)."""

    body_pos: torch.Tensor  # (N, B, 3)
    body_quat: torch.Tensor  # (N, B, 4)
    body_linvel: torch.Tensor  # (N, B, 3)
    body_angvel: torch.Tensor  # (N, B, 3)
    obj_pos: torch.Tensor  # (N, O, 3)
    obj_quat: torch.Tensor  # (N, O, 4)
    obj_linvel: torch.Tensor  # (N, O, 3)
    obj_angvel: torch.Tensor  # (N, O, 3)
    contact: torch.Tensor  # (N, B) bool: net contact force above threshold (any partner)
    contact_force: torch.Tensor  # (N, B, 3)
    contact_obj: torch.Tensor  # (N, B) bool: touches a dynamic object
    joint_vel: torch.Tensor  # (N, D)
    points: torch.Tensor  # (N, P, 3) dynamic objects' surface points in the world


@dataclass
class RefFrame:
    """Reference quantities gathered at one target frame per world."""

    body_pos: torch.Tensor  # (N, B, 3)
    body_quat: torch.Tensor  # (N, B, 4)
    obj_pos: torch.Tensor  # (N, O, 3)
    obj_quat: torch.Tensor  # (N, O, 4)
    points: torch.Tensor  # (N, P, 3)
    labels: torch.Tensor  # (N, B) int8
    hand: torch.Tensor  # (N, 2) bool
    near_vec: torch.Tensor  # (N, B, 3) each body minus its nearest object surface point


@dataclass
class GoalRef:
    """Reference quantities of the goal blocks at H horizons, (H, N, ...) float32 (gathered in one go)."""

    body_pos: torch.Tensor  # (H, N, K, 3) tracked bodies
    body_quat: torch.Tensor  # (H, N, R, 4) rotation-tracked bodies
    obj_pos: torch.Tensor  # (H, N, O, 3)
    obj_quat: torch.Tensor  # (H, N, O, 4)
    ig: torch.Tensor  # (H, N, K, 3) ig_feature of the tracked bodies' reference near vectors
    labels: torch.Tensor  # (H, N, C) contact labels of the contact bodies, as float
    hand: torch.Tensor  # (H, N, 2) reference hand contact, as float


def point_sq_dists(pos: torch.Tensor, points: torch.Tensor) -> torch.Tensor:
    """(N, M, 3) positions, (N, P, 3) points -> (N, M, P) squared distances, one batched matmul of
    [x, |x|^2, 1] . [-2p, 1, |p|^2]; never materialises (N, M, P, 3). Not clamped: a pair closer than the
    float32 rounding of |x|^2 + |p|^2 may come out slightly negative (users clamp, e.g. the IG weights)."""
    one_a, one_b = pos.new_ones(*pos.shape[:-1], 1), points.new_ones(*points.shape[:-1], 1)
    a = torch.cat([pos, pos.square().sum(-1, keepdim=True), one_a], -1)
    b = torch.cat([-2.0 * points, one_b, points.square().sum(-1, keepdim=True)], -1)
    return torch.bmm(a, b.transpose(1, 2))


def nearest_vectors(pos: torch.Tensor, points: torch.Tensor, sq_dists: torch.Tensor | None = None) -> torch.Tensor:
    """(N, M, 3) positions, (N, P, 3) points -> (N, M, 3) vector from the nearest point to each position;
    ``sq_dists`` (N, M, P): :func:`point_sq_dists` of the same, if already computed."""
    n, p = points.shape[:2]
    if p == 0:
        return torch.zeros_like(pos)
    d = point_sq_dists(pos, points) if sq_dists is None else sq_dists
    idx = d.min(-1).indices + torch.arange(0, n * p, p, device=pos.device)[:, None]  # first minimum
    return pos - points.reshape(n * p, 3).index_select(0, idx.flatten()).view(pos.shape)


def ig_feature(v: torch.Tensor, decay: float = 5.0) -> torch.Tensor:
    """InterMimic's interaction-graph transform v / |v| * exp(-decay |v|)."""
    n = torch.linalg.vector_norm(v, dim=-1, keepdim=True).clamp_min_(1e-6)
    return v * (torch.exp(-decay * n) / n)


def heading_matrix(root_quat: torch.Tensor) -> torch.Tensor:
    """(N, 4) root orientation -> (N, 3, 3) M with ``v @ M`` = v rotated into the heading frame (inverse yaw)."""
    return yaw_matrix(heading_angle(root_quat))


def observation_parts(
    s: SimState,
    near_vec: torch.Tensor,
    sim_hand: torch.Tensor,
    goal: GoalRef,
    horizons: tuple[int, ...],
    tracked: torch.Tensor,
    rotated: torch.Tensor,
    contact_bodies: torch.Tensor,
    state_contact_bodies: torch.Tensor | None,
) -> dict[str, list[torch.Tensor]]:
    """The observation as named parts, each a list of (N, w) pieces: the concatenation of every piece in order
    is the observation vector (one copy).

    ``state``: (N, 1 + 3(B-1) + 6B + 3B + 3B + C + 15 O + 3B) root height, body positions relative to the root,
    body orientations (6D), linear and angular velocities, contact markers, object position, orientation and
    velocities, interaction graph (:func:`ig_feature` of ``near_vec``); C = ``state_contact_bodies`` (None:
    all B bodies in order). Per
    horizon k, ``goal<k>/<piece>``: dpos 3K, ref_pos 3K, drot 6R, obj_dpos 3O, obj_drot 6O, dig 3K, dcontact C
    (``contact_bodies``), dhand 2.

    ``near_vec`` (N, B, 3) is :func:`nearest_vectors` of the bodies, ``sim_hand`` (N, 2) bool the simulated
    hand contacts, ``goal`` the reference at the horizons. Every 3-vector of every piece is rotated into the
    heading frame by one batched matmul; orientations enter as the columns of their rotation matrix (6D).
    """
    N, B, O, H = s.body_pos.shape[0], s.body_pos.shape[1], s.obj_pos.shape[1], len(horizons)
    K, R = len(tracked), len(rotated)
    rot = heading_matrix(s.body_quat[:, 0])
    c, sn = rot[:, 0, 0, None, None], rot[:, 1, 0, None, None]  # cos / sin of the heading
    root = s.body_pos[:, 0]
    # orientations: simulated bodies and objects, then dq = q_ref * conj(q) of every horizon (bodies, objects)
    q_sim = torch.cat([s.body_quat.index_select(1, rotated), s.obj_quat], 1)
    q_ref = torch.cat([goal.body_quat, goal.obj_quat], 2).transpose(0, 1).reshape(N, H * (R + O), 4)
    dq = quat_mul(q_ref, quat_conj(q_sim).repeat(1, H, 1))
    t6 = tan_norm_6d(torch.cat([s.body_quat, s.obj_quat, dq], 1))
    # heading conjugation h dq h^-1: its matrix columns are h (c D0 + s D1) and h (c D1 - s D0), D = R(dq) - I
    d = t6[:, B + O :] - _id6(t6.device, t6.dtype)
    d0, d1 = d[..., :3], d[..., 3:]
    drot = torch.cat([c * d0 + sn * d1, c * d1 - sn * d0], -1).view(N, H, R + O, 6)
    ig = ig_feature(near_vec)
    dpos = goal.body_pos - s.body_pos.index_select(1, tracked)  # (H, N, K, 3)
    ref_pos = goal.body_pos - root[:, None]
    obj_dpos = goal.obj_pos - s.obj_pos
    dig = goal.ig - ig.index_select(1, tracked)
    vec = [
        s.body_pos[:, 1:] - root[:, None],  # B-1
        t6[:, :B].reshape(N, 2 * B, 3),  # 2B
        s.body_linvel,  # B
        s.body_angvel,  # B
        s.obj_pos - root[:, None],  # O
        t6[:, B : B + O].reshape(N, 2 * O, 3),  # 2O
        s.obj_linvel,  # O
        s.obj_angvel,  # O
        ig,  # B
    ]
    for h in range(H):
        vec += [
            dpos[h],  # K
            ref_pos[h],  # K
            drot[:, h, :R].reshape(N, 2 * R, 3),  # 2R
            obj_dpos[h],  # O
            drot[:, h, R:].reshape(N, 2 * O, 3),  # 2O
            dig[h],  # K
        ]
    y = torch.bmm(torch.cat(vec, 1), rot).flatten(1)  # every vector in the heading frame
    a = 3 * (B - 1 + 2 * B + 2 * B)  # positions, orientations, velocities of the bodies
    b = a + 3 * (O + 2 * O + 2 * O + B)  # objects and the interaction graph
    contact = s.contact if state_contact_bodies is None else s.contact.index_select(1, state_contact_bodies)
    parts = {"state": [root[:, 2:3], y[:, :a], contact.to(y.dtype), y[:, a:b]]}
    label = goal.labels
    dcontact = label * ((label + 1) / 2 - s.contact_obj.index_select(1, contact_bodies).to(y.dtype))  # (H, N, C)
    dhand = goal.hand - sim_hand.to(y.dtype)
    widths = {"dpos": 3 * K, "ref_pos": 3 * K, "drot": 6 * R, "obj_dpos": 3 * O, "obj_drot": 6 * O, "dig": 3 * K}
    for h, k in enumerate(horizons):
        for name, w in widths.items():
            parts[f"goal{k}/{name}"] = [y[:, b : b + w]]
            b += w
        parts[f"goal{k}/dcontact"] = [dcontact[h]]
        parts[f"goal{k}/dhand"] = [dhand[h]]
    return parts
