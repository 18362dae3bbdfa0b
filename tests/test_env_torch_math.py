"""Torch quaternion helpers against the numpy reference implementation (wristmimic.rotations)."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from wristmimic import rotations as R
from wristmimic.env import torch_math as T


@pytest.fixture
def quats() -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(7)
    a = R.quat_normalize(rng.normal(size=(200, 4)))
    b = R.quat_normalize(rng.normal(size=(200, 4)))
    return a, b


def _t(a: np.ndarray) -> torch.Tensor:
    return torch.as_tensor(a, dtype=torch.float32)


def test_mul_conj_rotate_match_numpy(quats: tuple[np.ndarray, np.ndarray]) -> None:
    a, b = quats
    v = np.random.default_rng(1).normal(size=(200, 3))
    assert np.allclose(T.quat_mul(_t(a), _t(b)).numpy(), R.quat_mul(a, b), atol=1e-6)
    assert np.allclose(T.quat_conj(_t(a)).numpy(), R.quat_conj(a), atol=1e-7)
    assert np.allclose(T.quat_rotate(_t(a), _t(v)).numpy(), R.quat_rotate(a, v), atol=1e-5)


def test_broadcasting_over_leading_axes(quats: tuple[np.ndarray, np.ndarray]) -> None:
    a, _ = quats
    q = _t(a[:5])  # (5, 4)
    v = _t(np.random.default_rng(2).normal(size=(5, 7, 3)))
    out = T.quat_rotate(q[:, None], v)
    assert out.shape == (5, 7, 3)
    assert np.allclose(out.numpy(), R.quat_rotate(a[:5, None], v.numpy().astype(np.float64)), atol=1e-5)
    assert T.quat_mul(q[:, None], _t(a[:7])[None]).shape == (5, 7, 4)


def test_angle_matches_numpy_and_range(quats: tuple[np.ndarray, np.ndarray]) -> None:
    a, b = quats
    ang = T.quat_angle(_t(a), _t(b))
    assert np.allclose(ang.numpy(), R.quat_angle(a, b), atol=1e-5)
    assert float(ang.min()) >= 0.0 and float(ang.max()) <= math.pi
    # sign-invariant, symmetric, and precise for small angles (where arccos loses float32 precision)
    assert np.allclose(T.quat_angle(_t(a), -_t(b)).numpy(), ang.numpy(), atol=1e-6)
    assert np.allclose(T.quat_angle(_t(b), _t(a)).numpy(), ang.numpy(), atol=1e-6)
    small = torch.tensor([math.cos(5e-5), math.sin(5e-5), 0.0, 0.0])
    assert T.quat_angle(torch.tensor([1.0, 0, 0, 0]), small).item() == pytest.approx(1e-4, rel=1e-4)


def test_heading_quat_matches_yaw_of_the_rotated_x_axis(quats: tuple[np.ndarray, np.ndarray]) -> None:
    a, _ = quats
    m = R.quat_to_matrix(a)
    yaw = np.arctan2(m[:, 1, 0], m[:, 0, 0])
    h = T.heading_quat(_t(a)).numpy()
    expected = np.stack([np.cos(yaw / 2), 0 * yaw, 0 * yaw, np.sin(yaw / 2)], -1)
    assert np.allclose(R.quat_canonical(h), R.quat_canonical(expected), atol=1e-5)
    assert np.allclose(T.heading_angle(_t(a)).numpy(), yaw, atol=1e-5)
    # a pure yaw is its own heading; removing the heading leaves a rotated x axis with zero y component
    yaw_only = R.quat_normalize(np.array([[math.cos(0.6), 0, 0, math.sin(0.6)]]))
    assert np.allclose(T.heading_quat(_t(yaw_only)).numpy(), yaw_only, atol=1e-6)
    rest = T.quat_mul(T.quat_conj(T.heading_quat(_t(a))), _t(a))
    x_axis = T.quat_rotate(rest, torch.tensor([1.0, 0.0, 0.0]).expand(200, 3))
    assert np.allclose(x_axis[:, 1].numpy(), 0.0, atol=1e-5)


def test_tan_norm_6d_is_first_two_columns(quats: tuple[np.ndarray, np.ndarray]) -> None:
    a, _ = quats
    m = R.quat_to_matrix(a)
    expected = np.concatenate([m[:, :, 0], m[:, :, 1]], axis=-1)  # [R00, R10, R20, R01, R11, R21]
    assert np.allclose(T.tan_norm_6d(_t(a)).numpy(), expected, atol=1e-6)
    assert T.tan_norm_6d(torch.tensor([1.0, 0, 0, 0])).tolist() == [1.0, 0.0, 0.0, 0.0, 1.0, 0.0]
    # 90 deg about z: x -> y, y -> -x
    qz = torch.tensor([math.cos(math.pi / 4), 0, 0, math.sin(math.pi / 4)])
    assert np.allclose(T.tan_norm_6d(qz).numpy(), [0, 1, 0, -1, 0, 0], atol=1e-6)
