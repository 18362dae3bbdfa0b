"""Observation terms: the proprioceptive state and the goal (future reference minus current), batched.

Everything is expressed in the root heading frame (yaw only, about the root). Goal differences are arranged
so that a world whose state equals the reference at the target frame has a zero difference block:
rotations enter as ``6D(dq) - 6D(identity)``, contacts as ``label * ((label + 1) / 2 - contact)``.
Each piece's width is given in the comments (B bodies, K tracked bodies, R rotation-tracked bodies,
C contact bodies, O dynamic objects).
"""

from __future__ import annotations

from dataclasses import dataclass

import torch

from wristmimic.env.torch_math import heading_quat, quat_conj, quat_mul, quat_rotate, tan_norm_6d

_ID6 = torch.tensor([1.0, 0.0, 0.0, 0.0, 1.0, 0.0])


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


def _frame(v: torch.Tensor, inv_heading: torch.Tensor) -> torch.Tensor:
    """Rotate (N, M, 3) world vectors into each world's heading frame."""
    return quat_rotate(inv_heading[:, None].expand(*v.shape[:-1], 4), v)


def _rot6(q: torch.Tensor, inv_heading: torch.Tensor) -> torch.Tensor:
    """(N, M, 4) world orientations -> (N, M*6) tan-norm 6D in the heading frame."""
    qh = quat_mul(inv_heading[:, None].expand_as(q), q)
    return tan_norm_6d(qh).flatten(1)


def _drot6(q_ref: torch.Tensor, q: torch.Tensor, inv_heading: torch.Tensor) -> torch.Tensor:
    """Rotation from simulated to reference orientation, in the heading frame, as 6D minus identity."""
    h = inv_heading[:, None].expand_as(q)
    dq = quat_mul(quat_mul(h, quat_mul(q_ref, quat_conj(q))), quat_conj(h))
    return (tan_norm_6d(dq) - _ID6.to(q.device)).flatten(1)


def nearest_vectors(pos: torch.Tensor, points: torch.Tensor) -> torch.Tensor:
    """(N, M, 3) positions, (N, P, 3) points -> (N, M, 3) vector from the nearest point to each position."""
    if points.shape[1] == 0:
        return torch.zeros_like(pos)
    d = torch.cdist(pos, points)  # (N, M, P)
    idx = d.argmin(-1)
    nearest = torch.gather(points, 1, idx[..., None].expand(*idx.shape, 3))
    return pos - nearest


def ig_feature(v: torch.Tensor, decay: float = 5.0) -> torch.Tensor:
    """InterMimic's interaction-graph transform v / |v| * exp(-decay |v|)."""
    n = v.norm(dim=-1, keepdim=True).clamp_min(1e-6)
    return v / n * torch.exp(-decay * n)


def state_obs(
    s: SimState, near_vec: torch.Tensor, inv_heading: torch.Tensor, contact_bodies: torch.Tensor
) -> torch.Tensor:
    """Proprioceptive state, (N, 1 + 3(B-1) + 6B + 3B + 3B + C + 15 O + 3B); ``near_vec`` (N, B, 3) is
    :func:`nearest_vectors` of the bodies."""
    root = s.body_pos[:, 0]
    rel = _frame(s.body_pos[:, 1:] - root[:, None], inv_heading)
    ig = ig_feature(_frame(near_vec, inv_heading))
    obj_rel = _frame(s.obj_pos - root[:, None], inv_heading)
    parts = [
        root[:, 2:3],  # 1 root height
        rel.flatten(1),  # 3(B-1) body positions relative to the root
        _rot6(s.body_quat, inv_heading),  # 6B body orientations
        _frame(s.body_linvel, inv_heading).flatten(1),  # 3B
        _frame(s.body_angvel, inv_heading).flatten(1),  # 3B
        s.contact[:, contact_bodies].float(),  # C contact markers
        obj_rel.flatten(1),  # 3O object position
        _rot6(s.obj_quat, inv_heading),  # 6O object orientation
        _frame(s.obj_linvel, inv_heading).flatten(1),  # 3O
        _frame(s.obj_angvel, inv_heading).flatten(1),  # 3O
        ig.flatten(1),  # 3B interaction graph
    ]
    return torch.cat(parts, dim=1)


def goal_obs(
    s: SimState,
    near_vec: torch.Tensor,
    r: RefFrame,
    inv_heading: torch.Tensor,
    tracked: torch.Tensor,
    rotated: torch.Tensor,
    contact_bodies: torch.Tensor,
    hands: tuple[torch.Tensor, torch.Tensor],
) -> dict[str, torch.Tensor]:
    """Goal block for one horizon as named pieces (their concatenation is the observation); ``near_vec``
    (N, B, 3) is :func:`nearest_vectors` of the simulated bodies."""
    root = s.body_pos[:, 0]
    sim_ig = ig_feature(near_vec[:, tracked])
    ref_ig = ig_feature(r.near_vec[:, tracked])
    label = r.labels[:, contact_bodies].float()
    sim_hand = torch.stack([s.contact_obj[:, hands[0]].any(1), s.contact_obj[:, hands[1]].any(1)], 1)
    return {
        "dpos": _frame(r.body_pos[:, tracked] - s.body_pos[:, tracked], inv_heading).flatten(1),  # 3K
        "ref_pos": _frame(r.body_pos[:, tracked] - root[:, None], inv_heading).flatten(1),  # 3K
        "drot": _drot6(r.body_quat[:, rotated], s.body_quat[:, rotated], inv_heading),  # 6R
        "obj_dpos": _frame(r.obj_pos - s.obj_pos, inv_heading).flatten(1),  # 3O
        "obj_drot": _drot6(r.obj_quat, s.obj_quat, inv_heading),  # 6O
        "dig": _frame(ref_ig - sim_ig, inv_heading).flatten(1),  # 3K
        "dcontact": label * ((label + 1) / 2 - s.contact_obj[:, contact_bodies].float()),  # C
        "dhand": r.hand.float() - sim_hand.float(),  # 2
    }


def heading_inverse(root_quat: torch.Tensor) -> torch.Tensor:
    """(N, 4) root orientation -> inverse of its yaw-only heading rotation."""
    return quat_conj(heading_quat(root_quat))
