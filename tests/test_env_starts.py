"""Failure-weighted start frames (BeyondMimic's adaptive sampling)."""

from __future__ import annotations

import pytest
import torch

from wristmimic.env.config import StartSamplingConfig
from wristmimic.env.starts import AdaptiveStarts, StateBank


def test_starts_are_uniform_without_failures_and_stay_in_range() -> None:
    s = AdaptiveStarts(StartSamplingConfig(bin_frames=10), num_frames=101)
    assert s.num_bins == 10
    torch.testing.assert_close(s.probabilities(), torch.full((10,), 0.1))
    f = s.sample(20_000, torch.Generator().manual_seed(0))
    assert f.min() == 0 and f.max() == 99
    counts = torch.bincount(f // 10, minlength=10).float() / len(f)
    assert (counts - 0.1).abs().max() < 0.01


def test_failures_pull_starts_to_just_before_where_rollouts_die() -> None:
    cfg = StartSamplingConfig(bin_frames=10, alpha=0.1, uniform=0.1, kernel=3, kernel_lambda=0.5)
    s = AdaptiveStarts(cfg, num_frames=101)
    frames = torch.full((64,), 55)  # every failure in bin 5
    for _ in range(50):
        s.record(frames, torch.ones(64, dtype=torch.bool))
    p = s.probabilities()
    assert p.sum().item() == pytest.approx(1.0)
    # bins 5, 4, 3 get failure weights 1, 0.5, 0.25 (of 1.75) on top of the uniform share; later bins only that
    torch.testing.assert_close(p[[5, 4, 3]], 0.9 * torch.tensor([1, 0.5, 0.25]) / 1.75 + 0.01)
    torch.testing.assert_close(p[6:], torch.full((4,), 0.01))
    s.record(torch.full((64,), 5), torch.zeros(64, dtype=torch.bool))  # no termination: no failure counted
    assert s.failures[0] == 0


def test_sampling_is_seeded() -> None:
    s = AdaptiveStarts(StartSamplingConfig(), num_frames=50)
    s.record(torch.tensor([30, 31, 40]), torch.tensor([True, True, False]))
    a = s.sample(100, torch.Generator().manual_seed(3))
    b = s.sample(100, torch.Generator().manual_seed(3))
    assert torch.equal(a, b)


def test_state_bank_draws_only_recorded_states_of_the_frame() -> None:
    bank = StateBank(num_frames=6, size=4, nq=3, nv=2)
    gen = torch.Generator().manual_seed(0)
    have, _, _ = bank.draw(torch.tensor([0, 3, 5]), gen)
    assert not have.any()  # nothing banked yet
    qpos = torch.arange(9, dtype=torch.float64).reshape(3, 3)
    qvel = -torch.arange(6, dtype=torch.float64).reshape(3, 2)
    bank.record(torch.tensor([3, 3, 5]), torch.tensor([True, True, False]), qpos, qvel, gen)
    have, q, v = bank.draw(torch.tensor([3, 5, 3, 3]).repeat(50), gen)
    assert have.tolist() == [True, False, True, True] * 50
    rows = {tuple(r) for r in q[have].tolist()}
    assert rows <= {tuple(qpos[0].tolist()), tuple(qpos[1].tolist())} and len(rows) == 2  # either, never world 2's
    for qq, vv in zip(q[have], v[have], strict=True):  # position and velocity of the same world
        i = int(qq[0]) // 3
        assert torch.equal(vv, qvel[i])


def test_legacy_runs_have_no_state_bank_and_bad_values_are_refused() -> None:
    from dataclasses import replace

    from wristmimic.env.config import EnvConfig, check_env_config, env_config_from_dict

    assert env_config_from_dict({"starts": {"adaptive": True}}).starts.bank == 0.0
    for bad in (dict(bank=1.5), dict(bank=-0.1), dict(bank_size=0)):
        with pytest.raises(ValueError, match="bank"):
            check_env_config(replace(EnvConfig(), starts=replace(EnvConfig().starts, **bad)))
    assert not env_config_from_dict({"starts": {"adaptive": True}}).starts.depenetrate  # runs before it: off
    with pytest.raises(ValueError, match="depenetrate_tol"):
        check_env_config(replace(EnvConfig(), starts=replace(EnvConfig().starts, depenetrate_tol=float("nan"))))
