"""Terminations: thresholds at their exact boundaries, grace, reason ordering, the contact-lost counter."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
import torch

from wristmimic.env.bodies import BodySets
from wristmimic.env.config import EnvConfig, WristThresholds, variant_config
from wristmimic.env.terminations import (
    BODY_ERROR,
    CONTACT_LOST,
    FALL,
    NONE,
    OBJECT_ERROR,
    REASONS,
    WRIST,
    ContactLostCounter,
    TerminationInputs,
    check_terminations,
)
from wristmimic.env.torch_math import quat_angle, quat_mul
from wristmimic.env.window import APPROACH, GRASP, OUTSIDE, STABILIZE

# toy humanoid as in test_env_rewards: key bodies 1..7, wrists 4 and 7, fingers 8 and 9
SETS = BodySets.from_roles(
    {
        "key_bodies": np.array([1, 2, 3, 4, 5, 6, 7]),
        "wrists": np.array([4, 7]),
        "left_arm": np.array([2, 3]),
        "right_arm": np.array([5, 6]),
        "fingers": np.array([8, 9]),
        "left_hand": np.array([4, 8]),
        "right_hand": np.array([7, 9]),
    }
)
CFG = variant_config("wristmimic")
REF_WRIST_QUAT = torch.tensor([[0.9, 0.3, -0.2, 0.1], [0.5, -0.5, 0.5, 0.5]])
REF_WRIST_QUAT = REF_WRIST_QUAT / REF_WRIST_QUAT.norm(dim=-1, keepdim=True)


def healthy(n: int = 1) -> TerminationInputs:
    """n worlds exactly on the reference, standing, mid-episode, in the grasp phase, both hands grasping."""
    body = torch.rand(n, 10, 3, generator=torch.Generator().manual_seed(0))
    pts = torch.rand(n, 6, 3, generator=torch.Generator().manual_seed(1))
    wrist_pos = torch.tensor([[0.0, 0.3, 1.0], [0.0, -0.3, 1.0]]).expand(n, 2, 3).clone()
    return TerminationInputs(
        root_height=torch.full((n,), 0.9),
        body_pos=body.clone(),
        ref_body_pos=body.clone(),
        obj_points=pts.clone(),
        ref_obj_points=pts.clone(),
        contact_lost=torch.zeros(n, dtype=torch.long),
        wrist_pos=wrist_pos.clone(),
        ref_wrist_pos=wrist_pos.clone(),
        wrist_quat=REF_WRIST_QUAT.expand(n, 2, 4).clone(),
        ref_wrist_quat=REF_WRIST_QUAT.expand(n, 2, 4).clone(),
        phase=torch.full((n,), GRASP, dtype=torch.long),
        grasp_hands=torch.ones(n, 2, dtype=torch.bool),
        step=torch.full((n,), 5, dtype=torch.long),
    )


def _reasons(x: TerminationInputs, cfg: EnvConfig = CFG) -> list[int]:
    done, reason = check_terminations(x, SETS, cfg)
    assert done.dtype == torch.bool and reason.dtype == torch.long
    assert torch.equal(done, reason != NONE)
    return reason.tolist()


def _rotated(angle: float, axis: tuple[float, float, float] = (0.3, -0.8, 0.5)) -> torch.Tensor:
    """(2, 4) reference wrist orientations each composed with a rotation of ``angle`` about ``axis``."""
    a = torch.tensor(axis, dtype=torch.float64)
    a = a / a.norm()
    dq = torch.cat([torch.tensor([math.cos(angle / 2)], dtype=torch.float64), a * math.sin(angle / 2)]).float()
    return quat_mul(REF_WRIST_QUAT, dq.expand(2, 4))


def test_healthy_state_does_not_terminate() -> None:
    assert _reasons(healthy(3)) == [NONE] * 3
    assert REASONS[FALL] == "fall" and REASONS[WRIST] == "wrist" and len(REASONS) == 6


def test_fall_is_strict_and_after_grace() -> None:
    x = healthy(4)
    x.root_height = torch.tensor([0.3, 0.29, 0.29, 0.29])
    x.step = torch.tensor([5, 5, 1, 2])
    assert _reasons(x) == [NONE, FALL, NONE, FALL]


def test_body_error_uses_the_mean_over_key_bodies() -> None:
    x = healthy(4)
    x.body_pos[0, 1:8, 0] += 0.5  # mean exactly 0.5 -> not above
    x.body_pos[1, 1:8, 2] += 0.51
    x.body_pos[2, [0, 8, 9]] += 10.0  # root and fingers are not key bodies
    x.body_pos[3, 1, 0] += 0.51 * 7  # one body far: the mean matters
    assert _reasons(x) == [NONE, BODY_ERROR, NONE, BODY_ERROR]


def test_object_error_uses_the_mean_point_error() -> None:
    x = healthy(3)
    x.obj_points[0, :, 1] += 0.5
    x.obj_points[1, :, 1] += 0.51
    x.obj_points[2, 0, 1] += 0.51  # mean 0.085
    assert _reasons(x) == [NONE, OBJECT_ERROR, NONE]


def test_contact_lost_after_more_than_the_frame_count() -> None:
    x = healthy(3)
    x.contact_lost = torch.tensor([10, 11, 11])
    x.step = torch.tensor([50, 50, 1])
    assert _reasons(x) == [NONE, CONTACT_LOST, NONE]


@pytest.mark.parametrize("hand", [0, 1])
@pytest.mark.parametrize("ph", [APPROACH, GRASP, STABILIZE])
def test_wrist_position_threshold_boundary(ph: int, hand: int) -> None:
    thr = {APPROACH: CFG.wrist.approach_pos, GRASP: CFG.wrist.grasp_pos, STABILIZE: CFG.wrist.stabilize_pos}[ph]
    x = healthy(3)
    x.phase[:] = ph
    x.wrist_pos[0, hand, 0] = thr  # error exactly the threshold (reference x is 0)
    x.wrist_pos[1, hand, 0] = thr + 1e-4
    x.wrist_pos[2, hand, 0] = -(thr + 1e-4)
    assert torch.linalg.vector_norm(x.wrist_pos[0, hand] - x.ref_wrist_pos[0, hand]).item() == np.float32(thr)
    assert _reasons(x) == [NONE, WRIST, WRIST]


@pytest.mark.parametrize("hand", [0, 1])
@pytest.mark.parametrize("ph", [APPROACH, GRASP, STABILIZE])
def test_wrist_rotation_threshold_boundary(ph: int, hand: int) -> None:
    names = {APPROACH: "approach_rot", GRASP: "grasp_rot", STABILIZE: "stabilize_rot"}
    thr = getattr(CFG.wrist, names[ph])
    x = healthy(3)
    x.phase[:] = ph
    x.wrist_quat[0, hand] = _rotated(thr)[hand]
    x.wrist_quat[1, hand] = _rotated(thr + 1e-4)[hand]
    x.wrist_quat[2, hand] = _rotated(thr - 1e-4)[hand]
    assert _reasons(x) == [NONE, WRIST, NONE]
    # exactly at the threshold: set it to the float32 error the termination itself measures
    err = quat_angle(x.ref_wrist_quat[0, hand], x.wrist_quat[0, hand]).item()
    assert err == pytest.approx(thr, abs=1e-6)
    exact = replace(CFG, wrist=replace(CFG.wrist, **{names[ph]: err}))
    assert _reasons(x, exact)[0] == NONE
    above = replace(CFG, wrist=replace(CFG.wrist, **{names[ph]: err - 1e-4}))
    assert _reasons(x, above)[0] == WRIST


def test_tight_thresholds_only_in_the_grasp_phase() -> None:
    x = healthy(4)
    x.phase = torch.tensor([APPROACH, GRASP, STABILIZE, OUTSIDE])
    x.wrist_pos[:, 0, 0] = 0.1  # between 7 cm and 15 cm
    assert _reasons(x) == [NONE, WRIST, NONE, NONE]


def test_wrist_never_for_non_grasping_hand_outside_or_without_wrist_resets() -> None:
    x = healthy(4)
    x.wrist_pos[:, 1, 0] = 1.0  # right wrist 1 m off
    x.wrist_quat[:, 1] = _rotated(2.0)[1]
    x.grasp_hands = torch.tensor([[True, False], [False, False], [True, True], [False, True]])
    x.phase = torch.tensor([GRASP, GRASP, OUTSIDE, GRASP])
    assert _reasons(x) == [NONE, NONE, NONE, WRIST]
    for variant in ("decoupled", "reward-modulation-only", "intermimic"):
        assert _reasons(x, variant_config(variant)) == [NONE] * 4
    assert _reasons(x, variant_config("reset-only")) == [NONE, NONE, NONE, WRIST]


def test_wrist_rule_ignores_grace_but_not_step_zero() -> None:
    x = healthy(3)
    x.wrist_pos[:, 0, 0] = 0.2
    x.step = torch.tensor([0, 1, 2])
    assert CFG.termination.grace_frames == 1
    assert _reasons(x) == [NONE, WRIST, WRIST]


def test_first_reason_wins() -> None:
    x = healthy(5)
    x.root_height[0] = 0.1  # fall
    x.body_pos[:2, 1:8] += 1.0  # body error
    x.obj_points[:3] += 1.0  # object error
    x.contact_lost[:4] = 20  # contact lost
    x.wrist_pos[:, 0, 0] = 0.5  # wrist
    assert _reasons(x) == [FALL, BODY_ERROR, OBJECT_ERROR, CONTACT_LOST, WRIST]
    assert _reasons(x, replace(CFG, wrist_resets=False)) == [FALL, BODY_ERROR, OBJECT_ERROR, CONTACT_LOST, NONE]


def test_thresholds_come_from_config() -> None:
    x = healthy(1)
    x.wrist_pos[0, 0, 0] = 0.05
    assert _reasons(x) == [NONE]
    tight = replace(CFG, wrist=WristThresholds(grasp_pos=0.035, grasp_rot=0.1))
    assert _reasons(x, tight) == [WRIST]
    x.root_height[0] = 0.5
    assert _reasons(x, replace(CFG, termination=replace(CFG.termination, fall_height=0.6))) == [FALL]


def test_contact_lost_counter_counts_and_resets_per_world() -> None:
    c = ContactLostCounter(3)
    ref = torch.tensor([[True, False], [True, True], [False, False]])
    lost_left = torch.tensor([[False, False], [False, True], [True, True]])
    assert c.update(ref, lost_left).tolist() == [1, 1, 0]
    assert c.update(ref, lost_left).tolist() == [2, 2, 0]
    # world 1: the left hand regains contact, the right hand loses it: max over hands of the run lengths
    lost_right = torch.tensor([[False, False], [True, False], [False, False]])
    assert c.update(ref, lost_right).tolist() == [3, 1, 0]
    c.reset(torch.tensor([0]))  # world 0 restarts, world 1 keeps its run
    assert c.update(ref, lost_right).tolist() == [1, 2, 0]
    assert c.counts.tolist() == [[1, 0], [0, 2], [0, 0]]
    # the reference hand leaving contact ends the run
    assert c.update(torch.zeros(3, 2, dtype=torch.bool), lost_left).tolist() == [0, 0, 0]
