"""Physics settings compared by the benchmarks, and the raw ``mj_step`` rate they are measured against.

``BEFORE`` is the physics of the commit issue #15 started from (7b14b30's ``SceneConfig``: 1/120 s x 4 substeps),
with every sensor evaluated at the state just reached by a full extra forward pass (what the sensor-lag fix
added); ``NOW`` is today's defaults. The raw rate is plain ``mujoco.rollout`` of the scene's model (``nstep`` =
substeps per call, no extra sensor pass, solver warm start cleared per call as in the environment), from the
environment's own states and controls, on the same threads: the ceiling an environment built on it can reach.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import mujoco
import numpy as np
from mujoco import rollout

from wristmimic.scene import SceneConfig


@dataclass(frozen=True)
class Settings:
    name: str
    scene: SceneConfig
    backend_options: dict = field(default_factory=dict)


BEFORE = Settings(
    "before (7b14b30 physics)",
    SceneConfig(timestep=1.0 / 120.0, substeps=4, solver="newton", iterations=100),
    {"exact_contacts": True},
)
NOW = Settings("now (defaults)", SceneConfig(), {})
PGS = Settings("pgs 20 it", SceneConfig(solver="pgs", iterations=20), {})
"""PGS with 20 iterations: 1.24-1.33x training frames/s, but it fails issue #15's fidelity gate (``SceneConfig.solver``)."""
DT90 = Settings("newton 1/90 s x 3", SceneConfig(timestep=1.0 / 90.0, substeps=3), {})
"""Newton at 1/90 s x 3 substeps: 1.19-1.23x the raw rate (``physics_sweep.py``); with the recipe of 2026-12-05 and the
hands' friction 2, synth_default succeeds in 100 %, but on the 1.55 m humanoid in 93.4 % (89.6-95.8) against 100 %, so it
fails issue #15's fidelity gate (``reports/timestep_refsafe_20261207/``)."""


def raw_step_rate(
    model: mujoco.MjModel, states: np.ndarray, ctrl: np.ndarray, substeps: int, nthread: int, seconds: float = 3.0
) -> float:
    """Physics steps per second of ``mujoco.rollout`` stepping ``states`` (n, nstate) ``substeps`` steps per call
    under ``ctrl`` (n, nu), repeated from the same states for ``seconds``."""
    n = len(states)
    pool = rollout.Rollout(nthread=nthread)
    datas = [mujoco.MjData(model) for _ in range(nthread)]
    c = np.ascontiguousarray(np.broadcast_to(np.asarray(ctrl, np.float64)[:, None], (n, substeps, model.nu)))
    st = np.ascontiguousarray(states)
    out = np.empty((n, substeps, len(st[0])))
    pool.rollout(model, datas, st, c, nstep=substeps, state=out)  # warm-up
    calls, t0 = 0, time.perf_counter()
    while time.perf_counter() - t0 < seconds:
        pool.rollout(model, datas, st, c, nstep=substeps, state=out)
        calls += 1
    rate = calls * n * substeps / (time.perf_counter() - t0)
    pool.close()
    return rate


def dataset_or_shared_omomo(path, sequence: str, tmp: str):
    """``path`` if given, else ``sequence`` of the shared InterMimic OMOMO copy converted into ``tmp``."""
    from pathlib import Path

    if path is not None:
        return Path(path)
    from wristmimic.convert.common import ConvertOptions
    from wristmimic.convert.intermimic import convert_intermimic

    out = Path(tmp) / "omomo.h5"
    shared = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "intermimic_omomo"
    convert_intermimic(shared, out, sequences=[sequence], options=ConvertOptions(show_progress=False))
    return out
