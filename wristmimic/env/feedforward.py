"""Feedforward warm start: sampling-based trajectory optimisation of open-loop PD-target offsets (SPIDER-like).

Tracking the reference with PD targets alone drifts: on the built-in scene the body rocks back on its heels
while the arms reach (10 cm of root error by frame 29, measured), and nothing carries the object. Before
training, this module searches offsets u(t) to the body and wrist hinges' PD targets so that the open-loop
replay (zero policy actions) follows the reference: root, wrists and the object, with the hands in contact where
the reference says so. The policy then learns a residual around reference + u(t).

Receding horizon over knots every ``knot_frames`` frames (targets interpolate linearly between knots): for each
knot, ``samples`` worlds start from the nominal state at that knot, roll out ``horizon_knots`` knots ahead with
Gaussian perturbations of the knots (cross-entropy method: the mean of the ``elites`` cheapest samples, noise
annealed by ``sigma_decay`` per iteration), the first knot is committed and the nominal state advances. Finger
hinges get no offset (fingers learn from rewards alone). Deterministic for a seed; the result is saved with the
run and used unchanged by training, evaluation and ``view``.

Measured on ``synth_default``: ~95 s of search; the zero-action replay's root drift falls from 11 to 2-4 cm and
its frame-0 survival rises from 40 to 51 of 139 frames (wrist resets still end it in the grasp phase); a policy
trained 200k frames on top reached no more frames in frame-0 trials than one without (39.8 against 41.2), so
the recipe leaves it off (``EnvConfig.feedforward.enabled``).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import torch

from wristmimic.env import window as W
from wristmimic.env.config import FeedforwardConfig
from wristmimic.env.terminations import phase_thresholds
from wristmimic.env.torch_math import quat_angle

if TYPE_CHECKING:
    from wristmimic.env.vec_env import WristMimicEnv


def knot_count(num_frames: int, knot_frames: int) -> int:
    """Knots at frames 0, k, 2k, ... up to and including the first one at or past the last frame."""
    return math.ceil((num_frames - 1) / knot_frames) + 1


def interpolate(knots: torch.Tensor, frames: torch.Tensor, knot_frames: int) -> torch.Tensor:
    """(..., K, D) knot values -> (..., F, D) values at ``frames`` (F,) by linear interpolation."""
    i = (frames // knot_frames).clamp_max(knots.shape[-2] - 2)
    a = ((frames - i * knot_frames).to(knots.dtype) / knot_frames).clamp(0.0, 1.0)[:, None]
    return knots[..., i, :] * (1.0 - a) + knots[..., i + 1, :] * a


def step_cost(env: WristMimicEnv, frames: torch.Tensor, cfg: FeedforwardConfig) -> tuple[torch.Tensor, torch.Tensor]:
    """(N,) tracking cost of the worlds' current state against the reference at ``frames``, and (N,) bool
    fallen: root below the fall height, mean key-body error beyond the body-error threshold, or (with wrist
    resets) a grasping hand's wrist beyond its phase's threshold, as the run's terminations judge it."""
    s, rf = env.sim_state(), env.ref_frame(frames)
    w = env.sets.wrists
    root = (s.body_pos[:, 0] - rf.body_pos[:, 0]).square().sum(-1)
    root_rot = quat_angle(rf.body_quat[:, 0], s.body_quat[:, 0])
    wrist = (s.body_pos[:, w] - rf.body_pos[:, w]).square().sum(-1).mean(-1)
    wrist_rot = quat_angle(rf.body_quat[:, w], s.body_quat[:, w]).mean(-1)
    cost = cfg.w_root * root + cfg.w_root_rot * root_rot + cfg.w_wrist * wrist + cfg.w_wrist_rot * wrist_rot
    if s.obj_pos.shape[1]:
        cost = cost + cfg.w_object * (s.obj_pos - rf.obj_pos).square().sum(-1).mean(-1)
        cost = cost + cfg.w_object_rot * quat_angle(rf.obj_quat, s.obj_quat).mean(-1)
        hand = torch.stack([s.contact_obj[:, h].any(1) for h in env.hands], 1)
        cost = cost + cfg.w_contact * (rf.hand & ~hand).sum(-1)
    key = env.sets.key
    body_err = (s.body_pos[:, key] - rf.body_pos[:, key]).norm(dim=-1).mean(-1)
    fallen = (s.body_pos[:, 0, 2] < env.cfg.termination.fall_height) | (body_err > env.cfg.termination.body_error)
    if env.cfg.wrist_resets:
        t_c = torch.full_like(frames, env.ref.t_c)
        ph = W.phase(frames, t_c, env.cfg.window)
        pos_thr, rot_thr = phase_thresholds(ph, env.cfg.wrist)
        pos_err = (s.body_pos[:, w] - rf.body_pos[:, w]).norm(dim=-1)
        rot_err = quat_angle(rf.body_quat[:, w], s.body_quat[:, w])
        beyond = (pos_err > pos_thr[:, None]) | (rot_err > rot_thr[:, None])
        fallen |= (beyond & env.ref.grasp_hands[None]).any(-1) & (ph != W.OUTSIDE)
    return cost, fallen


def optimise_feedforward(env: WristMimicEnv, progress: bool = False) -> torch.Tensor:
    """(T, D) PD-target offsets for ``env``'s scene (zero on finger hinges); ``env`` supplies ``samples`` worlds
    (its own state is overwritten). See the module docstring."""
    cfg = env.cfg.feedforward
    T, D, N, dev = env.ref.num_frames, env.num_hinges, env.num_worlds, env.device
    kf, H = cfg.knot_frames, cfg.horizon_knots
    K = knot_count(T, kf)
    body = env.residual_hinges.to(dev)
    knots = torch.zeros(K, D, device=dev)
    gen = torch.Generator(device=dev).manual_seed(cfg.seed)
    n_elite = max(1, round(cfg.elite_frac * N))
    every = torch.ones(N, dtype=torch.bool, device=dev)
    ctrl = torch.zeros(N, env.scene.model.nu, device=dev)
    qpos, qvel = env.reference_state(torch.zeros(1, dtype=torch.long, device=dev))
    zero = torch.zeros(N, env.action_size, device=dev)

    def rollout(start: int, stop: int, cand: torch.Tensor) -> torch.Tensor:
        """Roll every world from the nominal state at ``start`` to ``stop`` with knots ``cand`` (N, K, D)."""
        env.backend.reset(every, qpos.expand(N, -1), qvel.expand(N, -1))
        total = torch.zeros(N, device=dev)
        dead = torch.zeros(N, dtype=torch.bool, device=dev)
        for f in range(start + 1, stop + 1):
            fr = torch.full((N,), f, dtype=torch.long, device=dev)
            off = interpolate(cand, fr[:1], kf)[:, 0]  # (N, D)
            base = env.action_to_ctrl(zero, fr)  # the reference targets of frame f (no feedforward yet)
            target = torch.where(body, base + off, base)
            ctrl[:, env._act_cols] = torch.maximum(torch.minimum(target, env._hi), env._lo)
            env.backend.step(ctrl, env.scene.config.substeps)
            c, fallen = step_cost(env, fr, cfg)
            dead |= fallen
            total += torch.where(dead, torch.full_like(c, cfg.fall_cost), c)
        return total

    saved_ff = env.feedforward
    env.feedforward = torch.zeros_like(env.feedforward)
    try:
        for k in range(K - 1):
            start, stop = k * kf, min((k + H) * kf, T - 1)
            free = torch.arange(k, min(k + H, K), device=dev)  # knots this window moves (k itself is fixed
            free = free[free > 0]  # at 0 for k = 0: the episode starts on the reference)
            mean, sigma = knots.clone(), cfg.sigma
            for _ in range(cfg.iterations):
                cand = mean.expand(N, K, D).clone()
                noise = torch.randn(N, len(free), D, generator=gen, device=dev) * sigma
                noise[0] = 0.0  # the current mean is always a candidate
                cand[:, free] += torch.where(body, noise, torch.zeros_like(noise))
                cost = rollout(start, stop, cand) + cfg.w_offset * cand[:, free].square().sum((1, 2))
                elite = cost.topk(n_elite, largest=False).indices
                mean = cand[elite].mean(0)
                sigma *= cfg.sigma_decay
            knots = mean
            # advance the nominal state one knot with the committed offsets
            one = knots.expand(N, K, D)
            rollout(start, min((k + 1) * kf, T - 1), one)
            qpos = env.backend.qpos[:1].clone().double()
            qvel = env.backend.qvel[:1].clone().double()
            if progress:
                print(f"\rfeedforward: knot {k + 1}/{K - 1}", end="", flush=True)
        if progress:
            print()
    finally:
        env.feedforward = saved_ff
    frames = torch.arange(T, device=dev)
    return torch.where(body, interpolate(knots, frames, kf), torch.zeros(T, D, device=dev))
