"""A reference whose palms do not lie inside objects (``env.clear_hands``)."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import mujoco
import numpy as np
import pytest
import torch

from wristmimic.env.clearance import _Palm, arm_chains
from wristmimic.env.config import EnvConfig, check_env_config
from wristmimic.env.reference import load_reference
from wristmimic.env.vec_env import WristMimicEnv
from wristmimic.format import open_dataset
from wristmimic.rotations import quat_to_matrix
from wristmimic.scene import build_scene

SEQ = "sub2_largetable_000"


def _palm_depths(env: WristMimicEnv) -> np.ndarray:
    """(T, 2) deepest penetration of each palm into the table, the environment's reference state posed."""
    m, d = env.scene.model, mujoco.MjData(env.scene.model)
    palms = [_Palm(env.scene, w) for w, _ in arm_chains(env.scene)]
    table = env._ref_qpos.numpy()
    out = np.zeros((len(table), len(palms)))
    for t in range(len(table)):
        d.qpos[:] = table[t]
        mujoco.mj_kinematics(m, d)
        mujoco.mj_collision(m, d)
        out[t] = [p.deepest(d)[0] for p in palms]
    return out


@pytest.fixture(scope="module")
def pair(omomo_h5: Path) -> tuple[WristMimicEnv, WristMimicEnv]:
    cfg = EnvConfig()
    return WristMimicEnv.from_file(omomo_h5, SEQ, 1, cfg), WristMimicEnv.from_file(
        omomo_h5, SEQ, 1, replace(cfg, clear_hands=True)
    )


def test_sub2_palms_leave_the_table_and_keep_their_orientation(pair: tuple[WristMimicEnv, WristMimicEnv]) -> None:
    """OMOMO's palms lie up to ~19 mm inside sub2's table top through the carry; cleared, at most 2 mm."""
    old, new = pair
    before, after = _palm_depths(old), _palm_depths(new)
    assert before.max() > 0.015 and (before > 0.003).any(axis=1).sum() > 90
    assert after.max() <= 0.002 + 1e-6
    assert new.ref.clear_hands and new.ref.palms_cleared > 90 and not old.ref.clear_hands
    wrists = [w for w, _ in arm_chains(new.scene)]
    shift = (new.ref.body_pos[:, wrists] - old.ref.body_pos[:, wrists]).norm(dim=-1)
    assert 0.01 < shift.max() < 0.03  # moved out by about the penetration, no further
    q0, q1 = old.ref.body_quat[:, wrists].double(), new.ref.body_quat[:, wrists].double()
    angle = 2 * torch.acos((q0 * q1).sum(-1).abs().clamp(max=1.0))
    assert angle.max() < np.radians(3)  # the wrist keeps its reference orientation


def test_only_arm_joints_and_the_bodies_they_carry_change(pair: tuple[WristMimicEnv, WristMimicEnv]) -> None:
    old, new = pair
    skel = new.scene.skeleton
    arm_bodies = {b for _, chain in arm_chains(new.scene) for b in chain}
    arm_joints = [j for j, b in enumerate(skel.joint_bodies) if int(b) in arm_bodies]
    delta = (new.ref.joint_angles - old.ref.joint_angles).abs().reshape(new.ref.num_frames, -1, 3).amax(dim=(0, 2))
    moved = set(torch.nonzero(delta > 0).flatten().tolist())
    assert moved and moved <= set(arm_joints)
    carried = set()
    for b in arm_bodies:
        carried.update(skel.subtree(b))
    still = [b for b in range(skel.num_bodies) if b not in carried]
    torch.testing.assert_close(new.ref.body_pos[:, still], old.ref.body_pos[:, still], rtol=0, atol=1e-6)
    torch.testing.assert_close(new.ref.obj_pos, old.ref.obj_pos, rtol=0, atol=0)
    steps = (new.ref.joint_angles[1:] - new.ref.joint_angles[:-1]).abs().max()
    steps0 = (old.ref.joint_angles[1:] - old.ref.joint_angles[:-1]).abs().max()
    assert steps < steps0 + 0.05  # smoothed: no jump where a contact window starts


def test_the_environment_refuses_a_reference_loaded_otherwise(
    pair: tuple[WristMimicEnv, WristMimicEnv], omomo_h5: Path
) -> None:
    old, new = pair
    with pytest.raises(ValueError, match="clear_hands True needs a reference loaded with that"):
        WristMimicEnv(old.scene, old.ref, 1, replace(old.cfg, clear_hands=True))
    with pytest.raises(ValueError, match="clear_hands must be true or false"):
        check_env_config(replace(EnvConfig(), clear_hands="yes"))  # type: ignore[arg-type]
    with open_dataset(omomo_h5) as ds:  # deterministic: loaded again, the same reference
        again = load_reference(ds, build_scene(ds, SEQ, None), new.cfg.ig_points, 0, clear_hands=True)
    torch.testing.assert_close(again.joint_angles, new.ref.joint_angles, rtol=0, atol=0)


def test_kettle_palms_touch_nothing_so_nothing_changes(parahome_h5: Path) -> None:
    """ParaHome's kettle is held by the fingers through the handle; no palm lies inside it."""
    with open_dataset(parahome_h5) as ds:
        scene = build_scene(ds, "s110_move_kettle", None)
        ref = load_reference(ds, scene, 64, 0, clear_hands=True)
    assert ref.clear_hands and ref.palms_cleared == 0


def test_wrist_offsets_move_each_touching_hand_in_the_object_frame(
    pair: tuple[WristMimicEnv, WristMimicEnv], omomo_h5: Path
) -> None:
    """The grip probe's arm offset map, applied to the reference: the wrist moves by R_obj @ offset where the
    reference hand touches the object, keeps its orientation to first order, and nothing moves far from contact."""
    old, _ = pair
    off = (0.0, 0.0, 0.03, 0.0, -0.02, 0.01)
    env = WristMimicEnv.from_file(omomo_h5, SEQ, 1, replace(old.cfg, wrist_offsets=off))
    assert env.ref.wrist_offsets == off
    wrists = [w for w, _ in arm_chains(env.scene)]
    touch = old.ref.hand.numpy().astype(bool)
    rot = quat_to_matrix(old.ref.obj_quat[:, 0].double().numpy())
    moved = (env.ref.body_pos[:, wrists] - old.ref.body_pos[:, wrists]).double().numpy()
    for h in range(2):
        want = rot @ np.asarray(off[3 * h : 3 * h + 3])
        frames = np.flatnonzero(touch[:, h])
        assert len(frames) > 50
        size = np.linalg.norm(off[3 * h : 3 * h + 3])
        err = np.linalg.norm(moved[frames, h] - want[frames], axis=-1)
        cos = (moved[frames, h] * want[frames]).sum(-1) / np.linalg.norm(moved[frames, h], axis=-1) / size
        # a first-order map at the reference pose: on sub2 within 5 % (left) and 23 % (right) of the offset
        assert np.median(err) < 0.25 * size and err.max() < 0.3 * size and cos.min() > 0.96
    far = ~np.convolve(touch.any(1), np.ones(21), mode="same").astype(bool)  # > 10 frames from any contact
    assert far[:10].all()
    torch.testing.assert_close(env.ref.joint_angles[far], old.ref.joint_angles[far], rtol=0, atol=0)
    q0, q1 = old.ref.body_quat[:, wrists].double(), env.ref.body_quat[:, wrists].double()
    assert (2 * torch.acos((q0 * q1).sum(-1).abs().clamp(max=1.0))).max() < np.radians(5)
    with pytest.raises(ValueError, match="wrist_offsets .* need a reference loaded with those offsets"):
        WristMimicEnv(old.scene, old.ref, 1, replace(old.cfg, wrist_offsets=off))
    for bad in ((0.0,) * 5, (0.0,) * 5 + (0.5,), (True,) * 6):
        with pytest.raises(ValueError, match="wrist_offsets must be empty or six numbers"):
            check_env_config(replace(EnvConfig(), wrist_offsets=bad))  # type: ignore[arg-type]
