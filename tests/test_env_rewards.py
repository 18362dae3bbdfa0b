"""Reward factors on a crafted 10-body toy state, against numbers worked out by hand in the comments."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
import torch

from wristmimic.env.bodies import BodySets
from wristmimic.env.config import EnvConfig, RewardWeights, check_env_config, variant_config
from wristmimic.env.rewards import RewardInputs, arm_weights, compute_reward, error_ig, factor_names
from wristmimic.env.torch_math import quat_angle
from wristmimic.humanoid.roles import compute_roles, detect_profile
from wristmimic.humanoid.skeleton import load_skeleton

from synthetic import parahome_like_mjcf, smplx_like_mjcf

# Toy humanoid: 0 root, 1 spine, 2 L shoulder, 3 L elbow, 4 L wrist, 5 R shoulder, 6 R elbow, 7 R wrist,
# 8 L finger, 9 R finger.
ROLES = {
    "key_bodies": np.array([1, 2, 3, 4, 5, 6, 7]),
    "wrists": np.array([4, 7]),
    "left_arm": np.array([2, 3]),
    "right_arm": np.array([5, 6]),
    "fingers": np.array([8, 9]),
    "left_hand": np.array([4, 8]),
    "right_hand": np.array([7, 9]),
}
SETS = BodySets.from_roles(ROLES)
N, B = 3, 10
HALF = math.log(2.0) / 5.0  # reference distance giving w_near = exp(-5 d) = 0.5
FAR = 100.0  # w_near = 0

# per body: position offset (sim - ref), rotation angle about z (ref = identity), reference object distance
OFFSET = [(5, 0, 0), (0.1, 0, 0), (0.2, 0, 0), (0.2, 0, 0), (0.1, 0, 0), (0.3, 0, 0), (0.3, 0, 0), (0, 0.2, 0),
          (0.5, 0, 0), (0, 0, 0)]  # fmt: skip
ANGLE = [1.0, 0.4, 0.2, 0.6, 0.3, 0.1, 0.8, 0.1, 0.7, 0.4]
DIST = [0.0, 0.0, FAR, HALF, 0.0, FAR, HALF, FAR, 0.0, FAR]  # w_near: 1 1 0 .5 1 0 .5 0 1 0


def _zrot(angles: list[float]) -> torch.Tensor:
    a = torch.tensor(angles, dtype=torch.float64)
    z = torch.zeros_like(a)
    return torch.stack([torch.cos(a / 2), z, z, torch.sin(a / 2)], -1).float()


def _ident(*shape: int) -> torch.Tensor:
    q = torch.zeros(*shape, 4)
    q[..., 0] = 1.0
    return q


def toy_inputs() -> RewardInputs:
    """World 0 outside the window, world 1 inside with the left hand grasping, world 2 inside with both."""
    g = torch.Generator().manual_seed(0)
    ig_pos, points = torch.randn(N, 7, 3, generator=g), torch.randn(N, 4, 3, generator=g)
    labels = torch.zeros(N, B, dtype=torch.int8)
    labels[0, [1, 7]] = 1
    labels[0, 2] = -1
    labels[0, [0, 8, 9]] = 1  # root and fingers are not 'other' contact bodies: ignored
    labels[2, :] = -1
    contact = torch.zeros(N, B, dtype=torch.bool)
    contact[0, [1, 2]] = True
    obj_vel = torch.zeros(N, 2, 6)
    obj_vel[:, 0, 0] = 0.1
    obj_vel[:, 0, 5] = 0.2
    force = torch.zeros(N, B, 3)
    force[:, 0] = torch.tensor([0.0, 0.0, 500.0])
    force[:, 2] = torch.tensor([10.0, -20.0, 0.0])
    return RewardInputs(
        body_pos=torch.tensor(OFFSET, dtype=torch.float32).expand(N, B, 3).clone(),
        body_quat=_zrot(ANGLE).expand(N, B, 4).clone(),
        ref_body_pos=torch.zeros(N, B, 3),
        ref_body_quat=_ident(N, B),
        ref_near_dist=torch.tensor(DIST).expand(N, B).clone(),
        obj_pos=torch.tensor([[1.1, 0.2, 0.5], [0.0, 1.0, 0.3]]).expand(N, 2, 3).clone(),
        obj_quat=_zrot([0.6, 0.0]).expand(N, 2, 4).clone(),
        ref_obj_pos=torch.tensor([[1.0, 0.0, 0.5], [0.0, 1.0, 0.0]]).expand(N, 2, 3).clone(),
        ref_obj_quat=_ident(N, 2),
        ig_pos=ig_pos,
        ref_ig_pos=ig_pos.clone(),
        points=points,
        ref_points=points.clone(),
        contact_obj=contact,
        ref_labels=labels,
        ref_hand=torch.tensor([[True, True], [True, False], [False, False]]),
        sim_hand=torch.tensor([[True, False], [False, True], [False, False]]),
        joint_vel=torch.tensor([0.1, 0.2, -0.2]).expand(N, 3).clone(),
        prev_joint_vel=torch.zeros(N, 3),
        obj_vel=obj_vel,
        prev_obj_vel=torch.zeros(N, 2, 6),
        contact_force=force,
        in_window=torch.tensor([False, True, True]),
        grasp_hands=torch.tensor([[True, False], [True, False], [True, True]]),
        step=torch.tensor([5, 1, 2]),
        dt=1.0 / 30.0,
    )


def _close(got: torch.Tensor, expected: list[float]) -> None:
    assert got.shape == (len(expected),)
    assert np.allclose(got.numpy(), expected, rtol=1e-5, atol=1e-6), (got.tolist(), expected)


def test_body_sets_from_roles() -> None:
    assert SETS.body.tolist() == [1, 2, 3, 5, 6]
    assert SETS.key.tolist() == [1, 2, 3, 4, 5, 6, 7] and SETS.contact_other.tolist() == SETS.key.tolist()
    assert SETS.wrists.tolist() == [4, 7] and SETS.left_hand.tolist() == [4, 8]
    assert SETS.body.dtype == torch.long


@pytest.mark.parametrize(("mjcf", "nb", "k"), [(smplx_like_mjcf, 19, 21), (parahome_like_mjcf, 20, 22)])
def test_body_sets_of_the_humanoids(mjcf, nb: int, k: int) -> None:
    skel = load_skeleton(mjcf())
    sets = BodySets.from_roles(compute_roles(skel, detect_profile(skel)))
    assert sets.body.numel() == nb and sets.key.numel() == k
    assert not set(sets.wrists.tolist()) & set(sets.body.tolist())
    assert set(sets.left_arm.tolist()) | set(sets.right_arm.tolist()) <= set(sets.body.tolist())
    assert not set(sets.fingers.tolist()) & set(sets.key.tolist())


def test_wristmimic_body_and_wrist_factors() -> None:
    reward, info = compute_reward(toy_inputs(), SETS, variant_config("wristmimic"))
    # body set [1, 2, 3, 5, 6]: w_near |dp|^2 = [.01, 0, .02, 0, .045], (1 - w_near) angle = [0, .2, .3, .1, .4]
    # world 0 (outside): E_p = .075/5, E_r = 1.0/5, lambdas 30 / 2.5
    # world 1 (inside, left grasping, bodies 2 and 3 off): E_p = .055/3, E_r = .5/3, lambdas 10 / 1
    # world 2 (inside, both grasping, only body 1 left): E_p = .01, E_r = 0
    _close(info["error/body_pos"], [0.015, 0.055 / 3, 0.01])
    _close(info["error/body_rot"], [0.2, 0.5 / 3, 0.0])
    _close(info["reward/body_pos"], [math.exp(-0.45), math.exp(-10 * 0.055 / 3), math.exp(-0.1)])
    _close(info["reward/body_rot"], [math.exp(-0.5), math.exp(-0.5 / 3), 1.0])
    # wrists 4 and 7: |dp|^2 = .01, .04 -> .025; angles .3, .1 -> .2; lambdas 10 / 1 in every world
    _close(info["error/wrist_pos"], [0.025] * 3)
    _close(info["reward/wrist_pos"], [math.exp(-0.25)] * 3)
    _close(info["reward/wrist_rot"], [math.exp(-0.2)] * 3)
    assert "reward/finger_pos" not in info and "reward/finger_rot" not in info
    assert reward.shape == (N,)


def test_reward_form_mean_averages_the_same_factors() -> None:
    cfg = variant_config("wristmimic")
    product, info = compute_reward(toy_inputs(), SETS, cfg)
    mean, info_mean = compute_reward(toy_inputs(), SETS, replace(cfg, reward_form="mean"))
    factors = torch.stack([info[f"reward/{n}"] for n in factor_names(cfg)], -1)
    _close(product, factors.prod(-1).tolist())
    _close(mean, factors.mean(-1).tolist())
    assert info_mean.keys() == info.keys()
    assert torch.all(mean >= product) and not torch.allclose(mean, product)  # partial credit: never below the product
    with pytest.raises(ValueError, match="reward_form"):
        check_env_config(replace(cfg, reward_form="sum"))


def test_object_ig_contact_and_energy_factors() -> None:
    _, info = compute_reward(toy_inputs(), SETS, variant_config("wristmimic"))
    # objects: dp = (.1, .2, 0), (0, 0, .3) -> (.01 + .04 + .09)/6; angles .6, 0 -> .3
    _close(info["reward/obj_pos"], [math.exp(-5 * 0.14 / 6)] * 3)
    _close(info["reward/obj_rot"], [math.exp(-0.1 * 0.3)] * 3)
    _close(info["reward/ig"], [1.0] * 3)  # ig == ref_ig
    # hand: world 0 right hand lost, world 1 left hand lost, world 2 no reference contact
    half = 0.5 * (1 + math.exp(-10))
    _close(info["reward/contact_hand"], [half, half, 1.0])
    _close(info["error/contact_hand"], [1.0, 1.0, 0.0])
    # other, world 0: labels on key bodies 1 (+1, touching), 2 (-1, touching), 7 (+1, not) -> 2/3 wrong
    _close(info["error/contact_other"], [2 / 3, 0.0, 0.0])
    _close(info["reward/contact_other"], [math.exp(-5 * 2 / 3), 1.0, 1.0])
    # energy (world 1 has step 1 < 2 -> factor 1): joint acc 30 * (.1, .2, -.2) -> mean(9, 36, 36) = 27
    _close(info["reward/joint_energy"], [math.exp(-2e-5 * 27), 1.0, math.exp(-2e-5 * 27)])
    _close(info["error/joint_energy"], [27.0, 0.0, 27.0])
    # object acc: linear (3, 0, 0, 0, 0, 0) -> 9/6; angular (0, 0, 6, 0, 0, 0) -> 36/6
    _close(info["reward/obj_energy_lin"], [math.exp(-2e-5 * 1.5), 1.0, math.exp(-2e-5 * 1.5)])
    _close(info["reward/obj_energy_ang"], [math.exp(-2e-5 * 6), 1.0, math.exp(-2e-5 * 6)])
    # contact forces: |500| + |10| + |-20| = 530 -> 530^2
    _close(info["reward/contact_energy"], [math.exp(-1e-9 * 530**2), 1.0, math.exp(-1e-9 * 530**2)])


PAPER_WEIGHTS = RewardWeights(root_pos=0.0, root_rot=0.0)  # the paper's reward: no root (anchor) factors


def test_reward_is_the_product_of_the_logged_factors() -> None:
    cfg = variant_config("wristmimic", weights=PAPER_WEIGHTS)
    reward, info = compute_reward(toy_inputs(), SETS, cfg)
    names = factor_names(cfg)
    assert {k for k in info if k.startswith("reward/")} == {f"reward/{n}" for n in names}
    assert {k for k in info if k.startswith("error/")} == {f"error/{n}" for n in names}
    prod = torch.stack([info[f"reward/{n}"] for n in names]).prod(0)
    assert torch.allclose(reward, prod)
    # world 1 by hand: body .0183/.1667, wrists .25/.2, objects, contact hand, energies all 1
    w1 = math.exp(-10 * 0.055 / 3 - 0.5 / 3 - 0.25 - 0.2 - 5 * 0.14 / 6 - 0.03) * 0.5 * (1 + math.exp(-10))
    assert reward[1].item() == pytest.approx(w1, rel=1e-5)
    for v in info.values():
        assert v.shape == (N,) and torch.isfinite(v).all()


def test_root_factors_track_the_root_body_and_are_off_at_zero_weight() -> None:
    x = toy_inputs()
    w = RewardWeights(root_pos=20.0, root_rot=2.0)
    reward, info = compute_reward(x, SETS, variant_config("wristmimic", weights=w))
    base, _ = compute_reward(x, SETS, variant_config("wristmimic", weights=PAPER_WEIGHTS))
    e_pos = (x.ref_body_pos[:, 0] - x.body_pos[:, 0]).square().sum(-1)
    e_rot = quat_angle(x.ref_body_quat[:, 0], x.body_quat[:, 0])
    torch.testing.assert_close(info["reward/root_pos"], torch.exp(-20.0 * e_pos))
    torch.testing.assert_close(info["reward/root_rot"], torch.exp(-2.0 * e_rot))
    torch.testing.assert_close(reward, base * info["reward/root_pos"] * info["reward/root_rot"])
    assert "root_pos" not in factor_names(variant_config("wristmimic", weights=PAPER_WEIGHTS))


def test_feet_factor_tracks_the_feet_bodies_unweighted() -> None:
    x = toy_inputs()
    sets = BodySets.from_roles({**ROLES, "feet": np.array([1, 8])})  # toy: spine and a finger stand in
    w = RewardWeights(root_pos=0.0, root_rot=0.0, feet_pos=100.0)
    reward, info = compute_reward(x, sets, variant_config("wristmimic", weights=w))
    base, _ = compute_reward(x, sets, variant_config("wristmimic", weights=PAPER_WEIGHTS))
    e = (x.ref_body_pos[:, [1, 8]] - x.body_pos[:, [1, 8]]).square().sum(-1).mean(-1)
    assert (e > 0).all()  # the toy offsets move both bodies: the factor is not trivially 1
    torch.testing.assert_close(info["reward/feet_pos"], torch.exp(-100.0 * e))
    torch.testing.assert_close(reward, base * info["reward/feet_pos"])
    assert "feet_pos" not in factor_names(variant_config("wristmimic", weights=PAPER_WEIGHTS))
    with pytest.raises(ValueError, match="feet"):
        compute_reward(x, SETS, variant_config("wristmimic", weights=w))  # toy SETS name no feet


def test_velocity_factors_track_root_and_body_linear_velocities() -> None:
    g = torch.Generator().manual_seed(1)
    v, v_ref = torch.randn(N, B, 3, generator=g), torch.randn(N, B, 3, generator=g)
    x = replace(toy_inputs(), body_linvel=v, ref_body_linvel=v_ref)
    w = RewardWeights(root_pos=0.0, root_rot=0.0, root_vel=2.0, body_vel=0.5)
    reward, info = compute_reward(x, SETS, variant_config("wristmimic", weights=w))
    base, _ = compute_reward(x, SETS, variant_config("wristmimic", weights=PAPER_WEIGHTS))
    # by hand: root |dv|^2 of body 0, and the mean over all B bodies
    e_root = ((v_ref[:, 0] - v[:, 0]) ** 2).sum(-1)
    e_body = ((v_ref - v) ** 2).sum(-1).mean(-1)
    assert (e_root > 0).all() and not torch.allclose(e_root, e_body)
    torch.testing.assert_close(info["reward/root_vel"], torch.exp(-2.0 * e_root))
    torch.testing.assert_close(info["reward/body_vel"], torch.exp(-0.5 * e_body))
    torch.testing.assert_close(reward, base * info["reward/root_vel"] * info["reward/body_vel"])
    # equal velocities leave the factors at 1; off at weight 0; an input without velocities is an error
    same, _ = compute_reward(replace(x, ref_body_linvel=v), SETS, variant_config("wristmimic", weights=w))
    torch.testing.assert_close(same, base)
    assert "root_vel" not in factor_names(variant_config("wristmimic", weights=PAPER_WEIGHTS))
    with pytest.raises(ValueError, match="root_vel"):
        compute_reward(toy_inputs(), SETS, variant_config("wristmimic", weights=w))


def test_feet_contact_factor_is_the_share_of_feet_off_the_reference_schedule() -> None:
    sim = torch.tensor([[True, True, False, False], [True, False, True, False], [False, False, False, False]])
    ref = torch.tensor([[True, True, False, False], [False, False, True, True], [True, True, True, False]])
    x = replace(toy_inputs(), feet_contact=sim, ref_feet_contact=ref)
    w = RewardWeights(root_pos=0.0, root_rot=0.0, feet_contact=2.0)
    reward, info = compute_reward(x, SETS, variant_config("wristmimic", weights=w))
    base, _ = compute_reward(x, SETS, variant_config("wristmimic", weights=PAPER_WEIGHTS))
    _close(info["error/feet_contact"], [0.0, 0.5, 0.75])  # 0, 2 and 3 of 4 feet differ
    torch.testing.assert_close(info["reward/feet_contact"], torch.exp(-2.0 * info["error/feet_contact"]))
    torch.testing.assert_close(reward, base * info["reward/feet_contact"])
    assert "feet_contact" not in factor_names(variant_config("wristmimic", weights=PAPER_WEIGHTS))
    with pytest.raises(ValueError, match="feet_contact"):
        compute_reward(toy_inputs(), SETS, variant_config("wristmimic", weights=w))


def test_fingertip_factor_is_the_mean_tip_distance_of_the_hands_in_reference_contact() -> None:
    x = replace(
        toy_inputs(),
        tip_sq_dists=torch.tensor([[0.01, 0.04], [0.09, 0.0], [0.25, 0.25]])[:, :, None].expand(N, 2, 2).clone(),
    )
    x.tip_sq_dists[:, :, 1] *= 4.0  # second tip twice as far: mean distance 1.5 x the first's
    w = RewardWeights(fingertip=20.0)
    reward, info = compute_reward(x, SETS, variant_config("wristmimic", weights=w))
    base, _ = compute_reward(x, SETS, variant_config("wristmimic", weights=PAPER_WEIGHTS))
    # ref_hand: world 0 both hands (0.1 and 0.2 m -> 0.15 + 0.3), world 1 left only (0.3 m -> 0.45), world 2 none
    _close(info["error/fingertip"], [0.45, 0.45, 0.0])
    torch.testing.assert_close(info["reward/fingertip"], torch.exp(-20.0 * info["error/fingertip"]))
    torch.testing.assert_close(reward, base * info["reward/fingertip"])
    assert "fingertip" not in factor_names(variant_config("wristmimic", weights=PAPER_WEIGHTS))
    with pytest.raises(ValueError, match="fingertip"):
        compute_reward(toy_inputs(), SETS, variant_config("wristmimic", weights=w))


def test_drive_factor_is_the_humanoids_push_against_the_reference_motion_over_the_weight() -> None:
    """Every body touching the object counts, bodies not touching it do not; only the component against the
    reference object's velocity costs; a reference object slower than 5 cm/s costs nothing."""
    contact = torch.zeros(N, B, dtype=torch.bool)
    contact[:, [4, 8, 9, 3]] = True  # left wrist, both fingers, the left elbow
    contact[1, 8] = False
    force = torch.zeros(N, B, 3)
    force[:, 4] = torch.tensor([-30.0, 5.0, 0.0])  # left wrist: 30 N against +x, 5 N sideways
    force[:, 8] = torch.tensor([-10.0, 0.0, 0.0])  # left finger (not touching in world 1)
    force[:, 9] = torch.tensor([15.0, 0.0, 0.0])  # right finger along the motion: offsets the push
    force[:, 3] = torch.tensor([-20.0, 0.0, 0.0])  # the elbow pushes too
    force[:, 7] = torch.tensor([-100.0, 0.0, 0.0])  # right wrist, not touching: ignored
    vel = torch.tensor([[[0.2, 0.0, 0.0]], [[0.2, 0.0, 0.0]], [[0.04, 0.0, 0.0]]])
    x = replace(
        toy_inputs(), contact_obj=contact, contact_force=force, ref_obj_linvel=vel, obj_weight=torch.tensor([50.0])
    )
    w = RewardWeights(drive=2.0)
    reward, info = compute_reward(x, SETS, variant_config("wristmimic", weights=w))
    base, _ = compute_reward(x, SETS, variant_config("wristmimic", weights=PAPER_WEIGHTS))
    _close(info["error/drive"], [45.0 / 50.0, 35.0 / 50.0, 0.0])  # world 0: -30 - 10 + 15 - 20; world 1: -30 + 15 - 20
    torch.testing.assert_close(info["reward/drive"], torch.exp(-2.0 * info["error/drive"]))
    torch.testing.assert_close(reward, base * info["reward/drive"])
    pull = replace(x, contact_force=-force)  # the same forces reversed: along the motion, free
    _close(compute_reward(pull, SETS, variant_config("wristmimic", weights=w))[1]["error/drive"], [0.0, 0.0, 0.0])
    assert "drive" not in factor_names(variant_config("wristmimic", weights=PAPER_WEIGHTS))
    with pytest.raises(ValueError, match="drive"):
        compute_reward(toy_inputs(), SETS, variant_config("wristmimic", weights=w))
    with pytest.raises(ValueError, match="one dynamic object"):
        compute_reward(replace(x, ref_obj_linvel=vel.expand(N, 2, 3)), SETS, variant_config("wristmimic", weights=w))


def test_window_modulation_zeroes_exactly_the_grasping_arm() -> None:
    x = toy_inputs()
    x.in_window = torch.tensor([True, True, False])
    x.grasp_hands = torch.tensor([[True, False], [False, True], [True, True]])
    m = arm_weights(x, SETS.body, SETS, variant_config("wristmimic"))  # columns: bodies 1, 2, 3, 5, 6
    assert m.tolist() == [[1, 0, 0, 1, 1], [1, 1, 1, 0, 0], [1, 1, 1, 1, 1]]
    off = arm_weights(x, SETS.body, SETS, variant_config("reset-only"))
    assert (off == 1).all()


def test_without_modulation_lambdas_stay_high_inside_the_window() -> None:
    _, info = compute_reward(toy_inputs(), SETS, variant_config("reset-only"))
    _close(info["reward/body_pos"], [math.exp(-0.45)] * 3)
    _close(info["reward/body_rot"], [math.exp(-0.5)] * 3)
    assert "reward/wrist_pos" in info


@pytest.mark.parametrize("variant", ["decoupled", "intermimic"])
def test_decoupled_and_intermimic_fold_wrists_into_the_body_terms(variant: str) -> None:
    _, info = compute_reward(toy_inputs(), SETS, variant_config(variant))
    assert "reward/wrist_pos" not in info and "reward/wrist_rot" not in info
    # bodies [1, 2, 3, 5, 6, 4, 7]: w |dp|^2 adds .01 (wrist 4, w 1) + 0 (wrist 7, w 0) -> .085/7
    # (1 - w) angle adds 0 + .1 -> 1.1/7; no modulation: lambdas 30 / 2.5 in every world
    _close(info["error/body_pos"], [0.085 / 7] * 3)
    _close(info["reward/body_pos"], [math.exp(-30 * 0.085 / 7)] * 3)
    _close(info["reward/body_rot"], [math.exp(-2.5 * 1.1 / 7)] * 3)
    assert ("reward/finger_pos" in info) == (variant == "intermimic")


@pytest.mark.parametrize("variant", ["finger-guidance", "intermimic"])
def test_finger_terms_only_with_finger_targets(variant: str) -> None:
    cfg = variant_config(variant)
    assert cfg.finger_targets
    _, info = compute_reward(toy_inputs(), SETS, cfg)
    # fingers 8 (w 1, |dp|^2 .25, angle .7 ignored) and 9 (w 0, dp 0, angle .4): E_fp = .125, E_fr = .2
    _close(info["reward/finger_pos"], [math.exp(-30 * 0.125)] * 3)
    _close(info["reward/finger_rot"], [math.exp(-2.5 * 0.2)] * 3)
    _, plain = compute_reward(toy_inputs(), SETS, replace(cfg, finger_targets=False))
    assert not any("finger" in k for k in plain)


def test_weights_come_from_config() -> None:
    cfg = variant_config("wristmimic")
    cfg = replace(cfg, weights=replace(cfg.weights, p=60.0, gwp=0.0))
    _, info = compute_reward(toy_inputs(), SETS, cfg)
    _close(info["reward/body_pos"][:1], [math.exp(-0.9)])
    _close(info["reward/wrist_pos"], [1.0] * 3)


def test_ig_small_case_by_hand() -> None:
    x = toy_inputs()
    # one node at the origin; ig = node - point
    x.ig_pos, x.ref_ig_pos = torch.zeros(1, 1, 3), torch.zeros(1, 1, 3)
    x.points = -torch.tensor([[1.0, 0, 0], [0, 0.05, 0]]).reshape(1, 2, 3)
    x.ref_points = -torch.tensor([[0.5, 0, 0], [0, 0.05, 0]]).reshape(1, 2, 3)
    x.body_pos = x.body_pos[:1]
    # w1 = [1, 1/max(.0025, .01)] = [1, 100] / 101; w2 = [4, 100] / 104; only pair 0 differs (.25)
    expected = 0.5 * 0.25 * (1 / 101 + 4 / 104)
    assert error_ig(x).item() == pytest.approx(expected, rel=1e-5)


def test_ig_matches_a_brute_force_loop() -> None:
    g = torch.Generator().manual_seed(3)
    x = toy_inputs()
    n, k, p = 2, 3, 5
    x.ig_pos = torch.randn(n, k, 3, generator=g) * 0.5
    x.points = torch.randn(n, p, 3, generator=g) * 0.5
    x.points[0, 2] = x.ig_pos[0, 1] - torch.tensor([0.01, 0.0, 0.02])  # a pair below the 0.1 m clamp
    x.ref_ig_pos = x.ig_pos + torch.randn(n, k, 3, generator=g) * 0.1
    x.ref_points = x.points + torch.randn(n, p, 3, generator=g) * 0.1
    x.body_pos = x.body_pos[:n]
    ig = (x.ig_pos[:, :, None] - x.points[:, None]).double().numpy()
    ref = (x.ref_ig_pos[:, :, None] - x.ref_points[:, None]).double().numpy()
    expected = []
    for i in range(n):
        w1 = np.zeros((k, p))
        w2 = np.zeros((k, p))
        for a in range(k):
            for b in range(p):
                w1[a, b] = 1.0 / max(float(ig[i, a, b] @ ig[i, a, b]), 0.01)
                w2[a, b] = 1.0 / max(float(ref[i, a, b] @ ref[i, a, b]), 0.01)
        w1 /= w1.sum()
        w2 /= w2.sum()
        e = 0.0
        for a in range(k):
            for b in range(p):
                d = ig[i, a, b] - ref[i, a, b]
                e += 0.5 * float(d @ d) * (w1[a, b] + w2[a, b])
        expected.append(e)
    assert np.allclose(error_ig(x).numpy(), expected, rtol=1e-5)


def test_no_objects_gives_finite_factors() -> None:
    x = toy_inputs()
    x.obj_pos = x.ref_obj_pos = x.obj_vel = x.prev_obj_vel = torch.zeros(N, 0, 3)
    x.obj_vel = x.prev_obj_vel = torch.zeros(N, 0, 6)
    x.obj_quat = x.ref_obj_quat = torch.zeros(N, 0, 4)
    x.ig = x.ref_ig = torch.zeros(N, 7, 0, 3)
    reward, info = compute_reward(x, SETS, EnvConfig())
    assert torch.isfinite(reward).all()
    _close(info["reward/obj_pos"], [1.0] * 3)
    _close(info["reward/ig"], [1.0] * 3)
