"""PPO training throughput against the raw MuJoCo step rate of the same scene, measured in the same run.

Usage:  python benchmarks/train_throughput.py [--dataset datasets/omomo.h5 --sequence sub2_largetable_000]
                                              [--preset cpu] [--iterations 5]

Prints the raw ``mj_step`` rate of the scene (``mujoco.rollout`` on all cores, the preset's number of worlds),
then for the preset: training frames/s (collect + update), the split between rollout collection and the PPO
update, and the physics share = (time the same physics steps take raw) / (training time).
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path

import numpy as np

from wristmimic.env.vec_env import WristMimicEnv
from wristmimic.rl.config import preset, preset_env
from wristmimic.rl.runner import Runner
from wristmimic.scene import SceneConfig
from wristmimic.sim.backend import CpuRolloutBackend

REPO = Path(__file__).resolve().parents[1]
SHARED = REPO.parent / "shared" / "data"


def raw_rate(env: WristMimicEnv, steps: int, nthread: int) -> float:
    """Physics steps per second of ``mujoco.rollout`` from the environment's states, zero controls."""
    sub, n = env.scene.config.substeps, env.num_worlds
    raw = CpuRolloutBackend(env.scene.model, n, nthread)
    raw._state[:] = env.backend._state
    ctrl = np.zeros((n, env.scene.model.nu))
    raw.step(ctrl, sub)
    t0 = time.perf_counter()
    for _ in range(steps):
        raw.step(ctrl, sub)
    dt = time.perf_counter() - t0
    raw.close()
    return n * steps * sub / dt


def bench(path: Path, sid: str, preset_name: str, iterations: int, num_envs: int | None) -> None:
    nthread = os.cpu_count() or 1
    cfg = preset(preset_name, num_envs=num_envs)
    env_cfg = preset_env(preset_name, "wristmimic")  # the preset's environment, as training builds it
    scene_cfg = SceneConfig(object_actuators=env_cfg.object_controller.enabled)
    env = WristMimicEnv.from_file(path, sid, cfg.num_envs, env_cfg, scene_cfg, nthread=nthread)
    with tempfile.TemporaryDirectory() as tmp:
        runner = Runner(env, cfg, 0, Path(tmp), "{}", {"scene": sid, "variant": "wristmimic"})
        runner.collect()
        runner.alg.update(runner.storage, runner.gen)  # warm-up iteration
        runner.storage.clear()
        t_collect = t_update = 0.0
        for _ in range(iterations):
            t0 = time.perf_counter()
            runner.collect()
            t1 = time.perf_counter()
            runner.alg.update(runner.storage, runner.gen)
            runner.storage.clear()
            t_collect, t_update = t_collect + t1 - t0, t_update + time.perf_counter() - t1
    frames = iterations * cfg.batch_size
    rate = raw_rate(env, 2 * cfg.horizon, nthread)
    t_train = t_collect + t_update
    t_raw = frames * env.scene.config.substeps / rate
    print(
        f"{sid} preset {preset_name} ({cfg.num_envs} worlds, horizon {cfg.horizon}, MLP {list(cfg.actor_hidden)}, "
        f"obs {env.observation_size}, actions {env.action_size}, {nthread} threads)\n"
        f"  raw mj_step         {rate:10,.0f} steps/s  = {rate / env.scene.config.substeps:8,.0f} control frames/s\n"
        f"  training            {frames / t_train:10,.0f} frames/s  (collect {frames / t_collect:,.0f} frames/s, "
        f"update {t_update / t_train:.0%} of the time)\n"
        f"  physics share       {t_raw / t_train:10.1%}  (raw physics time / training time)"
    )
    env.close()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--dataset", type=Path)
    ap.add_argument("--sequence", default="sub2_largetable_000")
    ap.add_argument("--preset", default="cpu")
    ap.add_argument("--num-envs", type=int)
    ap.add_argument("--iterations", type=int, default=5)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        path = args.dataset
        if path is None:
            from wristmimic.convert.common import ConvertOptions
            from wristmimic.convert.intermimic import convert_intermimic

            path = Path(tmp) / "omomo.h5"
            opts = ConvertOptions(show_progress=False)
            convert_intermimic(SHARED / "intermimic_omomo", path, sequences=[args.sequence], options=opts)
        bench(path, args.sequence, args.preset, args.iterations, args.num_envs)


if __name__ == "__main__":
    main()
