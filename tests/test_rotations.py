"""Rotation conventions at the boundaries, checked against SciPy and MuJoCo."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from wristmimic import rotations as R


@pytest.fixture
def rots() -> Rotation:
    return Rotation.random(500, random_state=3)


def test_xyzw_wxyz_round_trip(rots: Rotation) -> None:
    xyzw = rots.as_quat()
    wxyz = R.xyzw_to_wxyz(xyzw)
    assert np.allclose(wxyz[:, 0], xyzw[:, 3]) and np.allclose(wxyz[:, 1:], xyzw[:, :3])
    assert np.allclose(R.wxyz_to_xyzw(wxyz), xyzw)


def test_matrix_and_rotation_vector_match_scipy(rots: Rotation) -> None:
    q = R.xyzw_to_wxyz(rots.as_quat())
    assert np.allclose(R.quat_to_matrix(q), rots.as_matrix(), atol=1e-12)
    assert np.allclose(R.quat_canonical(R.matrix_to_quat(rots.as_matrix())), R.quat_canonical(q), atol=1e-12)
    assert np.allclose(R.quat_to_rotvec(q), rots.as_rotvec(), atol=1e-12)
    assert np.allclose(R.quat_angle(R.rotvec_to_quat(rots.as_rotvec()), q), 0, atol=1e-7)
    assert np.allclose(R.quat_rotate(q, [0.3, -1, 2]), rots.apply([0.3, -1, 2]))


def test_quat_mul_composes_like_matrices(rots: Rotation) -> None:
    a, b = rots[:250], rots[250:]
    qa, qb = R.xyzw_to_wxyz(a.as_quat()), R.xyzw_to_wxyz(b.as_quat())
    assert np.allclose(R.quat_to_matrix(R.quat_mul(qa, qb)), (a * b).as_matrix(), atol=1e-12)


def test_euler_xyz_is_what_three_mujoco_hinges_produce(rots: Rotation) -> None:
    """Intrinsic XYZ Euler angles fed to hinges x, y, z give back the rotation (MuJoCo FK)."""
    xml = """<mujoco><worldbody><body name="a"><joint type="hinge" axis="1 0 0"/>
             <joint type="hinge" axis="0 1 0"/><joint type="hinge" axis="0 0 1"/>
             <geom size="0.1"/></body></worldbody></mujoco>"""
    m = mujoco.MjModel.from_xml_string(xml)
    d = mujoco.MjData(m)
    q = R.xyzw_to_wxyz(rots.as_quat()[:50])
    e = R.quat_to_euler_xyz(q)
    assert np.allclose(e, rots[:50].as_euler("XYZ"), atol=1e-9)
    for k in range(50):
        d.qpos[:] = e[k]
        mujoco.mj_kinematics(m, d)
        assert R.quat_angle(d.xquat[1], q[k]) < 1e-7


def test_euler_gimbal_lock_is_still_exact() -> None:
    e = np.array([[0.3, np.pi / 2, -0.2], [1.0, -np.pi / 2, 0.5]])
    q = R.euler_xyz_to_quat(e)
    assert np.all(R.quat_angle(R.euler_xyz_to_quat(R.quat_to_euler_xyz(q)), q) < 1e-6)


def test_sixd_is_first_two_rows(rots: Rotation) -> None:
    m = rots.as_matrix()
    d6 = R.matrix_to_sixd_rows(m)
    assert np.allclose(d6[:, :3], m[:, 0, :]) and np.allclose(d6[:, 3:], m[:, 1, :])
    noisy = d6 + 0.01 * np.random.default_rng(0).normal(size=d6.shape)
    back = R.sixd_rows_to_matrix(noisy)
    assert np.allclose(back @ np.swapaxes(back, -1, -2), np.eye(3), atol=1e-12)
    assert np.allclose(R.sixd_rows_to_matrix(d6), m, atol=1e-12)
