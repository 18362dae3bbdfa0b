"""Geometric contact labels, first contact frames and the contact window (crafted scenes)."""

from __future__ import annotations

import json

import mujoco
import numpy as np
import pytest
import trimesh

from wristmimic.convert import contacts as C
from wristmimic.errors import InputError
from wristmimic.rotations import euler_xyz_to_quat, quat_rotate

from conftest import SHARED_DATA

HINGES = '<joint type="hinge" axis="1 0 0"/><joint type="hinge" axis="0 1 0"/><joint type="hinge" axis="0 0 1"/>'
ROOT_Z = 2.0  # root body's world height; children below it are placed relative to it
R = 0.04  # sphere radius of the test bodies
H = 0.25  # half size of the test cube

# body -> world position of its sphere centre (object cube of half size H at the origin)
NEAR = (H + 0.015 + R, 0.0, 0.0)  # 1.5 cm from the +x face
MID = (-(H + 0.05 + R), 0.0, 0.0)  # 5 cm from the -x face
FAR = (0.0, H + 0.30 + R, 0.0)  # 30 cm from the +y face
BOX = (0.0, -(H + 0.03 + 0.02), 0.0)  # box geom (half 2 cm) 3 cm from the -y face
CAPS = (0.0, 0.0, H + 0.06 + 0.03)  # horizontal capsule (radius 3 cm) 6 cm above the top face
FOOT = (1.5, 0.0, -1.92)  # far from the cube; 8 cm above the floor when the root is at ROOT_Z


def _rel(p):
    return f"{p[0]} {p[1]} {p[2] - ROOT_Z}"


MJCF = f"""
<mujoco>
  <worldbody>
    <geom name="floor" type="plane" size="10 10 .1"/>
    <body name="root" pos="0 0 {ROOT_Z}">
      <freejoint/>
      <geom type="sphere" size="{R}"/>
      <body name="near" pos="{_rel(NEAR)}">{HINGES}<geom type="sphere" size="{R}"/></body>
      <body name="mid" pos="{_rel(MID)}">{HINGES}<geom type="sphere" size="{R}"/></body>
      <body name="far" pos="{_rel(FAR)}">{HINGES}<geom type="sphere" size="{R}"/></body>
      <body name="box" pos="{_rel(BOX)}">{HINGES}<geom type="box" size="0.02 0.02 0.02"/></body>
      <body name="caps" pos="{_rel(CAPS)}">{HINGES}<geom type="capsule" fromto="-0.1 0 0 0.1 0 0" size="0.03"/></body>
      <body name="foot" pos="{FOOT[0]} {FOOT[1]} {FOOT[2]}">{HINGES}<geom type="sphere" size="{R}"/></body>
    </body>
  </worldbody>
</mujoco>
"""
ROOT, NEAR_B, MID_B, FAR_B, BOX_B, CAPS_B, FOOT_B = range(7)
PARAMS = C.ContactParams(object_points=20000)


@pytest.fixture(scope="module")
def model() -> mujoco.MjModel:
    return mujoco.MjModel.from_xml_string(MJCF)


def _qpos(model, T: int, root_z: float | np.ndarray = ROOT_Z) -> np.ndarray:
    q = np.zeros((T, model.nq))
    q[:, 2] = root_z
    q[:, 3] = 1.0
    return q


def _cube(half: float = H):
    m = trimesh.creation.box(extents=[2 * half] * 3)
    return np.asarray(m.vertices), np.asarray(m.faces)


def _pose(T: int, pos=(0.0, 0.0, 0.0), quat=(1.0, 0.0, 0.0, 0.0)):
    return np.tile(np.asarray(pos, float), (T, 1, 1)), np.tile(np.asarray(quat, float), (T, 1, 1))


# ---------------------------------------------------------------------------------------------------------
# geom surface points


def test_geom_surface_points_lie_on_the_surfaces():
    xml = """<mujoco><worldbody><geom type="plane" size="1 1 .1"/>
      <body><freejoint/>
        <geom type="sphere" size="0.05"/>
        <geom type="capsule" size="0.03 0.1" pos="0.3 0 0"/>
        <geom type="box" size="0.02 0.04 0.06" pos="0.6 0 0"/>
        <geom type="cylinder" size="0.03 0.05" pos="0.9 0 0"/>
        <geom type="ellipsoid" size="0.03 0.05 0.07" pos="1.2 0 0"/>
      </body></worldbody></mujoco>"""
    m = mujoco.MjModel.from_xml_string(xml)
    pts, gi = C.geom_surface_points(m, 0.01)
    assert pts.shape == (len(gi), 3) and 0 not in gi  # the world floor is skipped
    assert np.all(np.diff(gi) >= 0)
    sph, cap, box, cyl, ell = (pts[gi == g] for g in range(1, 6))
    np.testing.assert_allclose(np.linalg.norm(sph, axis=1), 0.05, atol=1e-12)
    assert len(sph) >= 4 * np.pi * 0.05**2 / 0.01**2  # about one point per spacing^2
    seg_z = np.clip(cap[:, 2], -0.1, 0.1)  # distance to the segment on the local z axis
    np.testing.assert_allclose(
        np.linalg.norm(cap - np.column_stack([0 * seg_z, 0 * seg_z, seg_z]), axis=1), 0.03, atol=1e-12
    )
    assert cap[:, 2].min() == pytest.approx(-0.13, abs=2e-3) and cap[:, 2].max() == pytest.approx(0.13, abs=2e-3)
    half = np.array([0.02, 0.04, 0.06])
    assert np.all(np.abs(box) <= half + 1e-12)
    np.testing.assert_allclose(np.max(np.abs(box) / half, axis=1), 1.0, atol=1e-12)  # on a face
    for ax in range(3):  # every face is covered
        assert np.any(np.isclose(box[:, ax], half[ax])) and np.any(np.isclose(box[:, ax], -half[ax]))
    rxy = np.linalg.norm(cyl[:, :2], axis=1)
    on_side = np.isclose(rxy, 0.03) & (np.abs(cyl[:, 2]) <= 0.05 + 1e-12)
    on_cap = np.isclose(np.abs(cyl[:, 2]), 0.05) & (rxy <= 0.03 + 1e-12)
    assert np.all(on_side | on_cap) and on_cap.sum() > 10
    np.testing.assert_allclose(np.sum((ell / [0.03, 0.05, 0.07]) ** 2, axis=1), 1.0, atol=1e-9)
    # deterministic
    pts2, gi2 = C.geom_surface_points(m, 0.01)
    np.testing.assert_array_equal(pts, pts2)
    np.testing.assert_array_equal(gi, gi2)


def test_geom_surface_points_rejects_mesh_geoms():
    xml = """<mujoco><asset><mesh name="t" vertex="0 0 0 1 0 0 0 1 0 0 0 1"/></asset><worldbody>
      <body><freejoint/><geom type="mesh" mesh="t"/></body></worldbody></mujoco>"""
    with pytest.raises(InputError, match="unsupported geom type"):
        C.geom_surface_points(mujoco.MjModel.from_xml_string(xml), 0.01)
    with pytest.raises(InputError):
        C.geom_surface_points(mujoco.MjModel.from_xml_string(MJCF), 0.0)


# ---------------------------------------------------------------------------------------------------------
# distances and labels


def test_static_distances_and_labels(model):
    T = 2
    pos, quat = _pose(T)
    d = C.body_object_distance(model, _qpos(model, T), [_cube()], pos, quat, PARAMS)
    assert d.shape == (T, 7) and d.dtype == np.float32
    np.testing.assert_allclose(d[:, NEAR_B], 0.015, atol=3e-3)
    np.testing.assert_allclose(d[:, MID_B], 0.05, atol=3e-3)
    np.testing.assert_allclose(d[:, BOX_B], 0.03, atol=3e-3)
    np.testing.assert_allclose(d[:, CAPS_B], 0.06, atol=3e-3)
    assert np.all(d[:, FAR_B] > PARAMS.no_touch_m)  # 30 cm: beyond the resolved range (inf)
    assert np.all(np.isinf(d[:, ROOT]))
    lab = C.labels_from_distance(d, PARAMS)
    assert lab.dtype == np.int8
    np.testing.assert_array_equal(lab[0], [-1, 1, 0, -1, 0, 0, -1])


def test_chunking_gives_the_same_answer(model, monkeypatch):
    T = 4
    pos, quat = _pose(T)
    pos[:, 0, 0] = np.linspace(-0.05, 0.05, T)
    full = C.body_object_distance(model, _qpos(model, T), [_cube()], pos, quat, PARAMS)
    monkeypatch.setattr(C, "_CHUNK_POINTS", 97)
    chunked = C.body_object_distance(model, _qpos(model, T), [_cube()], pos, quat, PARAMS)
    np.testing.assert_array_equal(full, chunked)


def test_moving_object_changes_labels_per_frame(model):
    pos, quat = _pose(3)
    pos[1, 0, 0] = 0.10  # cube moves toward `near` (overlaps it) and away from `mid`
    pos[2, 0, 0] = -0.12  # cube moves toward `mid`, away from `near`
    d = C.body_object_distance(model, _qpos(model, 3), [_cube()], pos, quat, PARAMS)
    lab = C.labels_from_distance(d, PARAMS)
    np.testing.assert_array_equal(lab[:, NEAR_B], [1, 1, -1])
    np.testing.assert_array_equal(lab[:, MID_B], [0, -1, 1])
    assert d[1, NEAR_B] < 0.005 and d[2, MID_B] < 0.005  # overlapping
    assert d[2, NEAR_B] == pytest.approx(0.135, abs=3e-3)
    assert d[1, MID_B] > PARAMS.no_touch_m


def test_object_rotation_is_respected():
    xml = f"""<mujoco><worldbody><body><freejoint/><geom type="sphere" size="{R}"/></body>
      </worldbody></mujoco>"""
    m = mujoco.MjModel.from_xml_string(xml)
    bar = trimesh.creation.box(extents=[1.0, 0.1, 0.1])  # long along local x
    q = np.zeros((3, m.nq))
    q[:, :3] = [0.3, 0.3, 0.05 + 0.01 + R]  # sphere bottom 1 cm above the bar's top face (z = 0.05)
    q[:, 3] = 1.0
    pos = np.zeros((3, 1, 3))
    quat = np.stack([euler_xyz_to_quat([0, 0, a]) for a in (0.0, np.pi / 4, -np.pi / 4)])[:, None]
    d = C.body_object_distance(m, q, [(bar.vertices, bar.faces)], pos, quat, PARAMS)
    assert d[1, 0] == pytest.approx(0.01, abs=3e-3)  # bar rotated +45 deg about z lies under the sphere
    assert d[0, 0] > 0.15 and d[2, 0] > 0.15
    np.testing.assert_array_equal(C.labels_from_distance(d, PARAMS)[:, 0], [-1, 1, -1])


def test_several_objects_take_the_minimum(model):
    T = 1
    pos = np.array([[[0.0, 0.0, 0.0], [0.0, 0.0, 5.0]]])  # second cube far away
    quat = np.tile([1.0, 0, 0, 0], (T, 2, 1))
    d2 = C.body_object_distance(model, _qpos(model, T), [_cube(), _cube(0.1)], pos, quat, PARAMS)
    d1 = C.body_object_distance(model, _qpos(model, T), [_cube()], pos[:, :1], quat[:, :1], PARAMS)
    np.testing.assert_array_equal(d1, d2)
    with pytest.raises(InputError):
        C.body_object_distance(model, _qpos(model, T), [_cube()], pos, quat, PARAMS)


def test_buried_body_counts_as_contact_in_a_closed_mesh():
    xml = f"""<mujoco><worldbody><body><freejoint/><geom type="sphere" size="{R}"/></body></worldbody></mujoco>"""
    m = mujoco.MjModel.from_xml_string(xml)
    q = np.zeros((2, m.nq))
    q[:, 3] = 1.0
    q[0, 2] = 0.0  # frame 0: sphere at the centre of the cube, 21 cm from every face (beyond the query bound)
    q[1, 2] = -0.12  # frame 1: 9 cm above the bottom face, inside
    pos, quat = _pose(2)
    closed = _cube()
    d = C.body_object_distance(m, q, [closed], pos, quat, PARAMS)
    np.testing.assert_array_equal(d[:, 0], [0.0, 0.0])
    v, f = closed
    top = np.all(v[f][:, :, 2] > H - 1e-9, axis=1)  # remove the top face: open mesh, no inside test
    d_open = C.body_object_distance(m, q, [(v, f[~top])], pos, quat, PARAMS)
    assert np.isinf(d_open[0, 0])
    assert d_open[1, 0] == pytest.approx(0.09, abs=3e-3)


def test_inside_test_is_not_fooled_by_a_sample_on_the_next_face():
    """Near an edge the single nearest surface sample can lie on the adjacent face, whose normal calls a point
    outside the object 'inside'. Crafted samples: a point 9.6 cm in front of the front face (x = 0.3), 2.5 mm
    below the top (z = 0.45), whose nearest sample is on the top face; it is outside, the front-face samples
    and the bounding box say so."""
    from scipy.spatial import cKDTree

    top = np.array([[0.295, y, 0.45] for y in (-0.01, 0.0, 0.01)])
    front = np.array([[0.3, y, z] for y in (-0.01, 0.0, 0.01) for z in (0.40, 0.38)])
    pts = np.vstack([top, front])
    normals = np.vstack([np.tile([0, 0, 1.0], (len(top), 1)), np.tile([1.0, 0, 0], (len(front), 1))])
    tree = cKDTree(pts)
    ot = C._ObjectTree(tree, tree, 0.0, normals, np.array([-0.3, -0.5, -0.45]), np.array([0.3, 0.5, 0.45]))
    p = np.array([[0.396, 0.0, 0.4475], [0.0, 0.0, 0.2]])  # outside near the edge; truly inside
    assert tree.query(p[0])[1] < len(top)  # the nearest sample is on the top face
    inside = C._inside(ot, p, np.array([0.096, 0.2]), np.zeros(2, dtype=np.int64), np.array([False, False]))
    assert inside.tolist() == [False, True]


def test_foot_rule(model):
    root_z = np.array([ROOT_Z, ROOT_Z + 0.5])  # frame 1: foot 58 cm above the floor
    q = _qpos(model, 2, root_z)
    low = C.body_lowest_z(model, q, np.array([FOOT_B, NEAR_B]), PARAMS)
    assert low.shape == (2, 2)
    np.testing.assert_allclose(low[:, 0], [0.08 - R, 0.58 - R], atol=1e-3)
    np.testing.assert_allclose(low[:, 1], [-R, 0.5 - R], atol=1e-3)
    pos, quat = _pose(2)
    d = C.body_object_distance(model, q, [_cube()], pos, quat, PARAMS)
    plain = C.labels_from_distance(d, PARAMS)
    assert np.all(plain[:, FOOT_B] == -1)
    feet = np.array([FOOT_B])
    lab = C.labels_from_distance(d, PARAMS, feet=feet, feet_height=low[:, :1])
    np.testing.assert_array_equal(lab[:, FOOT_B], [0, -1])  # planted foot: never -1
    np.testing.assert_array_equal(np.delete(lab, FOOT_B, 1), np.delete(plain, FOOT_B, 1))
    # the rule never lowers a contact label
    lab1 = C.labels_from_distance(np.zeros((2, 7)), PARAMS, feet=feet, feet_height=np.zeros((2, 1)))
    assert np.all(lab1 == 1)
    with pytest.raises(InputError):
        C.labels_from_distance(d, PARAMS, feet=feet)


# ---------------------------------------------------------------------------------------------------------
# hands, first contact, window, agreement


def test_hand_contact():
    lab = np.array([[0, 1, -1, -1], [0, 0, 0, 1], [-1, -1, -1, -1]], dtype=np.int8)
    h = C.hand_contact(lab, np.array([0, 1]), np.array([2, 3]))
    np.testing.assert_array_equal(h, [[True, False], [False, True], [False, False]])


def test_first_contact_frames_ignores_short_runs():
    hand = np.zeros((20, 2), dtype=bool)
    hand[2:4, 0] = True  # run of 2: too short
    hand[7:10, 0] = True  # run of 3: first contact of the left hand
    hand[15:17, 1] = True  # right hand only short runs
    hand[19, 1] = True
    np.testing.assert_array_equal(C.first_contact_frames(hand, 3), [7, -1])
    np.testing.assert_array_equal(C.first_contact_frames(hand, 2), [2, 15])
    np.testing.assert_array_equal(C.first_contact_frames(hand, 1), [2, 15])
    hand[17:20, 1] = True  # 15..19 now one run of 5
    np.testing.assert_array_equal(C.first_contact_frames(hand, 4), [-1, 15])
    assert C.first_contact_frames(hand, 3).dtype == np.int32


def test_contact_window_clipped():
    assert C.contact_window(np.array([30, 50]), 100, 10, 15).tolist() == [20, 45]
    assert C.contact_window(np.array([-1, 40]), 100, 10, 15).tolist() == [30, 55]  # t_c over hands with contact
    assert C.contact_window(np.array([4, -1]), 100, 10, 15).tolist() == [0, 19]  # clipped at the start
    assert C.contact_window(np.array([95, 97]), 100, 10, 15).tolist() == [85, 99]  # clipped at the end
    assert C.contact_window(np.array([-1, -1]), 100, 10, 15).tolist() == [-1, -1]
    assert C.contact_window(np.array([3, 5]), 100, 10, 15).dtype == np.int32


def test_label_agreement_numbers():
    a = np.array([[1, 1, 0, -1], [1, -1, 0, -1]], dtype=np.int8)
    b = np.array([[1, 0, 0, -1], [0, -1, 1, -1]], dtype=np.int8)
    r = C.label_agreement(a, b)
    json.dumps(r)  # JSON friendly
    assert r["n"] == 8 and r["agreement"] == pytest.approx(5 / 8)
    assert r["confusion"]["1->1"] == 1 and r["confusion"]["1->0"] == 2 and r["confusion"]["0->1"] == 1
    assert r["confusion"]["-1->-1"] == 3 and r["confusion"]["0->0"] == 1
    assert sum(r["confusion"].values()) == 8
    assert r["contact_precision"] == pytest.approx(1 / 3) and r["contact_recall"] == pytest.approx(1 / 2)
    assert r["contact_f1"] == pytest.approx(2 * (1 / 3) * (1 / 2) / (1 / 3 + 1 / 2))
    r2 = C.label_agreement(a, b, np.array([0]))
    assert r2["n"] == 2 and r2["agreement"] == 0.5 and r2["contact_precision"] == 0.5 and r2["contact_recall"] == 1
    r3 = C.label_agreement(a, b, np.array([3]))
    assert r3["agreement"] == 1.0 and r3["contact_precision"] is None and r3["contact_f1"] is None


def test_params_to_dict():
    d = C.ContactParams().to_dict()
    assert d["contact_m"] == 0.02 and d["no_touch_m"] == 0.10 and d["t_b"] == 10 and d["t_a"] == 15
    json.dumps(d)


@pytest.mark.parametrize("voxel", [0.01, 0.06])
def test_matches_brute_force_over_the_object_points(model, monkeypatch, voxel):
    """With object_points=0 the object is its vertex set: compare with an exhaustive search (a coarse voxel
    makes the coarse-to-fine search prune hard)."""
    monkeypatch.setattr(C, "_COARSE_VOXEL_M", voxel)
    ico = trimesh.creation.icosphere(subdivisions=3, radius=0.2)
    v, f = np.asarray(ico.vertices), np.asarray(ico.faces)
    rng = np.random.default_rng(3)
    T = 6
    pos = rng.uniform(-0.15, 0.15, (T, 1, 3))
    quat = rng.normal(size=(T, 1, 4))
    quat /= np.linalg.norm(quat, axis=-1, keepdims=True)
    q = _qpos(model, T)
    params = C.ContactParams(object_points=0)
    d = C.body_object_distance(model, q, [(v, f)], pos, quat, params)
    pts, gi = C.geom_surface_points(model, params.point_spacing_m)
    data = mujoco.MjData(model)
    ref = np.full((T, 7), np.inf)
    for t in range(T):
        data.qpos[:] = q[t]
        mujoco.mj_kinematics(model, data)
        world = np.einsum("pij,pj->pi", data.geom_xmat[gi].reshape(-1, 3, 3), pts) + data.geom_xpos[gi]
        obj = quat_rotate(quat[t, 0], v) + pos[t, 0]
        dist = np.linalg.norm(world[:, None] - obj[None], axis=-1).min(axis=1)
        np.minimum.at(ref[t], model.geom_bodyid[gi] - 1, dist)
    ref[ref > params.no_touch_m + C.REPORT_MARGIN_M] = np.inf
    assert np.isfinite(ref).sum() >= 10  # the scene has bodies in range
    np.testing.assert_allclose(d, ref, atol=1e-6)


# ---------------------------------------------------------------------------------------------------------
# real data (read from ../shared/data beside the checkout; skipped where absent)

OMOMO = SHARED_DATA / "intermimic_omomo"


@pytest.mark.shared_data
def test_hand_flags_agree_with_intermimic_labels():
    seq = OMOMO / "motions" / "sub2_largetable_000.pt"
    if not seq.exists():
        pytest.skip(f"{seq} is absent")
    torch = pytest.importorskip("torch")
    from wristmimic.humanoid.kinematics import hinge_angles, local_from_global, qpos_from
    from wristmimic.humanoid.roles import compute_roles, detect_profile
    from wristmimic.humanoid.skeleton import load_skeleton
    from wristmimic.rotations import xyzw_to_wxyz

    x = torch.load(seq, weights_only=True, map_location="cpu").detach().numpy().astype(np.float64)
    T = x.shape[0]
    skel = load_skeleton((OMOMO / "omomo.xml").read_text())
    roles = compute_roles(skel, detect_profile(skel))
    bq = xyzw_to_wxyz(x[:, 383:591].reshape(T, 52, 4))
    qpos = qpos_from(skel, x[:, :3], bq[:, 0], hinge_angles(local_from_global(skel, bq)))
    mesh = trimesh.load(OMOMO / "objects" / "largetable" / "largetable.obj", force="mesh", process=False)
    d = C.body_object_distance(
        skel.model, qpos, [(mesh.vertices, mesh.faces)], x[:, None, 318:321], xyzw_to_wxyz(x[:, None, 321:325])
    )
    lab = C.labels_from_distance(d)
    hand = C.hand_contact(lab, roles["left_hand"], roles["right_hand"])
    shipped = C.hand_contact(np.rint(x[:, 331:383]).astype(np.int8), roles["left_hand"], roles["right_hand"])
    assert np.mean(hand == shipped) > 0.95
    assert np.all(np.abs(C.first_contact_frames(hand, 3) - C.first_contact_frames(shipped, 3)) <= 3)
