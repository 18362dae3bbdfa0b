"""Does keeping each world's solver warm start pay? (issue #15, "keep each world's MjData so the warm start
survives"). ``mujoco.rollout`` starts every call from a cleared warm start, so the environment's first substep
of every control step solves its constraints from zero acceleration.

Usage:  python benchmarks/warm_start.py [--dataset datasets/omomo.h5 --sequence sub2_largetable_000]

For each scene (default: ``sub2_largetable_000`` and ``s110_move_kettle`` converted from the shared data) it
takes 64 training worlds' states (small random residual actions from failure-weighted starts, as
``physics_sweep.py`` does) and steps each world 16 control steps of ``substeps`` physics steps on one thread, three
ways: the warm start cleared before every control step (what the environment does), kept from the previous
step (one ``MjData`` per world), and kept but set from the finite-difference acceleration of the last substep
(what a caller without ``qacc_warmstart`` could pass as ``initial_warmstart``). It prints Newton iterations per
physics step (all substeps, and the first of each control step) and single-thread steps/s for each, with the
ratio to the cleared warm start. Run it on a quiet machine.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import mujoco
import numpy as np

from wristmimic.scene import SceneConfig

sys.path.insert(0, str(Path(__file__).resolve().parent))
from env_step import _default_datasets  # noqa: E402
from physics_sweep import _states  # noqa: E402

MODES = ("cleared", "kept", "finite difference")


def run(m: mujoco.MjModel, states: np.ndarray, ctrl: np.ndarray, substeps: int, steps: int, mode: str) -> tuple:
    """(Newton iterations per step, those of first substeps, steps/s) of every world stepped ``steps`` control
    steps from its state under its control, the warm start handled as ``mode``."""
    d = mujoco.MjData(m)
    iters, first, t = [], [], 0.0
    for i in range(len(states)):
        mujoco.mj_setState(m, d, states[i], mujoco.mjtState.mjSTATE_FULLPHYSICS)
        d.ctrl[:] = ctrl[i]
        d.qacc_warmstart[:] = 0.0
        fd = None
        for _ in range(steps):
            if mode == "cleared":
                d.qacc_warmstart[:] = 0.0
            elif mode == "finite difference" and fd is not None:
                d.qacc_warmstart[:] = fd
            for k in range(substeps):
                v0 = d.qvel.copy()
                t0 = time.perf_counter()
                mujoco.mj_step(m, d)
                t += time.perf_counter() - t0
                iters.append(int(d.solver_niter[0]))
                if k == 0:
                    first.append(int(d.solver_niter[0]))
            fd = (d.qvel - v0) / m.opt.timestep
    return float(np.mean(iters)), float(np.mean(first)), len(iters) / t


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--dataset", type=Path)
    ap.add_argument("--sequence")
    ap.add_argument("--worlds", type=int, default=64)
    ap.add_argument("--steps", type=int, default=16, help="Control steps per world.")
    args = ap.parse_args()
    cfg = SceneConfig(solver="newton", iterations=100)  # Newton's iterations depend on the warm start; PGS runs all 20
    with tempfile.TemporaryDirectory() as tmp:
        pairs = [(args.dataset, args.sequence)] if args.dataset else _default_datasets(Path(tmp))
        for path, sid in pairs:
            m, st, ctrl = _states(path, sid, cfg, args.worlds)
            print(f"{sid} ({args.worlds} worlds x {args.steps} control steps x {cfg.substeps} substeps, 1 thread)")
            base = None
            for mode in MODES:
                it, it1, rate = run(m, st, ctrl, cfg.substeps, args.steps, mode)
                base = base or rate
                print(
                    f"  warm start {mode:<18} Newton it/step {it:4.2f} (first substep {it1:4.2f})  "
                    f"{rate:7,.0f} steps/s  x{rate / base:4.2f}",
                    flush=True,
                )


if __name__ == "__main__":
    main()
