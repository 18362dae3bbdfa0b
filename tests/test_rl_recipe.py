"""The recommended CPU recipe on the built-in synthetic scene: PPO stays inside its trust region on a short
real run (the issue's bound: median approx KL <= 0.03 and median clip fraction <= 0.3 over the run, and no first
update far outside it)."""

from __future__ import annotations

import runpy
from dataclasses import replace
from pathlib import Path

import pandas as pd
import pytest

from wristmimic.rl import TrainSpec, preset, start_run
from wristmimic.rl.config import preset_env
from wristmimic.synth.generate import generate

ITERATIONS = 64


@pytest.fixture(scope="module")
def synth(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return generate(tmp_path_factory.mktemp("recipe") / "synth.h5", seed=0, variants=("default",))


@pytest.mark.slow
def test_cpu_recipe_stays_in_its_trust_region(synth: Path, tmp_path: Path) -> None:
    ppo = replace(preset("cpu"), max_frames=preset("cpu").batch_size * ITERATIONS, eval_every=0)
    start_run(
        TrainSpec(synth, "synth_default", "wristmimic", 0, "cpu", ppo), tmp_path / "run", nthread=2, progress=False
    )
    m = pd.read_csv(tmp_path / "run" / "metrics.csv")
    assert len(m) == ITERATIONS
    kl, clip = m["loss/approx_kl"].median(), m["loss/clip_fraction"].median()
    assert kl <= 0.03 and clip <= 0.3, (kl, clip)
    # the KL the schedule answers: the closed-form KL of each whole update, held in the band around 0.015
    assert 0.0 < m["loss/kl_update"].median() <= 0.03, m["loss/kl_update"].median()
    # the first update too: the schedule starts at its floor (from 1e-4 the first approx KL was 1e3-1e9)
    assert m["loss/approx_kl"].iloc[0] < 1.0, m["loss/approx_kl"].iloc[0]
    assert m["loss/learning_rate"].between(ppo.lr_min, ppo.lr_max).all()
    assert (m["loss/sigma"] >= ppo.min_std).all()


def test_presets_set_their_environment() -> None:
    paper, cpu = preset_env("paper", "wristmimic"), preset_env("cpu", "wristmimic")
    assert paper.action_mode == "absolute" and not paper.object_controller.enabled and not paper.starts.adaptive
    assert cpu.action_mode == "residual" and cpu.object_controller.enabled and cpu.starts.adaptive
    assert preset_env("cpu", "intermimic").finger_targets  # the variant's flags stay
    # the recipe weighs the object's rotation 10x the paper and its position 60x, and ends an episode when the
    # object is 10 cm off (a box left on the table or tipped must cost reward and the episode)
    assert paper.weights.orot == pytest.approx(0.1) and cpu.weights.orot == pytest.approx(1.0)
    assert paper.weights.op == pytest.approx(5.0) and cpu.weights.op == pytest.approx(300.0)
    assert paper.termination.object_error == 0.5 and cpu.termination.object_error == pytest.approx(0.1)
    assert cpu.weights.ig == paper.weights.ig and cpu.termination.body_error == paper.termination.body_error
    assert preset("paper").schedule == "fixed" and not preset("paper").learn_std
    # the recipe explores with temporally correlated noise (AR(1), rho 0.9); the paper with white noise
    assert preset("cpu").noise_correlation == pytest.approx(0.9) and preset("paper").noise_correlation == 0.0
    # the recipe adapts its rate once per update to the update's closed-form KL (one epoch, 4 minibatches)
    cpu_ppo = preset("cpu")
    assert (cpu_ppo.schedule, cpu_ppo.kl_source, cpu_ppo.epochs) == ("adaptive_update", "update", 1)
    assert cpu_ppo.batch_size // cpu_ppo.minibatch_size == 4 and cpu_ppo.desired_kl == pytest.approx(0.015)


def test_ablation_rows_each_change_one_lever_of_the_recipe() -> None:
    """scripts/ablation.py: every training row builds valid configs that differ from the recipe's in the fields it
    names and nowhere else; eval-only rows name a training row; the training signals are read from metrics.csv."""
    abl = runpy.run_path(str(Path(__file__).parents[1] / "scripts" / "ablation.py"))
    env0, ppo0 = preset_env("cpu", "wristmimic"), preset("cpu")
    for name, (_, env_kw, ppo_kw) in abl["ROWS"].items():
        env, ppo = replace(env0, **env_kw), replace(ppo0, **ppo_kw)
        changed = {f for f in env_kw if getattr(env, f) != getattr(env0, f)}
        changed |= {f for f in ppo_kw if getattr(ppo, f) != getattr(ppo0, f)}
        assert changed == set(env_kw) | set(ppo_kw), name  # a row whose value equals the recipe's ablates nothing
        assert (name in abl["EVAL_ONLY"] or name == "recipe") == (not changed), name
    assert {src for src, _, _ in abl["EVAL_ONLY"].values()} <= set(abl["ROWS"])
    m = pd.DataFrame(
        {
            "loss/approx_kl": [0.01, 0.02, 5.0],
            "loss/clip_fraction": [0.1, 0.2, 0.9],
            "eval/success_rate": [None, 0.5, 1.0],
        }
    )
    assert abl["_training_signals"](m) == {
        "median_approx_kl": 0.02,
        "median_kl_update": None,
        "median_clip_fraction": 0.2,
        "periodic_success_pct": "50 100",
    }
    assert abl["_training_signals"](m.assign(**{"loss/kl_update": [0.03, 0.01, 0.02]}))["median_kl_update"] == 0.02
