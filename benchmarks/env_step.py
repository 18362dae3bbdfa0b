"""Environment throughput against the raw MuJoCo step rate of the same scene, measured in the same run.

Usage:  python benchmarks/env_step.py [--dataset datasets/omomo.h5 --sequence sub2_largetable_000] [--worlds 64 256]

For each scene and world count it prints: the raw ``mj_step`` rate of the scene stepped by ``mujoco.rollout``
on all cores (zero controls, same worlds), the environment's control frames per second (policy actions are
small random perturbations), the ratio (time the same number of physics steps takes raw) / (environment
time), and the share of the environment's wall time spent inside MuJoCo (its own rollout calls, resets
included). Target: >= 80 % inside MuJoCo at 256 worlds on 2 cores.
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path

import numpy as np
import torch

from wristmimic.env.config import EnvConfig
from wristmimic.env.vec_env import WristMimicEnv
from wristmimic.sim.backend import CpuRolloutBackend

REPO = Path(__file__).resolve().parents[1]
SHARED = REPO.parent / "shared" / "data"


def _default_datasets(tmp: Path) -> list[tuple[Path, str]]:
    from wristmimic.convert.common import ConvertOptions
    from wristmimic.convert.intermimic import convert_intermimic
    from wristmimic.convert.skillmimic_parahome import convert_skillmimic_parahome

    opts = ConvertOptions(show_progress=False)
    om, ph = tmp / "omomo.h5", tmp / "parahome.h5"
    convert_intermimic(SHARED / "intermimic_omomo", om, sequences=["sub2_largetable_000"], options=opts)
    convert_skillmimic_parahome(SHARED / "skillmimic_parahome", ph, clips=["s110_move_kettle"], options=opts)
    return [(om, "sub2_largetable_000"), (ph, "s110_move_kettle")]


def bench(path: Path, sid: str, worlds: int, steps: int, cfg: EnvConfig) -> None:
    nthread = os.cpu_count() or 1
    env = WristMimicEnv.from_file(path, sid, num_worlds=worlds, config=cfg, seed=0, nthread=nthread)
    sub = env.scene.config.substeps
    raw = CpuRolloutBackend(env.scene.model, worlds, nthread)
    raw._state[:] = env.backend._state  # same starting states as the environment
    ctrl = np.zeros((worlds, env.scene.model.nu))
    raw.step(ctrl, sub)
    t0 = time.perf_counter()
    for _ in range(steps):
        raw.step(ctrl, sub)
    t_raw = time.perf_counter() - t0
    env.reset(seed=0)
    gen = torch.Generator().manual_seed(0)
    acts = [torch.rand(worlds, env.action_size, generator=gen) * 0.2 - 0.1 for _ in range(steps)]
    env.step(acts[0])
    phys0 = env.backend.physics_seconds
    t0 = time.perf_counter()
    for a in acts:
        env.step(a)
    t_env = time.perf_counter() - t0
    inside = (env.backend.physics_seconds - phys0) / t_env
    raw_rate = worlds * steps * sub / t_raw
    print(
        f"{sid:<22} worlds {worlds:>4}: raw mj_step {raw_rate:9,.0f}/s ({nthread} threads)  "
        f"env {worlds * steps / t_env:8,.0f} frames/s  raw-time/env-time {t_raw / t_env:6.1%}  "
        f"time inside MuJoCo {inside:6.1%}"
    )
    env.close()
    raw.close()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--dataset", type=Path)
    ap.add_argument("--sequence")
    ap.add_argument("--worlds", type=int, nargs="+", default=[64, 256])
    ap.add_argument("--steps", type=int, default=20)
    ap.add_argument("--ig-points", type=int, default=EnvConfig().ig_points, help="interaction-graph points")
    args = ap.parse_args()
    cfg = EnvConfig(ig_points=args.ig_points)
    with tempfile.TemporaryDirectory() as tmp:
        pairs = [(args.dataset, args.sequence)] if args.dataset else _default_datasets(Path(tmp))
        for path, sid in pairs:
            for n in args.worlds:
                bench(path, sid, n, args.steps, cfg)


if __name__ == "__main__":
    main()
