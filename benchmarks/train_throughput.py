"""PPO training throughput against the raw MuJoCo step rate of the same scene, measured in the same run.

Usage:  python benchmarks/train_throughput.py [--dataset datasets/omomo.h5 --sequence sub2_largetable_000]
                                              [--preset cpu] [--iterations 5] [--compare] [--pgs] [--dt90]

Prints the raw ``mj_step`` rate of the scene (plain ``mujoco.rollout`` on all cores from the training worlds'
states and controls, the preset's number of worlds, no extra sensor pass: see ``physics_settings.py``), then for
the preset: training frames/s (collect + update), the split between rollout collection and the PPO update, and
the ratio training frames/s / raw control frames/s. Target (issue #15): >= 0.7 on 2 cores.

``--compare`` also runs the physics settings before issue #15 in the same process and prints the ratio of the two
training rates; ``--pgs`` also runs PGS with 20 iterations (see ``SceneConfig.solver``), ``--dt90`` Newton at
1/90 s x 3 substeps (see ``physics_settings.DT90``).
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

from wristmimic.env.vec_env import WristMimicEnv
from wristmimic.rl.config import preset, preset_env
from wristmimic.rl.runner import Runner

sys.path.insert(0, str(Path(__file__).resolve().parent))
from physics_settings import BEFORE, DT90, NOW, PGS, Settings, dataset_or_shared_omomo, raw_step_rate  # noqa: E402


def bench(path: Path, sid: str, preset_name: str, iterations: int, num_envs: int | None, settings: Settings) -> float:
    """Print the rates of one setting; return training frames/s."""
    nthread = os.cpu_count() or 1
    cfg = preset(preset_name, num_envs=num_envs)
    env_cfg = preset_env(preset_name, "wristmimic")  # the preset's environment, as training builds it
    scene_cfg = replace(settings.scene, object_actuators=env_cfg.object_controller.enabled)
    env = WristMimicEnv.from_file(
        path, sid, cfg.num_envs, env_cfg, scene_cfg, nthread=nthread, backend_options=settings.backend_options
    )
    with tempfile.TemporaryDirectory() as tmp:
        runner = Runner(env, cfg, 0, Path(tmp), "{}", {"scene": sid, "variant": "wristmimic"})
        runner.collect()
        runner.update()  # warm-up iteration
        runner.storage.clear()
        t_collect = t_update = 0.0
        for _ in range(iterations):
            t0 = time.perf_counter()
            runner.collect()
            t1 = time.perf_counter()
            runner.update()
            runner.storage.clear()
            t_collect, t_update = t_collect + t1 - t0, t_update + time.perf_counter() - t1
    sub = env.scene.config.substeps
    frames = iterations * cfg.batch_size
    rate = raw_step_rate(env.scene.model, env.backend.state.copy(), env._ctrl.double().numpy(), sub, nthread)
    t_train = t_collect + t_update
    print(
        f"{sid} preset {preset_name}, {settings.name}: {cfg.num_envs} worlds, horizon {cfg.horizon}, "
        f"MLP {list(cfg.actor_hidden)}, obs {env.observation_size}, actions {env.action_size}, {nthread} threads, "
        f"timestep 1/{1 / env.scene.config.timestep:.0f} s x {sub}\n"
        f"  raw mj_step         {rate:10,.0f} steps/s  = {rate / sub:8,.0f} control frames/s\n"
        f"  training            {frames / t_train:10,.0f} frames/s  (collect {frames / t_collect:,.0f} frames/s, "
        f"update {t_update / t_train:.0%} of the time)\n"
        f"  ratio               {frames / t_train / (rate / sub):10.2f}  (training frames/s / raw control frames/s)",
        flush=True,
    )
    env.close()
    return frames / t_train


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--dataset", type=Path)
    ap.add_argument("--sequence", default="sub2_largetable_000")
    ap.add_argument("--preset", default="cpu")
    ap.add_argument("--num-envs", type=int)
    ap.add_argument("--iterations", type=int, default=5)
    ap.add_argument("--compare", action="store_true", help="also run the physics settings before issue #15")
    ap.add_argument("--pgs", action="store_true", help="also run PGS with 20 iterations (faster; fails the gate)")
    ap.add_argument("--dt90", action="store_true", help="also run Newton at 1/90 s x 3 substeps")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        path = dataset_or_shared_omomo(args.dataset, args.sequence, tmp)
        now = bench(path, args.sequence, args.preset, args.iterations, args.num_envs, NOW)
        if args.compare:
            before = bench(path, args.sequence, args.preset, args.iterations, args.num_envs, BEFORE)
            print(f"now / before: training frames/s x{now / before:.2f}")
        if args.pgs:
            pgs = bench(path, args.sequence, args.preset, args.iterations, args.num_envs, PGS)
            print(f"pgs / now: training frames/s x{pgs / now:.2f}")
        if args.dt90:
            dt90 = bench(path, args.sequence, args.preset, args.iterations, args.num_envs, DT90)
            print(f"1/90 s x 3 / now: training frames/s x{dt90 / now:.2f}")


if __name__ == "__main__":
    main()
