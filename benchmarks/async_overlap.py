"""Two half-batches in alternation (EnvPool's async mode) against one batch, measured in the same run.

Usage:  python benchmarks/async_overlap.py [--dataset datasets/omomo.h5 --sequence sub2_largetable_000]
                                           [--worlds 64] [--iterations 3]

Issue #15 lists overlapping the physics of one half of the worlds with the policy inference and observation math
of the other as a lever. This measures it with the CPU recipe's environment and policy network (random weights):
``sync`` steps one environment of N worlds (policy, then physics, then observation and reward math); ``async``
steps two environments of N / 2 worlds, one half's physics running on a worker thread (``mujoco.rollout``
releases the GIL) while the main thread runs the other half's math and policy, through
:meth:`WristMimicEnv.prepare_step` / :meth:`WristMimicEnv.finish_step`. Both rates are printed as ratios of the
raw ``mj_step`` control-frame rate of the same scene measured in the same run (see ``physics_settings.py``).
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import torch

from wristmimic.env.vec_env import WristMimicEnv
from wristmimic.rl.config import preset, preset_env
from wristmimic.rl.networks import ActorCritic

sys.path.insert(0, str(Path(__file__).resolve().parent))
from physics_settings import dataset_or_shared_omomo, raw_step_rate  # noqa: E402


def _policy(env: WristMimicEnv) -> ActorCritic:
    cfg = preset("cpu")
    net = ActorCritic(env.observation_size, env.action_size, cfg.actor_hidden, cfg.critic_hidden, -2.3)
    return net.eval()


def _act(net: ActorCritic, obs: torch.Tensor) -> torch.Tensor:
    with torch.no_grad():
        return net.act(net.normalizer(obs))[0]


def run_sync(env: WristMimicEnv, net: ActorCritic, steps: int) -> float:
    """Control frames per second of policy + environment, one batch."""
    obs = env.observe()
    t0 = time.perf_counter()
    for _ in range(steps):
        obs = env.step(_act(net, obs))[0]
    return steps * env.num_worlds / (time.perf_counter() - t0)


def run_async(a: WristMimicEnv, b: WristMimicEnv, net: ActorCritic, steps: int, pool: ThreadPoolExecutor) -> float:
    """Control frames per second with ``a``'s physics overlapping ``b``'s math and policy, and back."""
    sub = a.scene.config.substeps
    oa, ob = a.observe(), b.observe()
    t0 = time.perf_counter()
    act_a = _act(net, oa)
    phys_a = pool.submit(a.backend.step, a.prepare_step(act_a), sub)
    for s in range(steps):
        act_b = _act(net, ob)  # overlaps a's physics
        phys_a.result()
        phys_b = pool.submit(b.backend.step, b.prepare_step(act_b), sub)
        oa = a.finish_step(act_a)[0]  # overlaps b's physics
        if s + 1 < steps:
            act_a = _act(net, oa)
        phys_b.result()
        if s + 1 < steps:
            phys_a = pool.submit(a.backend.step, a.prepare_step(act_a), sub)
        ob = b.finish_step(act_b)[0]  # overlaps a's next physics
    return steps * (a.num_worlds + b.num_worlds) / (time.perf_counter() - t0)


def bench(path: Path, sid: str, worlds: int, iterations: int, steps: int) -> None:
    nthread = os.cpu_count() or 1
    cfg = preset_env("cpu", "wristmimic")
    torch.set_num_threads(cfg.math_threads)
    one = WristMimicEnv.from_file(path, sid, worlds, cfg, nthread=nthread)
    halves = [WristMimicEnv.from_file(path, sid, worlds // 2, cfg, seed=k, nthread=nthread) for k in range(2)]
    for e in (one, *halves):
        e.eval_info = False  # as in training
        e.reset()
    net = _policy(one)
    sub = one.scene.config.substeps
    raw = raw_step_rate(one.scene.model, one.backend.state.copy(), one._ctrl.double().numpy(), sub, nthread) / sub
    sync, asyn = [], []
    with ThreadPoolExecutor(1) as pool:
        run_sync(one, net, 4)  # warm-up
        run_async(*halves, net, 4, pool)
        for _ in range(iterations):  # interleaved, so a change in machine load hits both
            sync.append(run_sync(one, net, steps))
            asyn.append(run_async(*halves, net, steps, pool))
    s, y = max(sync), max(asyn)
    print(
        f"{sid}: {worlds} worlds, {nthread} threads, policy MLP {list(preset('cpu').actor_hidden)}\n"
        f"  raw mj_step           {raw:8,.0f} control frames/s\n"
        f"  sync  (1 x {worlds:3d})       {s:8,.0f} frames/s  ratio {s / raw:.2f}\n"
        f"  async (2 x {worlds // 2:3d})       {y:8,.0f} frames/s  ratio {y / raw:.2f}\n"
        f"  async / sync          {y / s:8.2f}",
        flush=True,
    )
    for e in (one, *halves):
        e.close()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--dataset", type=Path)
    ap.add_argument("--sequence", default="sub2_largetable_000")
    ap.add_argument("--worlds", type=int, nargs="+", default=[64])
    ap.add_argument("--iterations", type=int, default=3, help="timed repetitions of each mode (best kept)")
    ap.add_argument("--steps", type=int, default=64, help="control steps per repetition")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        path = dataset_or_shared_omomo(args.dataset, args.sequence, tmp)
        for n in args.worlds:
            bench(path, args.sequence, n, args.iterations, args.steps)


if __name__ == "__main__":
    main()
