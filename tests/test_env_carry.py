"""Carry feedforward (``EnvConfig.carry_feedforward``): arm and torso target offsets that hold up a carried
object's weight at the hands touching it, only while the reference has it off its supports, and the same targets
in training, evaluation and view."""

from __future__ import annotations

from pathlib import Path

import mujoco
import numpy as np
import pytest
import torch
from targets import assert_train_evaluate_view_targets_match

from wristmimic.env.carry import lifted_frames
from wristmimic.env.config import variant_config
from wristmimic.env.gravity import leg_bodies
from wristmimic.env.vec_env import WristMimicEnv
from wristmimic.synth.generate import generate

SID = "synth_default"


@pytest.fixture(scope="module")
def synth(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return generate(tmp_path_factory.mktemp("carry") / "synth.h5", seed=0, variants=("default",))


def _env(path: Path, **kw) -> WristMimicEnv:
    return WristMimicEnv.from_file(path, SID, 2, variant_config("wristmimic", **kw), nthread=1, seed=0)


def test_carry_offsets_hold_the_box_weight_at_the_hands_only_while_it_is_lifted(synth: Path) -> None:
    """At a mid-carry frame, PD at the reference pose with the offsets exerts sum_h J_h^T (m g / 2) z on the
    arm and torso hinges (J_h at the mean reference position of hand h's contacting bodies); nothing on legs or
    fingers, and nothing while the box rests on the table."""
    env, plain = _env(synth, carry_feedforward=True), _env(synth)
    sc, m, ref = env.scene, env.scene.model, env.ref
    qpos = env._ref_qpos.numpy()
    T = ref.num_frames
    lifted = lifted_frames(sc, qpos, np.arange(T))[:, 0]
    assert not lifted[0] and lifted.sum() >= 30  # on the table at the start, carried later
    active = np.abs(env.carry_feedforward.numpy()).sum(1) > 0
    assert active.any() and set(np.flatnonzero(active)) <= set(np.flatnonzero(lifted & ref.hand.numpy().any(-1)))
    # the middle of the longest lifted two-handed run (full ramp)
    both = lifted & ref.hand.numpy().all(-1)
    f = int(np.flatnonzero(both)[both.sum() // 2])
    a = torch.zeros(1, env.action_size)
    frames = torch.tensor([f])
    diff = (env.action_to_ctrl(a, frames) - plain.action_to_ctrl(a, frames)).numpy()[0]
    skel, roles = sc.skeleton, sc.humanoid.roles
    excluded = np.isin(skel.joint_bodies, list(roles["fingers"]) + leg_bodies(sc))
    keep = np.repeat(~excluded, 3)
    assert np.all(diff[~keep] == 0.0) and np.abs(diff[keep]).max() > 1e-3
    d = mujoco.MjData(m)
    d.qpos[:] = qpos[f]
    mujoco.mj_kinematics(m, d)
    mujoco.mj_comPos(m, d)
    weight = float(m.body_mass[sc.dynamic_objects[0].body_id]) * 9.81
    tau = np.zeros(m.nv)
    for side, key in enumerate(("left_hand", "right_hand")):
        bodies = np.asarray(roles[key])
        touching = bodies[ref.labels.numpy()[f, bodies] > 0]
        point = d.xpos[sc.body_ids[touching]].mean(0)
        jac = np.zeros((3, m.nv))
        mujoco.mj_jac(m, d, jac, None, point, int(sc.body_ids[int(roles["wrists"][side])]))
        tau += jac.T @ np.array([0.0, 0.0, weight / 2])
    want = tau[sc.hinge_dofadr.reshape(-1)]
    np.testing.assert_allclose((sc.gains[:, 0] * diff)[keep], want[keep], rtol=1e-3, atol=1e-3)
    # holding a load up asks the shoulders for torque: the offsets are not a rounding error
    assert np.abs(want[keep]).max() > 1.0


def test_carry_off_by_default_and_not_in_absolute_mode(synth: Path) -> None:
    assert not _env(synth).carry_feedforward.any()
    assert not _env(synth, carry_feedforward=True, action_mode="absolute").carry_feedforward.any()


def test_train_evaluate_and_view_apply_the_same_carry(synth: Path, tmp_path: Path) -> None:
    frames = torch.tensor([70, 90])
    assert_train_evaluate_view_targets_match(
        synth, SID, tmp_path / "run", frames, "carry_feedforward", carry_feedforward=True
    )
