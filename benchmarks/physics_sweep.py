"""Physics settings by measurement (issue #15, "a higher ceiling"): the raw control-frame rate of candidate
solver / timestep settings beside the defaults (Newton with 100 iterations at 1/120 s x 4), in the same process,
with a fidelity check for each.

Usage:  python benchmarks/physics_sweep.py [--dataset datasets/omomo.h5 --sequence sub2_largetable_000] [--only 1/60]

For each scene (default: ``sub2_largetable_000`` and ``s110_move_kettle`` converted from the shared data) and each
candidate :class:`~wristmimic.scene.SceneConfig` it prints:

- raw control frames/s: plain ``mujoco.rollout`` on all cores (``physics_settings.raw_step_rate``) from 256
  worlds' states reached by the training environment under that setting (small random residual actions,
  8 steps from failure-weighted starts), divided by the setting's substeps; and the ratio to the defaults;
- mean contacts and Newton/CG/PGS iterations per physics step at those states;
- fidelity: open-loop PD replay of the reference (no policy) for 30 frames from frame 0: root and wrist position
  error at frame 30 (cm). It shows gross changes only: a policy's success rate is the real gate.

Each rate is measured over ``--seconds`` per setting; run it on a quiet machine (nothing else on the cores).
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
from dataclasses import replace
from pathlib import Path

import mujoco
import numpy as np
import torch

from wristmimic.env.vec_env import WristMimicEnv
from wristmimic.format.reader import open_dataset
from wristmimic.rl.config import preset_env
from wristmimic.scene import SceneConfig, build_scene

sys.path.insert(0, str(Path(__file__).resolve().parent))
from env_step import _default_datasets  # noqa: E402
from physics_settings import raw_step_rate  # noqa: E402

NEWTON = SceneConfig(solver="newton", iterations=100)  # MuJoCo's defaults and the scene's
CANDIDATES: dict[str, SceneConfig] = {
    "newton 100 it, 1/120 x 4 (defaults)": NEWTON,
    "newton tol 1e-6": replace(NEWTON, tolerance=1e-6),
    "newton 4 it, 8 ls, tol 1e-6": replace(NEWTON, iterations=4, ls_iterations=8, tolerance=1e-6),
    "pgs 20 it": replace(NEWTON, solver="pgs", iterations=20),
    "cg": replace(NEWTON, solver="cg"),
    "elliptic cone": replace(NEWTON, cone="elliptic"),
    "newton, 1/90 x 3": replace(NEWTON, timestep=1 / 90, substeps=3),
    "newton, 1/60 x 2": replace(NEWTON, timestep=1 / 60, substeps=2),
    "pgs 20 it, 1/60 x 2": replace(NEWTON, solver="pgs", iterations=20, timestep=1 / 60, substeps=2),
    "newton, 1/60 x 2, refsafe off": replace(NEWTON, timestep=1 / 60, substeps=2, refsafe=False),
    "pgs 20 it, 1/60 x 2, refsafe off": replace(
        NEWTON, solver="pgs", iterations=20, timestep=1 / 60, substeps=2, refsafe=False
    ),
}


def _states(path: Path, sid: str, cfg: SceneConfig, worlds: int) -> tuple[mujoco.MjModel, np.ndarray, np.ndarray]:
    env = WristMimicEnv.from_file(path, sid, worlds, preset_env("cpu", "wristmimic"), cfg, seed=0, nthread=1)
    env.eval_info = False
    env.reset(seed=0)
    gen = torch.Generator().manual_seed(0)
    for _ in range(8):
        env.step(torch.rand(worlds, env.action_size, generator=gen) * 0.2 - 0.1)
    out = env.scene.model, env.backend.state.copy(), env._ctrl.double().numpy().copy()
    env.close()
    return out


def _solver_stats(m: mujoco.MjModel, states: np.ndarray, ctrl: np.ndarray) -> tuple[float, float]:
    d = mujoco.MjData(m)
    ncon, nit = [], []
    for i in range(0, len(states), 4):
        mujoco.mj_setState(m, d, states[i], mujoco.mjtState.mjSTATE_FULLPHYSICS)
        d.ctrl[:] = ctrl[i]
        mujoco.mj_step(m, d)
        ncon.append(d.ncon)
        nit.append(d.solver_niter[0])
    return float(np.mean(ncon)), float(np.mean(nit))


def _replay(path: Path, sid: str, cfg: SceneConfig, frames: int = 30) -> tuple[float, float]:
    """Root and mean wrist position error (m) after ``frames`` frames of open-loop PD replay from frame 0."""
    with open_dataset(path) as ds:
        sc = build_scene(ds, sid, cfg)
        s = ds.sequence(sid).load()
    m, d = sc.model, mujoco.MjData(sc.model)
    d.qpos[0:3], d.qpos[3:7] = s.root_pos[0], s.root_quat[0]
    d.qpos[sc.hinge_qposadr.ravel()] = s.joint_angles[0].ravel()
    for k, o in enumerate(sc.objects):
        if o.dynamic:
            d.qpos[o.qposadr : o.qposadr + 3] = s.object_pos[0, k]
            d.qpos[o.qposadr + 3 : o.qposadr + 7] = s.object_quat[0, k]
    mujoco.mj_forward(m, d)
    wrists = [int(b) for b in sc.humanoid.roles["wrists"]]
    t = min(frames, s.num_frames - 1)
    for f in range(1, t + 1):
        d.ctrl[sc.actuator_ids.ravel()] = np.clip(s.joint_angles[f].ravel(), sc.ctrl_range[:, 0], sc.ctrl_range[:, 1])
        for _ in range(cfg.substeps):
            mujoco.mj_step(m, d)
    root = float(np.linalg.norm(d.qpos[:3] - s.root_pos[t]))
    wrist = float(np.mean([np.linalg.norm(d.xpos[sc.body_ids[w]] - s.body_pos[t, w]) for w in wrists]))
    return root, wrist


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--dataset", type=Path)
    ap.add_argument("--sequence")
    ap.add_argument("--worlds", type=int, default=256)
    ap.add_argument("--seconds", type=float, default=3.0)
    ap.add_argument(
        "--only",
        action="append",
        default=[],
        help="run the candidates whose name contains this (repeatable; the defaults always run)",
    )
    args = ap.parse_args()
    first = next(iter(CANDIDATES))
    chosen = {k: v for k, v in CANDIDATES.items() if k == first or not args.only or any(o in k for o in args.only)}
    nthread = os.cpu_count() or 1
    with tempfile.TemporaryDirectory() as tmp:
        pairs = [(args.dataset, args.sequence)] if args.dataset else _default_datasets(Path(tmp))
        for path, sid in pairs:
            print(f"{sid} ({nthread} threads, {args.worlds} worlds)", flush=True)
            base = None
            for name, cfg in chosen.items():
                m, st, ctrl = _states(path, sid, cfg, args.worlds)
                rate = raw_step_rate(m, st, ctrl, cfg.substeps, nthread, args.seconds) / cfg.substeps
                base = base or rate
                ncon, nit = _solver_stats(m, st, ctrl)
                root, wrist = _replay(path, sid, cfg)
                print(
                    f"  {name:<34} raw {rate:7,.0f} control frames/s  x{rate / base:4.2f}  contacts {ncon:4.1f}  "
                    f"solver it {nit:4.1f}  replay@30: root {root * 100:5.1f} cm, wrists {wrist * 100:5.1f} cm",
                    flush=True,
                )


if __name__ == "__main__":
    main()
