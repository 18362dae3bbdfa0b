"""MuJoCo Warp backend throughput against bare ``mujoco_warp`` stepping of the same scene, in the same run.

Usage (on a GPU machine, from the repository root):
    python benchmarks/gpu_throughput.py [--dataset datasets/omomo.h5 --sequence sub2_largetable_000]
        [--worlds 1024 4096 8192] [--steps 50] [--eval-trials 10000 --eval-envs 4096] [--run RUN_DIR]

For each world count it prints the bare rate (the captured ``mujoco_warp.step`` loop alone, zero controls, in
physics steps/s), the environment's control frames/s (random actions; observations, rewards, terminations and
masked resets in torch on the same device), and the ratio (time the same physics steps take bare) /
(environment time). Then the wall time of a 10,000-trial evaluation of one scene (the paper protocol's noise)
with the policy of ``--run`` or, without one, an untrained policy of the right shape (the physics and
bookkeeping cost the same). Without a GPU it runs on Warp's CPU device with small defaults, as a smoke test:
those numbers say nothing about GPU throughput.
"""

from __future__ import annotations

import argparse
import hashlib
import tempfile
import time
from pathlib import Path
from typing import Any

import torch

from wristmimic.env.config import EnvConfig, variant_config
from wristmimic.env.vec_env import WristMimicEnv
from wristmimic.sim.warp_backend import WarpBackend, default_device

REPO = Path(__file__).resolve().parents[1]
SHARED = REPO.parent / "shared" / "data"


def _default_dataset(tmp: Path) -> tuple[Path, str]:
    from wristmimic.convert.common import ConvertOptions
    from wristmimic.convert.intermimic import convert_intermimic

    out = tmp / "omomo.h5"
    opts = ConvertOptions(show_progress=False)
    convert_intermimic(SHARED / "intermimic_omomo", out, sequences=["sub2_largetable_000"], options=opts)
    return out, "sub2_largetable_000"


def _sync(device: torch.device) -> None:
    if device.type == "cuda":
        torch.cuda.synchronize(device)


def bench_step(path: Path, sid: str, worlds: int, steps: int, device: str, cfg: EnvConfig) -> dict[str, float]:
    env = WristMimicEnv.from_file(
        path, sid, worlds, config=cfg, seed=0, backend="warp", backend_options={"device": device}
    )
    sub = env.scene.config.substeps
    env.reset(seed=0)
    raw = WarpBackend(env.scene.model, worlds, device=device)
    raw.load_state_dict(env.backend.state_dict())  # the same starting states as the environment
    raw._launch("step", sub)  # compile / capture outside the timing
    _sync(env.device)
    t0 = time.perf_counter()
    for _ in range(steps):
        raw._launch("step", sub)
    _sync(env.device)
    t_raw = time.perf_counter() - t0
    gen = torch.Generator(device=env.device).manual_seed(0)
    acts = [torch.rand(worlds, env.action_size, generator=gen, device=env.device) * 0.2 - 0.1 for _ in range(steps)]
    env.step(acts[0])
    _sync(env.device)
    t0 = time.perf_counter()
    for a in acts:
        env.step(a)
    _sync(env.device)
    t_env = time.perf_counter() - t0
    overflow = env.backend.overflowed() or raw.overflowed()
    env.close()
    raw.close()
    return {
        "raw_steps_per_s": worlds * steps * sub / t_raw,
        "env_frames_per_s": worlds * steps / t_env,
        "ratio": t_raw / t_env,
        "overflow": float(overflow),
    }


class _UntrainedPolicy:
    """A freshly initialised actor of the scene's sizes behind the evaluation policy interface."""

    def __init__(self, path: Path, sid: str, env: WristMimicEnv, cfg: EnvConfig):
        from wristmimic.rl.config import preset, to_jsonable
        from wristmimic.rl.networks import ActorCritic
        from wristmimic.safe_io import sha256_file

        ppo = preset("paper")
        torch.manual_seed(0)
        self.net = ActorCritic(env.observation_size, env.action_size, ppo.actor_hidden, ppo.critic_hidden, ppo.log_std)
        sha = sha256_file(path)
        self.metadata: dict[str, Any] = {
            "scene": sid,
            "variant": "wristmimic",
            "dataset": str(path),
            "dataset_sha256": sha,
            "env": to_jsonable(cfg),
            "checkpoint_sha256": hashlib.sha256(b"untrained").hexdigest(),
        }

    def to(self, device: torch.device | str) -> _UntrainedPolicy:
        self.net.to(device)
        return self

    @torch.no_grad()
    def act(self, obs: torch.Tensor, deterministic: bool = True) -> torch.Tensor:
        return self.net.actor(self.net.normalizer(obs))

    @property
    def sigma(self) -> torch.Tensor:
        return torch.exp(self.net.log_std.detach())


def bench_eval(path: Path, sid: str, trials: int, envs: int, device: str, run: Path | None, out: Path) -> float:
    from wristmimic.evaluate import evaluate_policy, load_eval_policy, load_protocol

    cfg = variant_config("wristmimic")
    if run is not None:
        policy: Any = load_eval_policy(run)
    else:
        probe = WristMimicEnv.from_file(path, sid, 1, config=cfg, nthread=1)
        probe.reset()
        policy = _UntrainedPolicy(path, sid, probe, cfg)
        probe.close()
    t0 = time.perf_counter()
    r = evaluate_policy(
        policy,
        load_protocol("paper"),
        out,
        trials=trials,
        num_envs=envs,
        progress=False,
        backend="warp",
        backend_options={"device": device},
        dataset=path if run is None else None,
    )
    seconds = time.perf_counter() - t0
    s = r.summary
    print(
        f"evaluation: {trials:,} trials of {sid} with {envs:,} worlds in {seconds:.1f} s "
        f"({trials / seconds:,.0f} trials/s; success {100 * s['success_rate']:.1f} %, mean trial "
        f"{s.get('frames_completed_mean', float('nan')):.1f} frames)"
    )
    return seconds


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--dataset", type=Path)
    ap.add_argument("--sequence")
    ap.add_argument("--device", default=default_device(), help="Warp device (default: cuda if there is one)")
    ap.add_argument("--worlds", type=int, nargs="+")
    ap.add_argument("--steps", type=int)
    ap.add_argument("--eval-trials", type=int)
    ap.add_argument("--eval-envs", type=int)
    ap.add_argument("--run", type=Path, help="trained run whose policy the evaluation uses (default: untrained)")
    a = ap.parse_args()
    gpu = a.device.startswith("cuda")
    worlds = a.worlds or ([1024, 4096, 8192] if gpu else [16, 64])
    steps = a.steps or (50 if gpu else 5)
    trials = a.eval_trials or (10_000 if gpu else 64)
    envs = a.eval_envs or (4096 if gpu else 32)
    if not gpu:
        print("no GPU: Warp's CPU device with small sizes (a smoke test; not GPU throughput)")
    else:
        print(f"device: {torch.cuda.get_device_name(torch.device(a.device))}")
    with tempfile.TemporaryDirectory() as tmp:
        if a.dataset:
            path, sid = a.dataset, a.sequence or "sub2_largetable_000"
        else:
            path, sid = _default_dataset(Path(tmp))
        cfg = variant_config("wristmimic")
        for n in worlds:
            r = bench_step(path, sid, n, steps, a.device, cfg)
            print(
                f"{sid} worlds {n:>5}: bare mujoco_warp {r['raw_steps_per_s']:12,.0f} steps/s  "
                f"env {r['env_frames_per_s']:10,.0f} frames/s  bare-time/env-time {r['ratio']:6.1%}"
                + ("  (contact/constraint room overflowed: raise nconmax/njmax)" if r["overflow"] else "")
            )
        bench_eval(path, sid, trials, envs, a.device, a.run, Path(tmp) / "eval")


if __name__ == "__main__":
    main()
