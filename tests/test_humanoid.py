"""Humanoid skeletons and roles, for both families (SMPL-X 52 bodies, ParaHome 61 bodies)."""

from __future__ import annotations

import numpy as np
import pytest

from wristmimic.errors import InputError
from wristmimic.humanoid.kinematics import (
    forward_kinematics,
    global_from_local,
    hinge_angles,
    joint_quat_from_hinges,
    local_from_global,
    qpos_from,
)
from wristmimic.humanoid.roles import ROLE_NAMES, compute_roles, detect_profile
from wristmimic.humanoid.skeleton import load_skeleton
from wristmimic.rotations import quat_angle

from conftest import shared_path
from synthetic import parahome_like_mjcf, smplx_like_mjcf


@pytest.mark.parametrize(
    "mjcf,family,bodies,fingers,key,contact",
    [(smplx_like_mjcf, "smplx", 52, 30, 21, 31), (parahome_like_mjcf, "parahome", 61, 38, 22, 32)],
)
def test_roles_from_tree(mjcf, family: str, bodies: int, fingers: int, key: int, contact: int) -> None:
    skel = load_skeleton(mjcf())
    prof = detect_profile(skel)
    roles = compute_roles(skel, prof)
    assert prof.family == family and skel.num_bodies == bodies and skel.num_joints == bodies - 1
    assert set(roles) == set(ROLE_NAMES)
    assert len(roles["fingers"]) == fingers and len(roles["key_bodies"]) == key
    assert len(roles["contact_bodies"]) == contact
    names = skel.body_names
    lw, rw = roles["wrists"]
    assert "Wrist" in names[lw] and ("L" in names[lw][:5] or "Left" in names[lw])
    assert [names[i] for i in roles["left_arm"]] == [names[skel.parents[skel.parents[lw]]], names[skel.parents[lw]]]
    assert set(roles["left_hand"]) == {lw, *roles["left_fingers"]}
    assert not set(roles["fingers"]) & set(roles["non_finger"])
    assert len(roles["left_fingertips"]) == 5 and len(roles["right_fingertips"]) == 5


def test_local_global_round_trip_and_fk() -> None:
    skel = load_skeleton(smplx_like_mjcf())
    rng = np.random.default_rng(0)
    angles = rng.uniform(-1.2, 1.2, (5, skel.num_joints, 3))
    root_q = np.tile([np.cos(0.3), 0, 0, np.sin(0.3)], (5, 1))
    jq = joint_quat_from_hinges(angles)
    g = global_from_local(skel, root_q, jq)
    fk = forward_kinematics(skel.model, qpos_from(skel, np.zeros((5, 3)), root_q, angles))
    assert quat_angle(fk.body_quat, g).max() < 1e-6
    assert quat_angle(local_from_global(skel, g), jq).max() < 1e-6
    assert np.abs(hinge_angles(jq) - angles).max() < 1e-6  # inside (-pi/2, pi/2) for y the decomposition is unique


def test_unsupported_joint_layout_is_rejected() -> None:
    xml = smplx_like_mjcf().replace('axis="0 1 0"', 'axis="0 0 1"', 1)
    with pytest.raises(InputError, match="joints are not three hinges x, y, z"):
        load_skeleton(xml, "bad.xml")
    with pytest.raises(InputError, match="bad.xml: mjcf: MuJoCo cannot compile it"):
        load_skeleton("<mujoco><worldbody><body>", "bad.xml")
    renamed = load_skeleton(smplx_like_mjcf().replace("L_Wrist", "LeftHandBase"))
    with pytest.raises(InputError, match="unknown humanoid family"):
        detect_profile(renamed)


@pytest.mark.shared_data
def test_shared_humanoids_have_the_expected_roles() -> None:
    om = load_skeleton(shared_path("intermimic_omomo", "omomo.xml").read_text())
    r = compute_roles(om, detect_profile(om))
    names = [om.body_names[i] for i in r["non_finger"]]
    assert len(names) == 22 and names[:1] == ["Pelvis"] and "L_Wrist" in names and "R_Thorax" in names
    for xml in sorted(shared_path("skillmimic_parahome", "humanoids").glob("*.xml")):
        ph = load_skeleton(xml.read_text())
        r = compute_roles(ph, detect_profile(ph))
        assert ph.num_bodies == 61 and len(r["fingers"]) == 38
        assert [ph.body_names[i] for i in r["right_arm"]] == ["jRightShoulder", "jRightElbow"]
