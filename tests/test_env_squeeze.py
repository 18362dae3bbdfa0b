"""Grip squeeze (``EnvConfig.grip_squeeze``): arm target offsets that press both hands into an object held
between them, only in antipodal two-handed holds, and the same targets in training, evaluation and view."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import mujoco
import numpy as np
import pytest
import torch
from targets import assert_train_evaluate_view_targets_match

from wristmimic.env.config import check_env_config, variant_config
from wristmimic.env.squeeze import arm_chain, hold_weights, press_directions
from wristmimic.env.vec_env import WristMimicEnv
from wristmimic.synth.generate import generate

SID = "synth_default"
FORCE = 40.0


@pytest.fixture(scope="module")
def synth(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return generate(tmp_path_factory.mktemp("squeeze") / "synth.h5", seed=0, variants=("default",))


def _env(path: Path, sid: str = SID, **kw) -> WristMimicEnv:
    return WristMimicEnv.from_file(path, sid, 2, variant_config("wristmimic", **kw), nthread=1, seed=0)


def test_squeeze_presses_each_wrist_toward_the_box_with_the_set_force(synth: Path) -> None:
    """At a reference frame of the carry, PD at the reference pose with the offsets exerts J^T (F n) on the arm
    hinges: the wrist pushes with F newtons toward the box face it holds; nothing else changes."""
    env, plain = _env(synth, grip_squeeze=FORCE), _env(synth)
    sc, m = env.scene, env.scene.model
    hold = np.flatnonzero(np.abs(env.squeeze_feedforward.numpy()).sum(1) > 0)
    both = np.flatnonzero(env.ref.hand.all(-1).numpy())
    assert len(hold) >= 40 and set(hold) <= set(both)  # the carry, and only two-handed frames
    f = int(hold[len(hold) // 2])
    a = torch.zeros(1, env.action_size)
    frames = torch.tensor([f])
    diff = (env.action_to_ctrl(a, frames) - plain.action_to_ctrl(a, frames)).numpy()[0]
    skel = sc.skeleton
    arms = np.repeat(np.isin(skel.joint_bodies, arm_chain(sc, 0) + arm_chain(sc, 1)), 3)
    assert np.all(diff[~arms] == 0.0) and np.abs(diff[arms]).max() > 1e-3
    # PD torque of the offsets at the reference pose = J^T F n for each wrist
    d = mujoco.MjData(m)
    d.qpos[:] = env.reference_state(frames)[0][0].numpy()
    mujoco.mj_kinematics(m, d)
    mujoco.mj_comPos(m, d)
    n = press_directions(sc, env.reference_state(frames)[0].numpy(), np.array([0]))[0]
    kp = sc.gains[:, 0]
    for side in (0, 1):
        jac = np.zeros((3, m.nv))
        mujoco.mj_jacBody(m, d, jac, None, int(sc.body_ids[int(sc.humanoid.roles["wrists"][side])]))
        chain = np.repeat(np.isin(skel.joint_bodies, arm_chain(sc, side)), 3)
        tau = (jac.T @ (FORCE * n[side]))[sc.hinge_dofadr.reshape(-1)]
        np.testing.assert_allclose((kp * diff)[chain], tau[chain], atol=1e-3)
    # the synthetic palms hold opposite faces of the box: the presses are opposed and horizontal
    assert float(n[0] @ n[1]) < -0.95 and abs(n[0][2]) < 0.1


def test_hold_weights_need_both_hands_in_opposition_and_ramp_in() -> None:
    T = 14
    hand = np.zeros((T, 2), dtype=bool)
    hand[2:12] = True
    hand[9, 1] = False  # one hand lets go for a frame
    dirs = np.zeros((T, 2, 3))
    dirs[:, 0], dirs[:, 1] = [0.0, 1.0, 0.0], [0.0, -1.0, 0.0]
    w = hold_weights(hand, dirs)
    assert np.all(w[:2] == 0) and np.all(w[12:] == 0) and w[9] == 0.0
    assert 0 < w[2] < w[3] < w[4] == 1.0 and w[8] < 1.0
    dirs[:, 1] = [0.0, 1.0, 0.0]  # both press the same way (a table lifted by one edge): no squeeze
    assert np.all(hold_weights(hand, dirs) == 0.0)


def test_squeeze_off_by_default_and_checked(synth: Path) -> None:
    env = _env(synth)
    assert env.cfg.grip_squeeze == 0.0 and not env.squeeze_feedforward.any()
    with pytest.raises(ValueError, match="grip_squeeze"):
        check_env_config(replace(env.cfg, grip_squeeze=-1.0))
    with pytest.raises(ValueError, match="grip_squeeze"):
        check_env_config(replace(env.cfg, grip_squeeze=float("nan")))


def test_train_evaluate_and_view_apply_the_same_squeeze(synth: Path, tmp_path: Path) -> None:
    frames = torch.tensor([60, 75])
    assert_train_evaluate_view_targets_match(
        synth, SID, tmp_path / "run", frames, "squeeze_feedforward", grip_squeeze=FORCE
    )
