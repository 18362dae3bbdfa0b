"""Shared check for PD-target offsets (gravity, squeeze, carry): training, evaluation and ``view`` build
environments that map the same actions to the same targets."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import torch

from wristmimic.env.config import variant_config
from wristmimic.env.vec_env import WristMimicEnv


def assert_train_evaluate_view_targets_match(
    path: Path, sid: str, run_dir: Path, frames: torch.Tensor, offsets: str, **env_kw: object
) -> None:
    """Train a tiny run with ``env_kw``, then check that the evaluation and view environments of its policy keep
    those settings and give the training environment's PD targets, bit for bit, at ``frames`` (where the
    training environment's ``offsets`` attribute is non-zero)."""
    from wristmimic.evaluate.policy import load_eval_policy
    from wristmimic.evaluate.trials import make_env
    from wristmimic.rl import TrainSpec, preset, start_run
    from wristmimic.view.rollout import env_for_policy

    env_cfg = variant_config("wristmimic", **env_kw)
    ppo = preset("cpu", num_envs=4, horizon=8, minibatch_size=16, epochs=1, actor_hidden=(16,), critic_hidden=(16,))
    spec = TrainSpec(path, sid, "wristmimic", 0, "cpu", replace(ppo, max_frames=32), env=env_cfg)
    start_run(spec, run_dir, progress=False)
    policy = load_eval_policy(run_dir)
    train_env = WristMimicEnv.from_file(path, sid, 2, env_cfg, nthread=1, seed=0)
    a = torch.linspace(-1, 1, 2 * train_env.action_size).reshape(2, -1)
    want = train_env.action_to_ctrl(a, frames)
    assert getattr(train_env, offsets)[frames].abs().max() > 1e-3
    for env in (make_env(policy.metadata, 2), env_for_policy(policy, None, None)):
        assert all(getattr(env.cfg, k) == v for k, v in env_kw.items())
        n = env.num_worlds
        torch.testing.assert_close(env.action_to_ctrl(a[:n], frames[:n]), want[:n], rtol=0, atol=0)
