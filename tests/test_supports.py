"""Static supports inferred from where a crafted box object rests."""

from __future__ import annotations

import json

import numpy as np
import pytest
import trimesh

from wristmimic.convert import supports as S
from wristmimic.rotations import euler_xyz_to_quat, quat_rotate

from conftest import SHARED_DATA

HALF = np.array([0.1, 0.05, 0.15])  # object box half sizes
MESH = trimesh.creation.box(extents=2 * HALF)
V, F = np.asarray(MESH.vertices), np.asarray(MESH.faces)
IDENT = np.array([1.0, 0.0, 0.0, 0.0])
P = S.SupportParams()


def _hold(pos, quat, n):
    return np.tile(pos, (n, 1)), np.tile(quat, (n, 1))


def _move(p0, p1, n):
    """n frames strictly between p0 and p1 (a carried object)."""
    s = np.linspace(0.0, 1.0, n + 2)[1:-1, None]
    return p0 + s * (p1 - p0)


def _scenario():
    """Rest at 0.8 m (0-19), carry (20-49), rest yawed at 0.95 m elsewhere (50-69), carry (70-89), floor (90-109)."""
    yaw = euler_xyz_to_quat(np.array([0.0, 0.0, np.pi / 6]))
    a = np.array([0.0, 0.0, 0.8 + HALF[2]])
    b = np.array([1.0, 0.5, 0.95 + HALF[2]])
    c = np.array([2.0, -0.5, HALF[2]])
    pa, qa = _hold(a, IDENT, 20)
    pb, qb = _hold(b, yaw, 20)
    pc, qc = _hold(c, IDENT, 20)
    pos = np.concatenate([pa, _move(a, b, 30), pb, _move(b, c, 20), pc])
    quat = np.concatenate([qa, np.tile(IDENT, (30, 1)), qb, np.tile(IDENT, (20, 1)), qc])
    touched = np.zeros(len(pos), dtype=bool)
    touched[20:50] = touched[70:90] = True
    return pos, quat, touched, yaw


def _footprint(pos, quat):
    w = quat_rotate(quat, V) + pos
    bot = w[:, 2] <= w[:, 2].min() + 1e-9
    return w[bot, :2].min(0), w[bot, :2].max(0)


def test_two_tables_and_the_floor():
    pos, quat, touched, yaw = _scenario()
    iv = S.resting_intervals(pos, quat, touched, P)
    # a frame next to a moving one is not still (central differences)
    assert iv == [(0, 18), (51, 68), (91, 109)]
    sup = S.infer_supports(V, F, pos, quat, touched, P)
    assert len(sup) == 2  # the floor interval yields none
    s0, s1 = sup
    assert s0.top_z == pytest.approx(0.8, abs=1e-3) and s1.top_z == pytest.approx(0.95, abs=1e-3)
    assert s0.intervals == [iv[0]] and s1.intervals == [iv[1]]
    for s, (p, q) in ((s0, (pos[0], IDENT)), (s1, (pos[60], yaw))):
        assert s.center[2] + s.half_extents[2] == pytest.approx(s.top_z, abs=1e-9)  # top at the object's bottom
        assert s.center[2] - s.half_extents[2] == pytest.approx(0.0, abs=1e-9)  # reaches the floor
        lo, hi = _footprint(p, q)
        np.testing.assert_allclose(s.center[:2] - s.half_extents[:2], lo - P.margin_m, atol=1e-6)
        np.testing.assert_allclose(s.center[:2] + s.half_extents[:2], hi + P.margin_m, atol=1e-6)
    # the yawed footprint is wider than the unrotated one
    assert s1.half_extents[0] > s0.half_extents[0] + 0.01


def test_still_but_touched_yields_nothing():
    pos, quat = _hold(np.array([0.0, 0.0, 0.8 + HALF[2]]), IDENT, 30)
    touched = np.ones(30, dtype=bool)
    assert S.resting_intervals(pos, quat, touched, P) == []
    assert S.infer_supports(V, F, pos, quat, touched, P) == []
    touched[12:14] = False  # two untouched frames (label flicker while held): still nothing
    assert S.infer_supports(V, F, pos, quat, touched, P) == []
    touched[10:] = False  # untouched from frame 10: one support
    strict = S.SupportParams(touched_rest=False)
    (s,) = S.infer_supports(V, F, pos, quat, touched, strict)
    assert s.intervals == [(10, 29)]
    (s,) = S.infer_supports(V, F, pos, quat, touched, P)  # the still run rests whole, touched frames included
    assert s.intervals == [(0, 29)]


def test_grasped_on_its_support_then_lifted():
    """ParaHome's pot: untouched for 3 frames, grasped while it still sits (frames 3-19), then lifted."""
    a = np.array([0.2, 0.1, 0.97 + HALF[2]])
    pos = np.concatenate([np.tile(a, (20, 1)), a + np.arange(1, 21)[:, None] * [0.0, 0.0, 0.02]])
    quat = np.tile(IDENT, (len(pos), 1))
    touched = np.ones(len(pos), dtype=bool)
    touched[:3] = False
    (s,) = S.infer_supports(V, F, pos, quat, touched, P)
    assert s.intervals == [(0, 18)] and s.top_z == pytest.approx(0.97, abs=1e-3)
    assert S.infer_supports(V, F, pos, quat, touched, S.SupportParams(touched_rest=False)) == []


@pytest.mark.parametrize("k, expected", [(4, 0), (5, 1)])
def test_min_frames(k, expected):
    a = np.array([0.0, 0.0, 0.8 + HALF[2]])
    pos = np.concatenate([np.tile(a, (k + 1, 1)), a + np.arange(1, 21)[:, None] * [0.0, 0.03, 0.0]])
    quat = np.tile(IDENT, (len(pos), 1))
    touched = np.zeros(len(pos), dtype=bool)
    # frames 0..k-1 are still (frame k sees the move in its central difference)
    sup = S.infer_supports(V, F, pos, quat, touched, P)
    assert len(sup) == expected
    if expected:
        assert sup[0].intervals == [(0, k - 1)]


def test_rotating_in_place_is_not_resting():
    T = 30
    pos = np.tile([0.0, 0.0, 0.8 + HALF[2]], (T, 1))
    quat = euler_xyz_to_quat(np.column_stack([np.zeros(T), np.zeros(T), np.arange(T) / 30.0]))  # 1 rad/s
    assert S.resting_intervals(pos, quat, np.zeros(T, bool), P) == []
    slow = euler_xyz_to_quat(np.column_stack([np.zeros(T), np.zeros(T), np.arange(T) * 0.1 / 30.0]))
    assert S.resting_intervals(pos, slow, np.zeros(T, bool), P) == [(0, T - 1)]


def test_same_place_twice_merges():
    a = np.array([0.3, 0.2, 0.7 + HALF[2]])
    up = a + [0.0, 0.0, 0.3]
    pos = np.concatenate([np.tile(a, (20, 1)), _move(a, up, 10), _move(up, a, 10), np.tile(a, (20, 1))])
    quat = np.tile(IDENT, (len(pos), 1))
    touched = np.zeros(len(pos), dtype=bool)
    touched[20:40] = True
    sup = S.infer_supports(V, F, pos, quat, touched, P)
    assert len(sup) == 1
    assert sup[0].intervals == [(0, 18), (41, 59)]
    assert sup[0].top_z == pytest.approx(0.7, abs=1e-3)
    # a second rest 2 cm higher on the same spot still merges (lowest top kept); 5 cm higher does not
    for dz, n in ((0.02, 1), (0.05, 2)):
        pos2 = pos.copy()
        pos2[40:, 2] += dz
        pos2[20:40] = np.concatenate([_move(a, up, 10), _move(up, a + [0, 0, dz], 10)])
        sup2 = S.infer_supports(V, F, pos2, quat, touched, P)
        assert len(sup2) == n
        assert sup2[0].top_z == pytest.approx(0.7, abs=1e-3)
    # far apart at the same height: two supports
    pos3 = pos.copy()
    pos3[40:, 0] += 2.0
    pos3[20:40] = np.concatenate([_move(a, up, 10), _move(up, a + [2.0, 0, 0], 10)])
    assert len(S.infer_supports(V, F, pos3, quat, touched, P)) == 2


def test_slab_thickness():
    pos, quat = _hold(np.array([0.0, 0.0, 0.8 + HALF[2]]), IDENT, 10)
    (s,) = S.infer_supports(V, F, pos, quat, np.zeros(10, bool), S.SupportParams(thickness_m=0.05))
    assert s.half_extents[2] == pytest.approx(0.025) and s.center[2] == pytest.approx(0.8 - 0.025, abs=1e-3)


def test_box_mesh_closed_and_outward():
    s = S.InferredSupport(
        center=np.array([1.0, 2.0, 0.4]), half_extents=np.array([0.3, 0.2, 0.4]), top_z=0.8, intervals=[(0, 9)]
    )
    v, f = s.box_mesh()
    assert v.shape == (8, 3) and v.dtype == np.float64 and f.shape == (12, 3) and f.dtype == np.int32
    np.testing.assert_allclose(v.mean(0), 0.0, atol=1e-12)
    np.testing.assert_allclose(np.abs(v), np.tile(s.half_extents, (8, 1)))
    m = trimesh.Trimesh(v, f, process=False)
    assert m.is_watertight and m.is_winding_consistent
    assert m.volume == pytest.approx(8 * np.prod(s.half_extents))
    # every face normal points away from the centre
    assert np.all(np.einsum("ij,ij->i", m.face_normals, m.triangles_center) > 0)


def test_params_to_dict():
    d = S.SupportParams().to_dict()
    assert d["margin_m"] == 0.10 and d["thickness_m"] is None
    json.dumps(d)


PARAHOME = SHARED_DATA / "skillmimic_parahome"


@pytest.mark.shared_data
def test_kettle_gets_a_table():
    clip = PARAHOME / "motions" / "wristmimic" / "s110_move_kettle" / "002_s110_move_kettle.pt"
    if not clip.exists():
        pytest.skip(f"{clip} is absent")
    torch = pytest.importorskip("torch")
    from wristmimic.rotations import rotvec_to_quat

    x = torch.load(clip, weights_only=True, map_location="cpu").detach().numpy().astype(np.float64)
    mesh = trimesh.load(PARAHOME / "objects" / "kettle.obj", force="mesh", process=False)
    pos, quat = x[:, 402:405], rotvec_to_quat(x[:, 405:408])
    touched = np.zeros(len(x), dtype=bool)
    touched[25:150] = True  # the right hand holds it (geometric labels: first contact at frame 25)
    sup = S.infer_supports(mesh.vertices, mesh.faces, pos, quat, touched)
    assert len(sup) >= 1 and sup[0].intervals[0][0] == 0
    w = quat_rotate(quat[0], mesh.vertices) + pos[0]
    assert sup[0].top_z == pytest.approx(w[:, 2].min(), abs=5e-3)  # the kettle starts on it, in mid-air
    assert 0.65 < sup[0].top_z < 0.78
