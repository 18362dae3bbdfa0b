"""Rollout trials, batched over worlds: each world runs trials back to back from frame 0.

The environment resets an ended world itself (``reset_frame0_prob = 1``, so at frame 0) and the world takes the
next trial index; no world waits for the batch. A trial's actions are the policy mean plus
``sigma * normal(seed, step, index)`` (``actions`` mode) or the mean from a state perturbed by
``normal(seed, ...)`` (``initial-state`` mode): with row-independent policy batches
(:func:`wristmimic.evaluate.policy.act_rows`) every trial is a pure function of (policy, scene, its seed), so
it replays alone and a resumed evaluation reproduces the same table.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any
from typing import Protocol as Interface

import numpy as np
import torch

from wristmimic.env.config import EnvConfig, env_config_from_dict
from wristmimic.env.vec_env import WristMimicEnv
from wristmimic.evaluate.metrics import TrialSums, is_strict_success, is_success
from wristmimic.evaluate.noise import normal, trial_seeds
from wristmimic.evaluate.policy import EvalPolicy, act_rows
from wristmimic.evaluate.protocol import InitialStateNoise, Protocol
from wristmimic.threads import torch_threads

Records = dict[str, np.ndarray]
"""Completed trials as columns (see :data:`wristmimic.evaluate.metrics.TRIAL_COLUMNS`, minus ``scene``)."""

NOISE_STREAM_ACTIONS, NOISE_STREAM_JOINTS, NOISE_STREAM_ROOT = 0, 1, 2


@dataclass(frozen=True)
class TrialSettings:
    """What defines the trials of one evaluation (a protocol after command-line overrides)."""

    base_seed: int
    noise: str
    max_obj_pos_err_m: float
    min_contact_ratio: float
    initial_state_noise: InitialStateNoise = InitialStateNoise()

    @classmethod
    def from_protocol(cls, p: Protocol) -> TrialSettings:
        return cls(p.base_seed, p.noise, p.max_object_position_error_m, p.min_contact_ratio, p.initial_state_noise)


def eval_env_config(env: EnvConfig | dict[str, Any], early_termination: str = "run") -> EnvConfig:
    """The run's environment config for evaluation: every (auto-)reset at frame 0 from the reference (no state
    bank, no root assist, no adhesion), no truncation before the end of the sequence; ``early_termination="base"``
    turns the wrist resets off."""
    if isinstance(env, dict):
        env = env_config_from_dict(env)
    cfg = replace(env, reset_frame0_prob=1.0, max_episode_frames=2**31 - 1, starts=replace(env.starts, bank=0.0))
    cfg = replace(cfg, root_assist=replace(cfg.root_assist, enabled=False))
    cfg = replace(cfg, hand_adhesion=replace(cfg.hand_adhesion, enabled=False))
    return replace(cfg, wrist_resets=False) if early_termination == "base" else cfg


def make_env(
    meta: dict[str, Any],
    num_worlds: int,
    early_termination: str = "run",
    nthread: int | None = None,
    dataset: str | Path | None = None,
    backend: str = "cpu",
    backend_options: dict | None = None,
) -> WristMimicEnv:
    """The evaluation environment of a policy's scene (``meta``: :attr:`EvalPolicy.metadata`) on ``backend``."""
    from wristmimic.scene import scene_config_from_dict

    sc = meta.get("scene_config")
    if isinstance(sc, dict):
        sc = scene_config_from_dict(sc)
    env = WristMimicEnv.from_file(
        dataset or meta["dataset"],
        meta["scene"],
        num_worlds=num_worlds,
        config=eval_env_config(meta.get("env") or EnvConfig(), early_termination),
        scene_config=sc,
        seed=0,
        nthread=nthread,
        max_frames=meta.get("ref_frames"),
        backend=backend,
        backend_options=backend_options,
    )
    if meta.get("feedforward") is not None:  # the run's optimised open-loop offsets (wristmimic.env.feedforward)
        env.feedforward = torch.as_tensor(meta["feedforward"], dtype=torch.float32, device=env.device).clone()
    return env


def perturb_initial_state(
    env: WristMimicEnv, ids: torch.Tensor, seeds: torch.Tensor, noise: InitialStateNoise
) -> torch.Tensor:
    """Add seeded Gaussian noise to the hinge angles and root position of worlds ``ids`` (just reset); returns
    the new observation of every world."""
    dev = env.device
    rows = ids.to(dev)
    mask = torch.zeros(env.num_worlds, dtype=torch.bool, device=dev)
    mask[rows] = True
    qpos, qvel = env.backend.qpos.double().clone(), env.backend.qvel.double().clone()
    adr = torch.as_tensor(env.scene.hinge_qposadr.reshape(-1), device=dev)
    zero = torch.zeros(len(ids), dtype=torch.long)  # noise is drawn for the reset worlds only
    joints = noise.joint_angle_rad * normal(seeds, zero, len(adr), NOISE_STREAM_JOINTS).double().to(dev)
    qpos[rows[:, None], adr[None]] += joints
    qpos[rows, 0:3] += noise.root_position_m * normal(seeds, zero, 3, NOISE_STREAM_ROOT).double().to(dev)
    env.backend.reset(mask, qpos, qvel)
    return env.observe()


class TrialRecorder(Interface):
    """What :func:`run_trials` tells a recorder (``wristmimic.evaluate.export``) besides the environment's
    ``on_step`` hook."""

    def begin(self, worlds: torch.Tensor) -> None:
        """``worlds`` (long) have just been put at frame 0 of a new trial."""

    def end(self, worlds: torch.Tensor, records: Records) -> None:
        """The trials of ``worlds`` completed (``records``: their rows, in the same order)."""


def run_trials(
    env: WristMimicEnv,
    policy: EvalPolicy,
    settings: TrialSettings,
    start: int,
    stop: int,
    sink: Callable[[Records], None],
    threads: int | None = None,
    recorder: TrialRecorder | None = None,
    trial_ids: np.ndarray | None = None,
) -> int:
    """Run trials ``start .. stop - 1`` on ``env``'s worlds; ``sink`` gets each step's completed trials.

    The policy and noise run with ``threads`` torch threads (default: the environment's ``math_threads``, 1):
    more OpenMP threads contend with the physics threads on a small machine (measured on 2 cores: the policy
    step took 10x longer with 2 torch threads). Returns the frames stepped by trials (their completed frames).
    ``trial_ids``: run trials ``trial_ids[start:stop]`` (any trial numbers, seeded as in the full run) instead.
    ``recorder`` is told when trials begin and end (export records their states).
    """
    # a copy (torch.tensor): callers may pass read-only arrays, which torch.as_tensor would share and warn about
    ids = None if trial_ids is None else torch.tensor(np.asarray(trial_ids), dtype=torch.long)
    with torch_threads(threads or env.cfg.math_threads):
        return _run(env, policy, settings, start, stop, sink, recorder, ids)


def _run(
    env: WristMimicEnv,
    policy: EvalPolicy,
    settings: TrialSettings,
    start: int,
    stop: int,
    sink: Callable[[Records], None],
    recorder: TrialRecorder | None = None,
    trial_ids: torch.Tensor | None = None,
) -> int:
    def number(pos: torch.Tensor) -> torch.Tensor:  # a position in start..stop-1 -> its trial number
        return pos if trial_ids is None else trial_ids[pos]

    N, T, dev = env.num_worlds, env.ref.num_frames, env.device
    ref_contact = int(env.ref.hand[1:T].sum())
    sigma = policy.sigma.to(dev, torch.float32)
    world_trial = torch.full((N,), -1, dtype=torch.long)
    take = min(N, stop - start)
    world_trial[:take] = torch.arange(start, start + take)
    nxt = start + take
    seeds = trial_seeds(settings.base_seed, number(world_trial.clamp_min(0)))
    steps = torch.zeros(N, dtype=torch.long)
    sums = TrialSums.zeros(N)
    obs, _ = env.reset(start_frames=torch.zeros(N, dtype=torch.long, device=dev))
    sampled = settings.noise == "actions"
    if not sampled:
        obs = perturb_initial_state(env, torch.arange(take), seeds[:take], settings.initial_state_noise)
    if recorder is not None:
        recorder.begin(torch.arange(take))
    frames = 0
    while bool((world_trial >= 0).any()):
        actions = act_rows(policy, obs)
        if sampled:
            actions = actions + sigma * normal(seeds, steps, env.action_size, NOISE_STREAM_ACTIONS).to(dev)
        obs, _, terminated, truncated, info = env.step(actions)
        # trial bookkeeping stays on the host: one small copy per step
        terminated, truncated = terminated.cpu(), truncated.cpu()
        sums.add({k: v.cpu() for k, v in info["eval"].items()})
        steps += 1
        done = (terminated | truncated) & (world_trial >= 0)
        if not bool(done.any()):
            continue
        ids = torch.nonzero(done).flatten()
        m = sums.means(ids, ref_contact)
        term = terminated[ids]
        success = is_success(
            term,
            truncated[ids],
            m["obj_pos_err_cm"] / 100.0,
            m["contact_ratio"],
            settings.max_obj_pos_err_m,
            settings.min_contact_ratio,
        )
        strict = is_strict_success(success, m["obj_pos_err_peak_cm"] / 100.0, settings.max_obj_pos_err_m)
        reasons = info["termination_reason"].cpu()[ids].tolist()
        n_frames = sums.frames[ids]
        frames += int(n_frames.sum())
        rec = {
            "trial": number(world_trial[ids]).numpy().copy(),
            "seed": seeds[ids].numpy().copy(),
            "success": success.numpy(),
            "terminated": term.numpy(),
            "termination_reason": np.array([WristMimicEnv.reason_name(r) for r in reasons], dtype=object),
            "frames_completed": n_frames.numpy().copy(),
            "frames_total": np.full(len(ids), T - 1, dtype=np.int64),
            **{k: v.numpy() for k, v in m.items()},
            "strict_success": strict.numpy(),
        }
        if recorder is not None:
            recorder.end(ids, rec)
        sink(rec)
        k = min(len(ids), stop - nxt)
        world_trial[ids[k:]] = -1
        new = ids[:k]
        world_trial[new] = torch.arange(nxt, nxt + k)
        nxt += k
        seeds[new] = trial_seeds(settings.base_seed, number(world_trial[new]))
        steps[ids] = 0
        sums.clear(ids)
        if k and not sampled:
            obs = perturb_initial_state(env, new, seeds[new], settings.initial_state_noise)
        if k and recorder is not None:
            recorder.begin(new)
    return frames
