"""Multiplicative reward of WristMimic (paper, Learning Wrist-Guided Manipulation; InterMimic's reward), batched.

r = prod_i exp(-lambda_i * E_i) (the hand-contact factor has InterMimic's form 0.5 * (1 + exp(-lambda E))).
Every ``error_*`` function returns the raw error E of one factor, shape (N,); the lambdas come from
:class:`wristmimic.env.config.RewardWeights`. :func:`compute_reward` returns the product and each factor as
``reward/<name>`` plus each raw error as ``error/<name>``, so a user sees which factor collapses.

Factors (names): body_pos, body_rot, [root_pos, root_rot, feet_pos, root_vel, body_vel,
feet_contact] (weights > 0), [wrist_pos, wrist_rot] (cfg.wrist_terms), [finger_pos, finger_rot]
(cfg.finger_targets), obj_pos, obj_rot, ig, contact_hand, contact_other, [fingertip, drive] (weights > 0),
joint_energy, obj_energy_lin, obj_energy_ang, contact_energy.
Shapes: N worlds, B bodies, O dynamic objects, K key bodies, P object surface points, D hinge joints.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import torch

from wristmimic.env.bodies import BodySets
from wristmimic.env.config import EnvConfig, RewardWeights
from wristmimic.env.torch_math import quat_angle


@dataclass(frozen=True)
class RewardConstants:
    """Fixed constants of the reward terms that are not weights (InterMimic's values; not in config.py)."""

    energy_start_step: int = 2
    """Energy factors are 1 (and their errors 0) while step < this (no valid previous velocity yet)."""
    ig_min_sq_dist: float = 0.01
    """Interaction-graph weights are 1 / max(|ig|^2, this) (m^2), bounding the weight of touching pairs."""


CONSTANTS = RewardConstants()


@dataclass
class RewardInputs:
    """Everything the reward reads, torch float32 unless stated."""

    body_pos: torch.Tensor  # (N, B, 3) simulated, world
    body_quat: torch.Tensor  # (N, B, 4) wxyz
    ref_body_pos: torch.Tensor  # (N, B, 3) reference at the tracked frame
    ref_body_quat: torch.Tensor  # (N, B, 4)
    ref_near_dist: torch.Tensor  # (N, B) reference distance body -> nearest reference object surface point (m)
    obj_pos: torch.Tensor  # (N, O, 3) dynamic objects, simulated
    obj_quat: torch.Tensor  # (N, O, 4)
    ref_obj_pos: torch.Tensor  # (N, O, 3)
    ref_obj_quat: torch.Tensor  # (N, O, 4)
    ig_pos: torch.Tensor  # (N, K, 3) simulated key-body positions (interaction-graph nodes)
    ref_ig_pos: torch.Tensor  # (N, K, 3) the same in the reference
    points: torch.Tensor  # (N, P, 3) simulated object surface points (all dynamic objects)
    ref_points: torch.Tensor  # (N, P, 3) the same in the reference
    contact_obj: torch.Tensor  # (N, B) bool: simulated body touches a dynamic object
    ref_labels: torch.Tensor  # (N, B) int8 in {-1, 0, 1}: reference contact labels
    ref_hand: torch.Tensor  # (N, 2) bool: reference hand [left, right] in contact
    sim_hand: torch.Tensor  # (N, 2) bool: any body of the simulated hand touches a dynamic object
    joint_vel: torch.Tensor  # (N, D) hinge velocities now
    prev_joint_vel: torch.Tensor  # (N, D) one control step earlier
    obj_vel: torch.Tensor  # (N, O, 6) linear + angular velocity now
    prev_obj_vel: torch.Tensor  # (N, O, 6)
    contact_force: torch.Tensor  # (N, B, 3) net contact force on each body (N)
    in_window: torch.Tensor  # (N,) bool: the tracked frame lies in the contact window
    grasp_hands: torch.Tensor  # (N, 2) bool: hands with a first contact frame in the sequence
    step: torch.Tensor  # (N,) long: control steps since the episode started
    dt: float  # control period (s)
    ig_sq_dists: torch.Tensor | None = None
    """(N, K, P) squared distances ig_pos -> points if already computed (the environment shares them with its
    nearest-point query); None: computed here."""
    tip_sq_dists: torch.Tensor | None = None
    """(N, 2, nt) squared distance of each hand's fingertips to the nearest object surface point; needed only
    by the ``fingertip`` factor."""
    body_linvel: torch.Tensor | None = None
    """(N, B, 3) simulated body-frame-origin linear velocities (world); needed only by root_vel / body_vel."""
    ref_body_linvel: torch.Tensor | None = None
    """(N, B, 3) the reference's at the tracked frame; needed only by root_vel / body_vel."""
    feet_contact: torch.Tensor | None = None
    """(N, F) bool: simulated foot bodies touching anything; needed only by feet_contact."""
    ref_feet_contact: torch.Tensor | None = None
    """(N, F) bool: the reference's foot bodies on the floor at the tracked frame; needed only by feet_contact."""
    ref_ig_weights: torch.Tensor | None = None
    """(N, K, P) the reference's normalised interaction-graph weights :func:`ig_weights` if precomputed per
    frame; None: computed here from ref_ig_pos and ref_points."""
    ref_obj_linvel: torch.Tensor | None = None
    """(N, O, 3) the reference objects' linear velocities at the tracked frame; needed only by drive."""
    obj_weight: torch.Tensor | None = None
    """(O,) the dynamic objects' weights m g (N); needed only by drive."""


# --- helpers -------------------------------------------------------------------------------------------------


def _mean(v: torch.Tensor, dims: tuple[int, ...]) -> torch.Tensor:
    """Mean over dims, 0 where those dims are empty (no objects, no points)."""
    n = 1
    for d in dims:
        n *= v.shape[d]
    return v.sum(dim=dims) / max(n, 1)


def _weighted_mean(e: torch.Tensor, m: torch.Tensor) -> torch.Tensor:
    """(N, J) errors, (N, J) weights -> (N,) sum(m e) / max(sum(m), 1)."""
    return (m * e).sum(-1) / m.sum(-1).clamp_min(1.0)


def near_weight(ref_near_dist: torch.Tensor, w: RewardWeights) -> torch.Tensor:
    """InterMimic's w_near = exp(-near_far * d): 1 at the object, -> 0 far from it."""
    return torch.exp(-w.near_far * ref_near_dist)


def tracked_bodies(sets: BodySets, cfg: EnvConfig) -> torch.Tensor:
    """Bodies of the body terms: sets.body, plus the wrists when there are no separate wrist factors."""
    return sets.body if cfg.wrist_terms else torch.cat([sets.body, sets.wrists])


def modulated(x: RewardInputs, cfg: EnvConfig) -> torch.Tensor:
    """(N,) bool: window modulation applies (cfg.window_modulation and the frame is in the contact window)."""
    return x.in_window & cfg.window_modulation


def arm_weights(x: RewardInputs, idx: torch.Tensor, sets: BodySets, cfg: EnvConfig) -> torch.Tensor:
    """(N, J) m_j(t): 0 for the shoulder/elbow of grasping side(s) while modulated, else 1."""
    left = torch.isin(idx, sets.left_arm)[None] & x.grasp_hands[:, 0:1]
    right = torch.isin(idx, sets.right_arm)[None] & x.grasp_hands[:, 1:2]
    off = (left | right) & modulated(x, cfg)[:, None]
    return (~off).to(x.body_pos.dtype)


# --- errors --------------------------------------------------------------------------------------------------


def body_errors(x: RewardInputs) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Per-body raw errors every body term selects from: (N, B) |p_ref - p|^2, (N, B) angle(q_ref, q) (rad)
    and (N, O) the objects' angle(q_ref, q), one quaternion pass for bodies and objects together."""
    sq = (x.ref_body_pos - x.body_pos).square().sum(-1)
    ang = quat_angle(torch.cat([x.ref_body_quat, x.ref_obj_quat], 1), torch.cat([x.body_quat, x.obj_quat], 1))
    B = x.body_pos.shape[1]
    return sq, ang[:, :B], ang[:, B:]


def error_pos(sq: torch.Tensor, w_near: torch.Tensor, idx: torch.Tensor, m: torch.Tensor) -> torch.Tensor:
    """E_p = sum_j m_j w_near,j |p_ref - p|^2 / max(sum_j m_j, 1) over bodies idx (position near the object);
    ``sq`` and ``w_near`` (N, B) from :func:`body_errors` and :func:`near_weight`."""
    return _weighted_mean(w_near.index_select(1, idx) * sq.index_select(1, idx), m)


def error_rot(ang: torch.Tensor, w_near: torch.Tensor, idx: torch.Tensor, m: torch.Tensor) -> torch.Tensor:
    """E_r = sum_j m_j (1 - w_near,j) angle(q_ref, q) / max(sum_j m_j, 1) over bodies idx (rotation far)."""
    return _weighted_mean((1.0 - w_near.index_select(1, idx)) * ang.index_select(1, idx), m)


def error_wrist_pos(sq: torch.Tensor, sets: BodySets) -> torch.Tensor:
    """E_wp = mean over both wrists of |p_ref - p|^2 (unweighted)."""
    return sq.index_select(1, sets.wrists).mean(-1)


def error_wrist_rot(ang: torch.Tensor, sets: BodySets) -> torch.Tensor:
    """E_wr = mean over both wrists of angle(q_ref, q) (rad)."""
    return ang.index_select(1, sets.wrists).mean(-1)


def error_root_pos(sq: torch.Tensor) -> torch.Tensor:
    """E_rootp = |p_ref - p|^2 of the root body (m^2)."""
    return sq[:, 0]


def error_feet_pos(sq: torch.Tensor, sets: BodySets) -> torch.Tensor:
    """E_fp = mean over the feet bodies (ankles and toes) of |p_ref - p|^2 (m^2, unweighted)."""
    return sq.index_select(1, sets.feet).mean(-1)


def error_root_rot(ang: torch.Tensor) -> torch.Tensor:
    """E_rootr = angle(q_ref, q) of the root body (rad)."""
    return ang[:, 0]


def _vel_sq(x: RewardInputs, name: str) -> torch.Tensor:
    """(N, B) |v_ref - v|^2 of every body; ``name`` the factor asking (for the error message)."""
    if x.body_linvel is None or x.ref_body_linvel is None:
        raise ValueError(f"weights.{name} > 0 needs body_linvel and ref_body_linvel in the reward inputs")
    return (x.ref_body_linvel - x.body_linvel).square().sum(-1)


def error_root_vel(x: RewardInputs) -> torch.Tensor:
    """E_rootv = |v_ref - v|^2 of the root body ((m/s)^2)."""
    return _vel_sq(x, "root_vel")[:, 0]


def error_body_vel(x: RewardInputs) -> torch.Tensor:
    """E_bv = mean over every body of |v_ref - v|^2 ((m/s)^2, unweighted)."""
    return _vel_sq(x, "body_vel").mean(-1)


def error_feet_contact(x: RewardInputs) -> torch.Tensor:
    """E_fc = share of foot bodies whose simulated contact differs from the reference's floor contact."""
    if x.feet_contact is None or x.ref_feet_contact is None:
        raise ValueError("weights.feet_contact > 0 needs feet_contact and ref_feet_contact in the reward inputs")
    return (x.feet_contact != x.ref_feet_contact).to(x.body_pos.dtype).mean(-1)


def error_obj_pos(x: RewardInputs) -> torch.Tensor:
    """E_op = mean over objects and xyz of (p_ref - p)^2."""
    return _mean((x.ref_obj_pos - x.obj_pos).square(), (1, 2))


def error_obj_rot(obj_ang: torch.Tensor) -> torch.Tensor:
    """E_or = mean over objects of angle(q_ref, q) (rad), from :func:`body_errors`."""
    return _mean(obj_ang, (1,))


def sq_dists(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """(N, K, 3), (N, P, 3) -> (N, K, P) squared distances, without materialising (N, K, P, 3)."""
    d = a.square().sum(-1)[:, :, None] + b.square().sum(-1)[:, None, :] - 2.0 * torch.bmm(a, b.transpose(1, 2))
    return d.clamp_min(0.0)


def ig_weights(sq: torch.Tensor, min_sq: float = CONSTANTS.ig_min_sq_dist) -> torch.Tensor:
    """(N, K, P) squared node-point distances -> interaction-graph weights 1 / max(d^2, min_sq), normalised to
    sum 1 over all pairs of each world."""
    w = sq.clamp_min(min_sq).reciprocal_()
    return w.div_(w.sum((1, 2), keepdim=True))


def error_ig(x: RewardInputs, min_sq: float = CONSTANTS.ig_min_sq_dist) -> torch.Tensor:
    """E_ig = 0.5 sum_kp |ig - ig_ref|^2 (w1 + w2), w = 1/max(|ig|^2, min_sq) normalised over all pairs.

    With ig_kp = x_k - p_p: ig - ig_ref = a_k - b_p with a = x - x_ref, b = p - p_ref, and
    |a_k - b_p|^2 = |a_k|^2 + |b_p|^2 - 2 a_k . b_p, so one batched matmul of w = w1 + w2 with [b, 1, |b|^2]
    gives every sum over p ((w b)_k, the row sums, (w |b|^2)_k): the (N, K, P) weights are read once
    (InterMimic's dense all-pairs graph).
    """
    if x.points.shape[1] == 0:
        return torch.zeros(x.body_pos.shape[0], dtype=x.body_pos.dtype, device=x.body_pos.device)
    sq = sq_dists(x.ig_pos, x.points) if x.ig_sq_dists is None else x.ig_sq_dists
    w2 = ig_weights(sq_dists(x.ref_ig_pos, x.ref_points), min_sq) if x.ref_ig_weights is None else x.ref_ig_weights
    w = sq.clamp_min(min_sq).reciprocal_()
    w = torch.addcmul(w2, w, w.sum((1, 2), keepdim=True).reciprocal_(), out=w)  # w1 / sum(w1) + w2
    a, b = x.ig_pos - x.ref_ig_pos, x.points - x.ref_points
    b_sq = b.square().sum(-1)[:, None]
    g = torch.bmm(torch.cat([b.transpose(1, 2), torch.ones_like(b_sq), b_sq], 1), w.transpose(1, 2))  # (N, 5, K)
    e = a.square().sum(-1) * g[:, 3] + g[:, 4] - 2.0 * (a.transpose(1, 2) * g[:, :3]).sum(1)
    return 0.5 * e.sum(1)


def error_contact_hand(x: RewardInputs) -> torch.Tensor:
    """(N, 2) E per hand = |c_sim - 1| where the reference hand is in contact, else 0."""
    return (x.ref_hand & ~x.sim_hand).to(x.body_pos.dtype)


def error_contact_other(x: RewardInputs, sets: BodySets) -> torch.Tensor:
    """E = sum mask |c_sim - c_ref| / max(sum mask, 1) over contact_other; target 1 at label 1, 0 at -1, 0 ignored."""
    labels = x.ref_labels.index_select(1, sets.contact_other)
    mask = (labels != 0).to(x.body_pos.dtype)
    diff = (x.contact_obj.index_select(1, sets.contact_other) != (labels > 0)).to(x.body_pos.dtype)
    return _weighted_mean(diff, mask)


def error_fingertip(x: RewardInputs) -> torch.Tensor:
    """E = sum over the hands in reference contact of the mean fingertip distance to the object surface (m)."""
    if x.tip_sq_dists is None:
        raise ValueError("weights.fingertip > 0 needs the fingertips' distances to the object (tip_sq_dists)")
    d = x.tip_sq_dists.clamp_min(0.0).sqrt().mean(-1)
    return (d * x.ref_hand.to(d.dtype)).sum(-1)


DRIVE_MIN_SPEED = 0.05
"""m/s: the drive factor looks only at frames where the reference object moves faster than this."""


def error_drive(x: RewardInputs) -> torch.Tensor:
    """E = max(0, -F . v / |v|) / (m g): the humanoid's net contact force F on the (one) dynamic object against the
    reference object's velocity v at the tracked frame (0 where |v| <= DRIVE_MIN_SPEED), over its weight. The
    contact sensors' net force of a body is the force it exerts on what it touches (world frame); every body
    touching the object counts (with only the hands counted, a policy moved its push to the forearms)."""
    if x.ref_obj_linvel is None or x.obj_weight is None:
        raise ValueError("weights.drive > 0 needs the reference object velocity and the object's weight")
    if x.ref_obj_linvel.shape[1] != 1:
        raise ValueError(
            f"weights.drive > 0 needs exactly one dynamic object, the scene has {x.ref_obj_linvel.shape[1]}"
        )
    touch = x.contact_obj.to(x.contact_force.dtype)
    force = (x.contact_force * touch[..., None]).sum(1)  # (N, 3) on the object
    v = x.ref_obj_linvel[:, 0]
    speed = torch.linalg.vector_norm(v, dim=-1)
    along = (force * v).sum(-1) / speed.clamp_min(DRIVE_MIN_SPEED)
    return torch.where(speed > DRIVE_MIN_SPEED, (-along).clamp_min(0.0) / x.obj_weight[0], 0.0)


def error_joint_energy(x: RewardInputs) -> torch.Tensor:
    """E_eg1 = mean over hinges of ((qd - qd_prev) / dt)^2 (joint acceleration)."""
    return _mean(((x.joint_vel - x.prev_joint_vel) / x.dt).square(), (1,))


def error_obj_energy_lin(x: RewardInputs) -> torch.Tensor:
    """E_eg2,lin = mean over objects and xyz of the object linear acceleration squared."""
    return _mean(((x.obj_vel[..., :3] - x.prev_obj_vel[..., :3]) / x.dt).square(), (1, 2))


def error_obj_energy_ang(x: RewardInputs) -> torch.Tensor:
    """E_eg2,ang = mean over objects and xyz of the object angular acceleration squared."""
    return _mean(((x.obj_vel[..., 3:] - x.prev_obj_vel[..., 3:]) / x.dt).square(), (1, 2))


def error_contact_energy(x: RewardInputs) -> torch.Tensor:
    """E_eg3 = (sum over bodies and xyz of |F|)^2 on the humanoid's net contact forces."""
    return x.contact_force.abs().sum((1, 2)).square()


# --- factors -------------------------------------------------------------------------------------------------


def reward_contact_hand(err: torch.Tensor, ref_hand: torch.Tensor, lam: float) -> torch.Tensor:
    """prod over hands of 0.5 (1 + exp(-lambda E)) where the reference hand is in contact, else 1."""
    f = torch.where(ref_hand, 0.5 * (1.0 + torch.exp(-lam * err)), torch.ones_like(err))
    return f.prod(-1)


@lru_cache(maxsize=32)
def _lambda_rows(
    lams: tuple[float, ...], lams_window: tuple[float, ...], device: torch.device, dtype: torch.dtype
) -> tuple[torch.Tensor, torch.Tensor]:
    """(F,) lambdas outside and inside the modulated window, made once per set of weights and device (no
    host-to-device copy per step)."""
    return torch.tensor(lams, dtype=dtype, device=device), torch.tensor(lams_window, dtype=dtype, device=device)


def factor_names(cfg: EnvConfig) -> tuple[str, ...]:
    """Names of the reward factors present for this config, in product order."""
    names = ["body_pos", "body_rot"]
    names += [
        n
        for n in ("root_pos", "root_rot", "feet_pos", "root_vel", "body_vel", "feet_contact")
        if getattr(cfg.weights, n) > 0
    ]
    if cfg.wrist_terms:
        names += ["wrist_pos", "wrist_rot"]
    if cfg.finger_targets:
        names += ["finger_pos", "finger_rot"]
    names += ["obj_pos", "obj_rot", "ig", "contact_hand", "contact_other"]
    names += ["fingertip"] if cfg.weights.fingertip > 0 else []
    names += ["drive"] if cfg.weights.drive > 0 else []
    names += ["joint_energy", "obj_energy_lin", "obj_energy_ang", "contact_energy"]
    return tuple(names)


def compute_reward(
    x: RewardInputs, sets: BodySets, cfg: EnvConfig, consts: RewardConstants = CONSTANTS
) -> tuple[torch.Tensor, dict[str, torch.Tensor]]:
    """(N,) reward = product (``reward_form="mean"``: mean) of factors; dict 'reward/<name>' -> (N,) factor,
    'error/<name>' -> (N,) raw error.

    Body terms use lambda p / r outside the window and gbp / gbr inside it (window_modulation only).
    Energy errors are zeroed (factor 1) while step < consts.energy_start_step.
    """
    w = cfg.weights
    idx = tracked_bodies(sets, cfg)
    m = arm_weights(x, idx, sets, cfg)
    sq, ang, obj_ang = body_errors(x)
    near = near_weight(x.ref_near_dist, w)
    errors: dict[str, torch.Tensor] = {
        "body_pos": error_pos(sq, near, idx, m),
        "body_rot": error_rot(ang, near, idx, m),
    }
    lams: dict[str, float] = {"body_pos": w.p, "body_rot": w.r}
    lams_window = {"body_pos": w.gbp, "body_rot": w.gbr}  # lambdas that change in the modulated window
    if w.root_pos > 0:
        errors["root_pos"], lams["root_pos"] = error_root_pos(sq), w.root_pos
    if w.root_rot > 0:
        errors["root_rot"], lams["root_rot"] = error_root_rot(ang), w.root_rot
    if w.feet_pos > 0:
        if not sets.feet.numel():
            raise ValueError("weights.feet_pos > 0 needs a humanoid whose roles name its feet")
        errors["feet_pos"], lams["feet_pos"] = error_feet_pos(sq, sets), w.feet_pos
    if w.root_vel > 0:
        errors["root_vel"], lams["root_vel"] = error_root_vel(x), w.root_vel
    if w.body_vel > 0:
        errors["body_vel"], lams["body_vel"] = error_body_vel(x), w.body_vel
    if w.feet_contact > 0:
        errors["feet_contact"], lams["feet_contact"] = error_feet_contact(x), w.feet_contact
    if cfg.wrist_terms:
        errors["wrist_pos"], lams["wrist_pos"] = error_wrist_pos(sq, sets), w.gwp
        errors["wrist_rot"], lams["wrist_rot"] = error_wrist_rot(ang, sets), w.gwr
    if cfg.finger_targets:
        ones = torch.ones(x.body_pos.shape[0], sets.fingers.numel(), dtype=x.body_pos.dtype, device=m.device)
        errors["finger_pos"], lams["finger_pos"] = error_pos(sq, near, sets.fingers, ones), w.fp
        errors["finger_rot"], lams["finger_rot"] = error_rot(ang, near, sets.fingers, ones), w.fr
    errors["obj_pos"], lams["obj_pos"] = error_obj_pos(x), w.op
    errors["obj_rot"], lams["obj_rot"] = error_obj_rot(obj_ang), w.orot
    errors["ig"], lams["ig"] = error_ig(x, consts.ig_min_sq_dist), w.ig
    errors["contact_other"], lams["contact_other"] = error_contact_other(x, sets), w.cg_other
    if w.fingertip > 0:
        errors["fingertip"], lams["fingertip"] = error_fingertip(x), w.fingertip
    if w.drive > 0:
        errors["drive"], lams["drive"] = error_drive(x), w.drive
    active = x.step >= consts.energy_start_step
    for name, fn, lam in (
        ("joint_energy", error_joint_energy, w.eg1),
        ("obj_energy_lin", error_obj_energy_lin, w.eg2),
        ("obj_energy_ang", error_obj_energy_ang, w.eg2),
        ("contact_energy", error_contact_energy, w.eg3),
    ):
        errors[name], lams[name] = torch.where(active, fn(x), 0.0), lam

    # every exp(-lambda E) factor in one pass: (N, F) lambdas, the window ones where modulated
    names = list(errors)
    lam, lam_w = _lambda_rows(
        tuple(lams[n] for n in names),
        tuple(lams_window.get(n, lams[n]) for n in names),
        x.body_pos.device,
        x.body_pos.dtype,
    )
    lam = torch.where(modulated(x, cfg)[:, None], lam_w, lam)
    f = torch.exp(-lam * torch.stack([errors[n] for n in names], -1))
    factors = {n: f[:, i] for i, n in enumerate(names)}
    hand_err = error_contact_hand(x)
    factors["contact_hand"] = reward_contact_hand(hand_err, x.ref_hand, w.cg_hand)
    errors["contact_hand"] = hand_err.sum(-1)  # reference-contact hands without simulated contact (0, 1, 2)

    order = factor_names(cfg)
    stacked = torch.stack([factors[n] for n in order], dim=-1)
    reward = stacked.mean(-1) if cfg.reward_form == "mean" else stacked.prod(-1)
    info = {f"reward/{n}": factors[n] for n in order}
    info.update({f"error/{n}": errors[n] for n in order})
    return reward, info
