"""Environment throughput against the raw MuJoCo step rate of the same scene, measured in the same run.

Usage:  python benchmarks/env_step.py [--dataset datasets/omomo.h5 --sequence sub2_largetable_000]
                                      [--worlds 64 256] [--compare]

For each scene and world count it prints: the raw ``mj_step`` rate of the scene (plain ``mujoco.rollout`` on all
cores from the environment's own states and controls, no extra sensor pass: see ``physics_settings.py``), the
environment's control frames per second under the CPU training recipe's environment (policy actions are small
random perturbations; evaluation-only errors off, as in training), the ratio (time the same number of physics
steps takes raw) / (environment time), and the share of the environment's wall time spent inside MuJoCo (its
own rollout calls, sensor passes and resets included). Target (issue #15): ratio >= 0.85 at 256 worlds on 2 cores.

``--compare`` runs the physics settings before issue #15 and today's side by side in the same process and prints
the ratio of the two environment rates and of the two raw rates.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

import torch

from wristmimic.env.vec_env import WristMimicEnv
from wristmimic.rl.config import preset_env

sys.path.insert(0, str(Path(__file__).resolve().parent))
from physics_settings import BEFORE, NOW, Settings, raw_step_rate  # noqa: E402

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


def bench(path: Path, sid: str, worlds: int, steps: int, settings: Settings) -> tuple[float, float]:
    """Print one line; return (environment frames/s, raw control frames/s)."""
    nthread = os.cpu_count() or 1
    cfg = preset_env("cpu", "wristmimic")
    env = WristMimicEnv.from_file(
        path, sid, worlds, cfg, settings.scene, seed=0, nthread=nthread, backend_options=settings.backend_options
    )
    env.eval_info = False  # as in training
    sub = env.scene.config.substeps
    env.reset(seed=0)
    gen = torch.Generator().manual_seed(0)
    acts = [torch.rand(worlds, env.action_size, generator=gen) * 0.2 - 0.1 for _ in range(steps)]
    for a in acts[:3]:
        env.step(a)
    raw = raw_step_rate(env.scene.model, env.backend.state.copy(), env._ctrl.double().numpy(), sub, nthread)
    phys0 = env.backend.physics_seconds
    t0 = time.perf_counter()
    for a in acts:
        env.step(a)
    t_env = time.perf_counter() - t0
    inside = (env.backend.physics_seconds - phys0) / t_env
    rate = worlds * steps / t_env
    print(
        f"{sid:<22} {settings.name:<26} worlds {worlds:>4}: raw mj_step {raw:9,.0f}/s = {raw / sub:7,.0f} "
        f"control frames/s ({nthread} threads)  env {rate:7,.0f} frames/s  ratio {rate * sub / raw:5.2f}  "
        f"inside MuJoCo {inside:6.1%}",
        flush=True,
    )
    env.close()
    return rate, raw / sub


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--dataset", type=Path)
    ap.add_argument("--sequence")
    ap.add_argument("--worlds", type=int, nargs="+", default=[64, 256])
    ap.add_argument("--steps", type=int, default=40)
    ap.add_argument("--compare", action="store_true", help="also run the physics settings before issue #15")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        pairs = [(args.dataset, args.sequence)] if args.dataset else _default_datasets(Path(tmp))
        for path, sid in pairs:
            for n in args.worlds:
                now = bench(path, sid, n, args.steps, NOW)
                if args.compare:
                    before = bench(path, sid, n, args.steps, BEFORE)
                    print(
                        f"{'':<22} now / before{'':<13} worlds {n:>4}: env x{now[0] / before[0]:.2f}, "
                        f"raw control frames/s x{now[1] / before[1]:.2f}",
                        flush=True,
                    )


if __name__ == "__main__":
    main()
