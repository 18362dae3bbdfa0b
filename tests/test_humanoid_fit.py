"""Per-subject skeletons: bone offsets read back from body positions, geoms carried along, feet deepened."""

from __future__ import annotations

import numpy as np
import pytest

from wristmimic.humanoid.fit import fit_offsets, lowest_foot_height, refit_mjcf, thicken_feet
from wristmimic.humanoid.kinematics import forward_kinematics, qpos_from
from wristmimic.humanoid.skeleton import load_skeleton

from synthetic import smplx_like_mjcf


def _fk(mjcf: str, seed: int = 0, T: int = 20):
    skel = load_skeleton(mjcf)
    rng = np.random.default_rng(seed)
    angles = rng.uniform(-0.6, 0.6, (T, skel.num_joints, 3))
    root_pos = np.tile([0.0, 0.0, 1.0], (T, 1))
    root_quat = np.tile([1.0, 0.0, 0.0, 0.0], (T, 1))
    qpos = qpos_from(skel, root_pos, root_quat, angles)
    return skel, qpos, forward_kinematics(skel.model, qpos)


def test_offsets_are_read_back_and_the_refitted_humanoid_reproduces_the_positions() -> None:
    subject, generic = smplx_like_mjcf({"L_Knee": 1.2, "R_Elbow": 0.9}), smplx_like_mjcf()
    _, qpos, fk = _fk(subject)
    skel = load_skeleton(generic)
    valid = np.ones(skel.num_bodies, bool)
    valid[skel.index("L_Index2")] = False  # a body whose position is unknown keeps the generic offset
    off, spread = fit_offsets(skel, fk.body_pos, fk.body_quat, valid)
    assert spread.max() < 1e-9
    assert off[skel.index("L_Knee")] == pytest.approx([0, 0, -0.456], abs=1e-9)
    assert off[skel.index("R_Elbow")] == pytest.approx([0, -0.234, 0], abs=1e-9)
    assert np.array_equal(off[skel.index("L_Index2")], skel.rest_pos[skel.index("L_Index2")])
    refit = load_skeleton(refit_mjcf(generic, skel, off))
    again = forward_kinematics(refit.model, qpos)
    keep = valid.copy()
    keep[skel.subtree(skel.index("L_Index2"))] = False
    assert np.abs(again.body_pos[:, keep] - fk.body_pos[:, keep]).max() < 1e-9


def test_a_body_s_geoms_follow_its_one_bone() -> None:
    generic = smplx_like_mjcf()
    skel = load_skeleton(generic)
    off = skel.rest_pos.copy()
    off[skel.index("L_Knee")] = [0.03, 0.0, -0.45]  # the thigh: longer and tilted
    model = load_skeleton(refit_mjcf(generic, skel, off)).model
    hip = model.body("L_Hip").id
    g = int(np.flatnonzero(model.geom_bodyid == hip)[0])
    # the capsule ran from the hip to 0.8 of the old bone; now along 0.8 of the new one, same radius
    half = model.geom_size[g, 1]
    assert 2 * half == pytest.approx(0.8 * np.linalg.norm([0.03, 0.0, -0.45]), abs=1e-5)
    assert model.geom_pos[g] == pytest.approx(0.4 * np.array([0.03, 0.0, -0.45]), abs=1e-5)
    assert model.geom_size[g, 0] == pytest.approx(0.02)


def test_thickened_feet_reach_exactly_that_much_lower() -> None:
    mjcf = smplx_like_mjcf()
    _, qpos, _ = _fk(mjcf, T=5)
    toes = ["L_Toe", "R_Toe"]
    before = lowest_foot_height(mjcf, qpos, toes)
    after = lowest_foot_height(thicken_feet(mjcf, toes, 0.04), qpos, toes)
    assert 0.0 < before - after <= 0.04 + 1e-9  # tilted feet: less than the depth
    zero = np.zeros_like(qpos[:1])
    zero[0, 2], zero[0, 3] = 1.0, 1.0  # upright: the box's -z is the world's
    b0 = lowest_foot_height(mjcf, zero, toes)
    assert b0 - lowest_foot_height(thicken_feet(mjcf, toes, 0.04), zero, toes) == pytest.approx(0.04, abs=1e-9)
    assert thicken_feet(mjcf, toes, 0.0) == mjcf
