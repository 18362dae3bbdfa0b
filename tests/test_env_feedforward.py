"""Feedforward warm start: knot interpolation, the optimiser's output, and one set of offsets shared by training,
evaluation and view."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import pytest
import torch

from wristmimic.env.config import FeedforwardConfig, variant_config
from wristmimic.env.feedforward import interpolate, knot_count, optimise_feedforward
from wristmimic.env.vec_env import WristMimicEnv
from wristmimic.evaluate.policy import load_eval_policy
from wristmimic.evaluate.trials import make_env
from wristmimic.rl import TrainSpec, preset, resume_run, start_run
from wristmimic.rl.checkpoint import load_checkpoint
from wristmimic.view.rollout import env_for_policy

from synthetic import converted_intermimic

SID = "sub1_box_000"
SMALL = FeedforwardConfig(enabled=True, knot_frames=10, horizon_knots=2, samples=4, iterations=2, elite_frac=0.5)


@pytest.fixture(scope="module")
def dataset(tmp_path_factory: pytest.TempPathFactory) -> Path:
    tmp = tmp_path_factory.mktemp("ff")
    return converted_intermimic(tmp, 30)


def test_knots_interpolate_linearly_and_cover_the_clip() -> None:
    assert knot_count(31, 10) == 4 and knot_count(32, 10) == 5
    knots = torch.tensor([[0.0], [1.0], [3.0], [3.0]])
    got = interpolate(knots, torch.tensor([0, 5, 10, 15, 29, 30]), 10)[:, 0]
    torch.testing.assert_close(got, torch.tensor([0.0, 0.5, 1.0, 2.0, 3.0, 3.0]))


def test_offsets_are_deterministic_finite_and_zero_on_fingers(dataset: Path) -> None:
    cfg = variant_config("wristmimic", feedforward=SMALL)
    runs = []
    for _ in range(2):
        env = WristMimicEnv.from_file(dataset, SID, SMALL.samples, cfg, seed=0, nthread=1)
        runs.append(optimise_feedforward(env))
        fingers = ~env.residual_hinges
        env.close()
    ff = runs[0]
    assert ff.shape == (30, fingers.numel()) and torch.isfinite(ff).all()
    assert torch.equal(runs[0], runs[1])
    assert (ff[:, fingers] == 0).all() and (ff[0] == 0).all() and ff.abs().max() > 0


def test_a_run_saves_its_offsets_and_evaluation_and_view_apply_them(dataset: Path, tmp_path: Path) -> None:
    env_cfg = variant_config("wristmimic", feedforward=SMALL)
    ppo = preset("cpu", num_envs=4, horizon=8, minibatch_size=16, epochs=1, actor_hidden=(16,), critic_hidden=(16,))
    spec = TrainSpec(dataset, SID, "wristmimic", 0, "cpu", replace(ppo, max_frames=32, eval_every=1), env=env_cfg)
    start_run(spec, tmp_path / "run", progress=False)
    ff = load_checkpoint(tmp_path / "run")["feedforward"]
    assert ff.abs().max() > 0
    policy = load_eval_policy(tmp_path / "run")
    for env in (make_env(policy.metadata, 2), env_for_policy(policy, None, None)):
        assert torch.equal(env.feedforward, ff)
    resume_run(tmp_path / "run", max_frames=64, progress=False)  # a resume keeps them (no new search)
    assert torch.equal(load_checkpoint(tmp_path / "run")["feedforward"], ff)
    off = replace(env_cfg, feedforward=replace(SMALL, enabled=False))
    start_run(replace(spec, env=off), tmp_path / "off", progress=False)
    assert (load_checkpoint(tmp_path / "off")["feedforward"] == 0).all()
