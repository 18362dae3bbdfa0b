"""Evaluation throughput against the raw MuJoCo step rate of the same scene, measured in the same run.

Usage:  python benchmarks/evaluate.py [--trials 10000] [--num-envs 128] [--dataset datasets/omomo.h5]

Runs N trials of the paper protocol (sampled actions, frame 0 to the end or an early termination) on
``sub2_largetable_000`` with the evaluation's own code path (``make_env`` + ``run_trials`` + the chunked Parquet
writer), then steps the same scene with ``CpuRolloutBackend`` (``mujoco.rollout``, same worlds and threads; zero controls
from the frame-0 state, restarted every mean trial length) for as many physics steps as the trials used. Prints the wall time, the raw time, their ratio (target
<= 1.3x), trials/s, the share of the loop spent inside MuJoCo and the share of stepped worlds that ran a trial
(idle worlds at the end still step). Without ``--run`` the policy is a randomly initialised network of the CPU
preset's size: its trials end early, which is what it measures (the loop cost), not a policy's quality.
"""

from __future__ import annotations

import argparse
import math
import os
import tempfile
import time
from pathlib import Path

import numpy as np
import torch

from wristmimic.env.config import variant_config
from wristmimic.evaluate.policy import RunPolicy, load_eval_policy
from wristmimic.evaluate.protocol import load_protocol
from wristmimic.evaluate.runner import _ChunkWriter
from wristmimic.evaluate.trials import TrialSettings, make_env, run_trials
from wristmimic.rl.config import preset
from wristmimic.rl.networks import ActorCritic
from wristmimic.sim.backend import CpuRolloutBackend

REPO = Path(__file__).resolve().parents[1]
SHARED = REPO.parent / "shared" / "data"
SCENE = "sub2_largetable_000"


class _RandomPolicy:
    """A randomly initialised actor of the CPU preset's size (no training), seeded."""

    def __init__(self, obs_size: int, action_size: int, meta: dict):
        torch.manual_seed(0)
        cfg = preset("cpu")
        self.net = ActorCritic(obs_size, action_size, cfg.actor_hidden, cfg.critic_hidden, cfg.log_std, cfg.obs_clip)
        self.metadata = meta

    def act(self, obs: torch.Tensor, deterministic: bool = True) -> torch.Tensor:
        return self.net.actor(self.net.normalizer(obs))

    @property
    def sigma(self) -> torch.Tensor:
        return torch.exp(self.net.log_std)


def _dataset(tmp: Path) -> Path:
    from wristmimic.convert.common import ConvertOptions
    from wristmimic.convert.intermimic import convert_intermimic

    out = tmp / "omomo.h5"
    convert_intermimic(SHARED / "intermimic_omomo", out, sequences=[SCENE], options=ConvertOptions(show_progress=False))
    return out


def bench(policy: RunPolicy | _RandomPolicy, trials: int, num_envs: int, nthread: int, out: Path) -> None:
    proto = load_protocol("paper")
    settings = TrialSettings.from_protocol(proto)
    t0 = time.perf_counter()
    env = make_env(policy.metadata, min(num_envs, trials), proto.early_termination, nthread)
    t_build = time.perf_counter() - t0
    env.reset(start_frames=torch.zeros(env.num_worlds, dtype=torch.long))
    frame0 = env.backend.state.copy()  # every trial starts here: the raw comparison restarts here too
    writer = _ChunkWriter(out, SCENE, settings.noise, 0, trials, 256)
    steps = [0]
    step = env.step

    def counted(a: torch.Tensor):  # count loop iterations (all worlds step, idle ones included)
        steps[0] += 1
        return step(a)

    env.step = counted  # type: ignore[method-assign]
    phys0 = env.backend.physics_seconds
    t0 = time.perf_counter()
    frames = run_trials(env, policy, settings, 0, trials, writer)
    t_loop = time.perf_counter() - t0
    inside = (env.backend.physics_seconds - phys0) / t_loop
    sub, worlds = env.scene.config.substeps, env.num_worlds
    raw = CpuRolloutBackend(env.scene.model, worlds, nthread)
    ctrl = np.zeros((worlds, env.scene.model.nu))
    iters, seg = math.ceil(frames / worlds), max(round(frames / trials), 1)
    t_raw = 0.0
    for i in range(iters):  # zero controls from the frame-0 state, restarted every mean trial length
        if i % seg == 0:
            raw.state[:] = frame0
        t0 = time.perf_counter()
        raw.step(ctrl, sub)
        t_raw += time.perf_counter() - t0
    t_raw *= frames / (iters * worlds)  # time of exactly `frames` x substeps steps
    env.close()
    raw.close()
    useful = frames / max(steps[0] * worlds, 1)
    print(
        f"{SCENE}: {trials:,} trials on {worlds} worlds, {nthread} threads; {frames:,} trial frames = "
        f"{frames * sub:,} mj_steps; mean trial {frames / trials:.1f} frames\n"
        f"  evaluation loop {t_loop:8.2f} s  ({trials / t_loop:,.1f} trials/s, {frames / t_loop:,.0f} frames/s), "
        f"env build {t_build:.2f} s\n"
        f"  raw mj_step     {t_raw:8.2f} s  for the same {frames * sub:,} steps ({frames * sub / t_raw:,.0f} steps/s)\n"
        f"  ratio loop / raw {t_loop / t_raw:5.2f}x  (target <= 1.3x); with env build {(t_loop + t_build) / t_raw:5.2f}x\n"
        f"  inside MuJoCo {inside:6.1%} of the loop; worlds running a trial {useful:6.1%} of stepped world-frames"
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--trials", type=int, default=10_000)
    ap.add_argument("--num-envs", type=int, default=128)
    ap.add_argument("--nthread", type=int, default=os.cpu_count() or 1)
    ap.add_argument("--dataset", type=Path, help="canonical file holding sub2_largetable_000 [default: convert]")
    ap.add_argument("--run", type=Path, help="a trained run of sub2_largetable_000 [default: random CPU-preset net]")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        if args.run:
            policy: RunPolicy | _RandomPolicy = load_eval_policy(args.run)
            print(f"policy: trained run {args.run}")
        else:
            ds = args.dataset or _dataset(Path(tmp))
            meta = {"scene": SCENE, "variant": "wristmimic", "dataset": str(ds), "env": variant_config("wristmimic")}
            probe = make_env(meta, 1, nthread=1)
            obs, _ = probe.reset()
            probe.close()
            policy = _RandomPolicy(obs.shape[1], probe.action_size, meta)
            print(f"policy: randomly initialised CPU-preset actor {preset('cpu').actor_hidden} (no trained policy)")
        out = Path(tmp) / "parts"
        out.mkdir()
        bench(policy, args.trials, args.num_envs, args.nthread, out)


if __name__ == "__main__":
    main()
