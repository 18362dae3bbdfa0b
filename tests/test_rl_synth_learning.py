"""The recommended CPU recipe learns on the built-in synthetic scene: after 102,400 frames (~2 minutes on 2
cores) its policy survives frame-0 trials of the quick protocol clearly longer than the zero-action policy.

Measured with the recipe and reference of 2026-12-02 (64 trials, the recipe's sigma 0.1 for both policies), seeds
0, 1, 2: trained 62.4, 131.6 and 87.6 frames against 33.8 for zero actions (deterministic); object position error
1.1, 6.3 and 4.7 cm against 0.7 cm (the zero-action hands never move the box, so object error cannot separate the
policies). The seeds now differ by up to 69 frames, but the smallest gap to zero actions is 28.6 frames; the margin
asserted, 4 frames, stays far below it (it was chosen for the previous recipe, whose seeds gave 40.9, 40.0, 40.9
against 32.9). "Not knocked away" is asserted at the paper's success threshold, 10 cm of mean object error: the seeds'
1.1-6.3 cm are seed noise (a fresh machine of 2026-12-02 gave seed 0 4.5 cm, the same code having given 1.1 on the
previous one: floating-point differences between machines grow over a training run), a box knocked off the
table is tens of centimetres off. The recipe of 2026-12-04 (32 worlds, an update every 1,024 frames) learns faster
per frame (its three seeds passed 90 % in periodic evaluations by 205-328k frames, against never for 64 worlds on
the same machine); its seeds at this budget were not re-measured. With the recipe's object terms of 2026-12-04
(object position lambda 300, episodes ended at 10 cm of object error) the test passes on seed 0 (2 threads, AMD
EPYC); the seed noise was not re-measured for it either. Re-measured with the recipe of 2026-12-04 that explores with
correlated noise (AR(1), rho 0.9; 2 threads, AMD EPYC): seeds 0, 1, 2 trained 63.2, 65.2 and 75.0 frames against
33.6 for zero actions (smallest gap 29.6 frames, against the 4-frame margin), object error 1.3, 1.5 and 2.4 cm.
With the recipe of 2026-12-05 (one epoch per update, the rate adapted to the update's closed-form KL; 2 threads,
Intel Xeon): seeds 0, 1, 2 trained 67.5, 110.8 and 71.7 frames against 33.6 for zero actions (smallest gap 33.9
frames, against the 4-frame margin), object error 1.7, 2.7 and 1.9 cm. With the hands' friction 2 (the defaults of
1bf6ccf; 1 thread, AMD EPYC, 2026-12-07): seeds 0, 1, 2 trained 137.1, 103.5 and 96.6 frames against 33.2 for zero
actions (smallest gap 63.4 frames), object error 3.6, 2.6 and 2.9 cm
(`reports/ablation_synth_default_20261207/slow_test_seeds.json`).
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import torch

from wristmimic.evaluate.policy import load_eval_policy
from wristmimic.evaluate.protocol import load_protocol
from wristmimic.evaluate.trials import TrialSettings, make_env, run_trials
from wristmimic.rl import TrainSpec, preset, start_run
from wristmimic.synth.generate import generate

FRAMES, TRIALS, MARGIN = 102_400, 64, 4.0


class _Zero:
    """Zero mean actions with the recipe's initial sigma (the untrained policy)."""

    def __init__(self, metadata: dict, action_size: int, sigma: float):
        self.metadata, self._a, self._sigma = metadata, action_size, sigma

    def act(self, obs: torch.Tensor, deterministic: bool = True) -> torch.Tensor:
        return torch.zeros(obs.shape[0], self._a)

    @property
    def sigma(self) -> torch.Tensor:
        return torch.full((self._a,), self._sigma)


def _trials(policy) -> tuple[float, float]:
    env = make_env(policy.metadata, 32, nthread=2)
    recs: list[dict] = []
    run_trials(env, policy, TrialSettings.from_protocol(load_protocol("quick")), 0, TRIALS, recs.append)
    env.close()
    frames = np.concatenate([r["frames_completed"] for r in recs])
    obj = np.concatenate([r["obj_pos_err_cm"] for r in recs])
    return float(frames.mean()), float(np.nanmean(obj))


@pytest.mark.slow
def test_recipe_survives_frame_0_trials_longer_than_zero_actions(tmp_path: Path) -> None:
    synth = generate(tmp_path / "synth.h5", seed=0, variants=("default",))
    ppo = replace(preset("cpu"), max_frames=FRAMES, eval_every=0)
    start_run(
        TrainSpec(synth, "synth_default", "wristmimic", 0, "cpu", ppo), tmp_path / "run", nthread=2, progress=False
    )
    trained = load_eval_policy(tmp_path / "run")
    zero = _Zero(trained.metadata, trained.policy.action_size, ppo.sigma)
    (f_trained, obj_trained), (f_zero, _) = _trials(trained), _trials(zero)
    assert f_trained > f_zero + MARGIN, (f_trained, f_zero)
    assert obj_trained < 10.0  # the object is not knocked away (seeds: 1.1-6.3 cm)
