"""Tests of wristmimic.convert.objects: URDF + OBJ loading, mass properties, surface samples."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

from wristmimic.convert.objects import (
    find_object_files,
    list_objects,
    load_object,
    mass_properties,
    read_urdf,
)
from wristmimic.errors import InputError

SIZE = np.array([0.2, 0.3, 0.5])
CENTER = np.array([0.1, -0.2, 0.3])
DENSITY = 750.0

# corners of the unit cube and its 12 outward triangles
# fmt: off
_CORNERS = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)], dtype=float)
_FACES = np.array(
    [
        [0, 1, 3], [0, 3, 2],  # x = 0
        [4, 6, 7], [4, 7, 5],  # x = 1
        [0, 4, 5], [0, 5, 1],  # y = 0
        [2, 3, 7], [2, 7, 6],  # y = 1
        [0, 2, 6], [0, 6, 4],  # z = 0
        [1, 5, 7], [1, 7, 3],  # z = 1
    ]
)
# fmt: on


def box_obj_text(extra_vertex: bool = False) -> str:
    """OBJ text of the closed box SIZE centred at CENTER (8 shared vertices, outward faces)."""
    verts = CENTER + (_CORNERS - 0.5) * SIZE
    lines = ["# test box"] + [f"v {x:.17g} {y:.17g} {z:.17g}" for x, y, z in verts]
    if extra_vertex:
        lines.append("v 9 9 9")  # unreferenced: must be kept, in place
    lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in _FACES]
    return "\n".join(lines) + "\n"


def urdf_text(filename: str, scale: str = "1.0 1.0 1.0") -> str:
    return f"""<?xml version="1.0" ?>
<robot name="box.urdf">
  <dynamics damping="0.5" friction="0.9"/>
  <link name="baseLink">
    <contact>
      <lateral_friction value="0.8"/>
      <rolling_friction value="0.4"/>
      <spinning_friction value="0.2"/>
      <stiffness value="30000"/>
      <damping value="1000"/>
    </contact>
    <inertial>
      <origin xyz="0 0 0.1" rpy="0 0 0"/>
      <mass value="4.0"/>
      <inertia ixx="0.06" ixy="0" ixz="0" iyy="0.07" iyz="0" izz="0.08"/>
    </inertial>
    <visual>
      <origin rpy="0 0 0" xyz="0 0 0"/>
      <geometry><mesh filename="{filename}" scale="{scale}"/></geometry>
    </visual>
    <collision>
      <geometry><mesh filename="{filename}" scale="{scale}"/></geometry>
    </collision>
  </link>
</robot>
"""


def make_layout(root: Path, layout: str, name: str = "box", scale: str = "1.0 1.0 1.0") -> Path:
    """Write an objects folder in the 'omomo' (<name>/<name>.obj), 'parahome' (<name>.obj) or 'bare' layout."""
    objects = root / "objects"
    objects.mkdir(parents=True, exist_ok=True)
    if layout == "omomo":
        (objects / name).mkdir(exist_ok=True)
        (objects / name / f"{name}.obj").write_text(box_obj_text())
        (objects / f"{name}.urdf").write_text(urdf_text(f"objects/{name}/{name}.obj", scale))
    elif layout == "parahome":
        (objects / f"{name}.obj").write_text(box_obj_text())
        (objects / f"{name}.urdf").write_text(urdf_text(f"{name}.obj", scale))
    else:
        (objects / f"{name}.obj").write_text(box_obj_text())
    return objects


def box_inertia(mass: float, size: np.ndarray) -> np.ndarray:
    a, b, c = size
    return np.diag([b * b + c * c, a * a + c * c, a * a + b * b]) * mass / 12.0


def distance_to_box_surface(points: np.ndarray) -> np.ndarray:
    q = np.abs(points.astype(np.float64) - CENTER) - SIZE / 2  # <= 0 inside, one component 0 on a face
    outside = np.linalg.norm(np.maximum(q, 0), axis=1)
    inside = np.minimum(q.max(axis=1), 0)
    return outside + np.abs(inside)


# --------------------------------------------------------------------------- layouts and URDF


@pytest.mark.parametrize("layout", ["omomo", "parahome", "bare"])
def test_load_box_both_layouts(tmp_path: Path, layout: str) -> None:
    objects = make_layout(tmp_path, layout)
    urdf, mesh = find_object_files(objects, "box")
    expected_mesh = objects / "box" / "box.obj" if layout == "omomo" else objects / "box.obj"
    assert mesh == expected_mesh
    assert urdf == (None if layout == "bare" else objects / "box.urdf")
    assert list_objects(objects) == ["box"]

    obj = load_object("box", objects, density=DENSITY)
    assert obj.name == "box" and obj.mesh_path == expected_mesh and obj.urdf_path == urdf
    assert obj.vertices.dtype == np.float64 and obj.faces.dtype == np.int32
    np.testing.assert_allclose(obj.vertices, CENTER + (_CORNERS - 0.5) * SIZE, rtol=0, atol=1e-15)
    np.testing.assert_array_equal(obj.faces, _FACES)
    urdf_mass = (obj.urdf or {}).get("inertial_mass")
    # the geometry gives COM and inertia shape; a URDF <inertial><mass> sets the mass
    mass = float(urdf_mass) if urdf_mass else float(np.prod(SIZE)) * DENSITY
    assert obj.watertight and obj.mass_method == ("visual_mesh+urdf_mass" if urdf_mass else "visual_mesh")
    assert obj.density == DENSITY
    assert obj.mass == pytest.approx(mass, rel=1e-6)
    np.testing.assert_allclose(obj.com, CENTER, rtol=0, atol=1e-12)
    np.testing.assert_allclose(obj.inertia, box_inertia(mass, SIZE), rtol=0, atol=1e-9 * mass)
    import hashlib

    assert obj.mesh_sha256 == hashlib.sha256(expected_mesh.read_bytes()).hexdigest()


def test_urdf_values_parsed(tmp_path: Path) -> None:
    objects = make_layout(tmp_path, "omomo")
    mesh, props = read_urdf(objects / "box.urdf")
    assert mesh == objects / "box" / "box.obj"
    assert props["lateral_friction"] == 0.8
    assert props["rolling_friction"] == 0.4
    assert props["spinning_friction"] == 0.2
    assert props["contact_stiffness"] == 30000.0
    assert props["contact_damping"] == 1000.0
    assert props["dynamics_damping"] == 0.5 and props["dynamics_friction"] == 0.9
    assert props["inertial_mass"] == 4.0
    assert props["inertial_origin_xyz"] == [0.0, 0.0, 0.1]
    assert props["inertial_inertia"] == [0.06, 0.0, 0.0, 0.07, 0.0, 0.08]
    assert props["mesh_scale"] == [1.0, 1.0, 1.0]
    assert load_object("box", objects).urdf == props


def test_urdf_without_optional_values(tmp_path: Path) -> None:
    objects = tmp_path / "objects"
    objects.mkdir()
    (objects / "box.obj").write_text(box_obj_text())
    (objects / "box.urdf").write_text(
        '<robot name="b"><link name="l"><visual><geometry><mesh filename="box.obj"/></geometry></visual></link></robot>'
    )
    mesh, props = read_urdf(objects / "box.urdf")
    assert mesh == objects / "box.obj"
    for key in ("lateral_friction", "contact_stiffness", "inertial_mass", "mesh_scale", "dynamics_damping"):
        assert key not in props


def test_urdf_mesh_missing_falls_back_to_layout(tmp_path: Path) -> None:
    objects = tmp_path / "objects"
    objects.mkdir()
    (objects / "pot.obj").write_text(box_obj_text())
    (objects / "pot.urdf").write_text(urdf_text("pot/base_visual.obj"))  # as in the ParaHome pot
    assert find_object_files(objects, "pot") == (objects / "pot.urdf", objects / "pot.obj")


def test_mesh_scale_applied(tmp_path: Path) -> None:
    objects = make_layout(tmp_path, "parahome", scale="2 2 2")
    obj = load_object("box", objects, density=DENSITY)
    np.testing.assert_allclose(obj.vertices, 2 * (CENTER + (_CORNERS - 0.5) * SIZE), atol=1e-15)
    assert obj.mass == pytest.approx(obj.urdf["inertial_mass"], rel=1e-6)  # the URDF's mass wins
    geo = 8 * float(np.prod(SIZE)) * DENSITY  # the geometry's inertia, scaled to that mass
    np.testing.assert_allclose(obj.inertia, box_inertia(geo, 2 * SIZE) * obj.mass / geo, atol=1e-9)
    np.testing.assert_allclose(obj.com, 2 * CENTER, atol=1e-12)


def test_vertices_kept_in_file_order(tmp_path: Path) -> None:
    objects = tmp_path / "objects"
    objects.mkdir()
    (objects / "box.obj").write_text(box_obj_text(extra_vertex=True))
    obj = load_object("box", objects, density=DENSITY)
    assert len(obj.vertices) == 9 and tuple(obj.vertices[8]) == (9.0, 9.0, 9.0)
    assert obj.mass == pytest.approx(float(np.prod(SIZE)) * DENSITY, rel=1e-6)
    assert distance_to_box_surface(obj.surface_points).max() < 1e-6


# --------------------------------------------------------------------------- surface samples


def test_surface_points(tmp_path: Path) -> None:
    objects = make_layout(tmp_path, "parahome")
    a = load_object("box", objects)
    assert a.surface_points.shape == (1024, 3) and a.surface_points.dtype == np.float32
    assert a.surface_seed == 2024
    assert distance_to_box_surface(a.surface_points).max() < 1e-6
    # points spread over all six faces
    q = (a.surface_points - CENTER) / (SIZE / 2)
    faces_hit = {(int(np.argmax(np.abs(p))), int(np.sign(p[np.argmax(np.abs(p))]))) for p in q}
    assert len(faces_hit) == 6
    b = load_object("box", objects)
    np.testing.assert_array_equal(a.surface_points, b.surface_points)
    c = load_object("box", objects, surface_seed=7)
    assert c.surface_seed == 7 and not np.array_equal(a.surface_points, c.surface_points)
    d = load_object("box", objects, n_surface=5000)
    assert d.surface_points.shape == (5000, 3)
    assert distance_to_box_surface(d.surface_points).max() < 1e-6


def test_surface_points_topped_up(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    import trimesh.sample

    objects = make_layout(tmp_path, "parahome")
    full = load_object("box", objects).surface_points
    real = trimesh.sample.sample_surface_even

    def short(mesh, count, radius=None, seed=None):  # rejection sampling sometimes returns fewer points
        points, index = real(mesh, count, radius=radius, seed=seed)
        return points[: count - 100], index[: count - 100]

    monkeypatch.setattr(trimesh.sample, "sample_surface_even", short)
    topped = load_object("box", objects).surface_points
    assert topped.shape == (1024, 3) and topped.dtype == np.float32
    np.testing.assert_array_equal(topped[:924], full[:924])
    assert not np.array_equal(topped[924:], full[924:])
    assert distance_to_box_surface(topped).max() < 1e-6
    np.testing.assert_array_equal(load_object("box", objects).surface_points, topped)


# --------------------------------------------------------------------------- mass fallbacks


def test_mass_repaired_when_vertices_duplicated() -> None:
    verts = CENTER + (_CORNERS - 0.5) * SIZE
    split_v = verts[_FACES].reshape(-1, 3)  # 36 vertices, one per face corner: not watertight as loaded
    split_f = np.arange(36, dtype=np.int32).reshape(12, 3)
    mass, com, inertia, method, watertight = mass_properties(split_v, split_f, DENSITY)
    assert not watertight and method == "visual_mesh_repaired"
    m = float(np.prod(SIZE)) * DENSITY
    assert mass == pytest.approx(m, rel=1e-6)
    np.testing.assert_allclose(com, CENTER, atol=1e-12)
    np.testing.assert_allclose(inertia, box_inertia(m, SIZE), atol=1e-9 * m)


def test_mass_inward_faces_are_fixed() -> None:
    verts = CENTER + (_CORNERS - 0.5) * SIZE
    mass, _, _, method, watertight = mass_properties(verts, _FACES[:, ::-1].copy(), DENSITY)
    assert watertight and method == "visual_mesh_repaired"
    assert mass == pytest.approx(float(np.prod(SIZE)) * DENSITY, rel=1e-6)


def test_mass_convex_hull_fallback() -> None:
    # an open, inconsistently wound surface: only the convex hull gives a solid
    verts = CENTER + (_CORNERS - 0.5) * SIZE
    faces = _FACES[:6].copy()
    faces[1] = faces[1][::-1]
    mass, com, _, method, watertight = mass_properties(verts, faces, DENSITY)
    assert not watertight and method == "convex_hull"
    assert mass == pytest.approx(float(np.prod(SIZE)) * DENSITY, rel=1e-6)
    np.testing.assert_allclose(com, CENTER, atol=1e-12)


def test_flat_mesh_has_no_mass(tmp_path: Path) -> None:
    objects = tmp_path / "objects"
    objects.mkdir()
    (objects / "sheet.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nf 1 2 3\nf 2 4 3\n")
    with pytest.raises(InputError, match="sheet.obj: mass"):
        load_object("sheet", objects)


# --------------------------------------------------------------------------- errors


def test_missing_mesh_names_object(tmp_path: Path) -> None:
    objects = tmp_path / "objects"
    objects.mkdir()
    with pytest.raises(InputError) as e:
        load_object("ghostcup", objects)
    msg = str(e.value)
    assert "ghostcup" in msg and str(objects) in msg and "ghostcup.obj" in msg
    (objects / "ghostcup.urdf").write_text(urdf_text("nowhere/ghostcup_visual.obj"))
    with pytest.raises(InputError, match="ghostcup") as e:
        load_object("ghostcup", objects)
    assert "nowhere" in str(e.value)
    assert list_objects(objects) == []


def test_malformed_urdf_names_file(tmp_path: Path) -> None:
    objects = make_layout(tmp_path, "parahome")
    (objects / "box.urdf").write_text('<robot name="x"><link name="l"></robot>')
    with pytest.raises(InputError, match="malformed") as e:
        load_object("box", objects)
    assert str(e.value).startswith(str(objects / "box.urdf"))


def test_bad_number_in_urdf(tmp_path: Path) -> None:
    objects = make_layout(tmp_path, "parahome")
    (objects / "box.urdf").write_text(urdf_text("box.obj").replace('value="0.8"', 'value="slippery"'))
    with pytest.raises(InputError, match="lateral_friction"):
        read_urdf(objects / "box.urdf")


def test_urdf_with_entities_rejected(tmp_path: Path) -> None:
    objects = make_layout(tmp_path, "parahome")
    (objects / "box.urdf").write_text(
        '<?xml version="1.0"?>\n<!DOCTYPE robot [<!ENTITY name "box.obj">]>\n'
        '<robot name="b"><link name="l"><visual><geometry><mesh filename="&name;"/></geometry>'
        "</visual></link></robot>"
    )
    with pytest.raises(InputError, match="DOCTYPE") as e:
        read_urdf(objects / "box.urdf")
    assert str(objects / "box.urdf") in str(e.value)


@pytest.mark.parametrize(
    ("text", "problem"),
    [
        ("# nothing\n", "empty"),
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 nan\nf 1 2 3\nf 1 2 4\n", "non-finite"),
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nf 1 2 9\n", "out of (bounds|range)"),
    ],
)
def test_bad_obj_rejected(tmp_path: Path, text: str, problem: str) -> None:
    objects = tmp_path / "objects"
    objects.mkdir()
    (objects / "bad.obj").write_text(text)
    with pytest.raises(InputError, match=problem) as e:
        load_object("bad", objects)
    assert str(objects / "bad.obj") in str(e.value)


def test_bad_name_rejected(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="name"):
        find_object_files(tmp_path, "../etc")


# --------------------------------------------------------------------------- shared data


def _shared_data() -> Path:
    env = os.environ.get("WRISTMIMIC_SHARED_DATA")
    return Path(env) if env else Path(__file__).resolve().parents[1].parent / "shared" / "data"


@pytest.mark.shared_data
def test_shared_objects() -> None:
    data = _shared_data()
    if not data.is_dir():
        pytest.skip(f"shared data folder {data} is absent (set WRISTMIMIC_SHARED_DATA)")
    wanted = {
        "intermimic_omomo/objects": ["largetable", "plasticbox"],
        "skillmimic_parahome/objects": ["kettle", "pan", "pot"],
    }
    for folder, names in wanted.items():
        objects = data / folder
        assert set(names) <= set(list_objects(objects))
        for name in names:
            obj = load_object(name, objects)
            assert np.isfinite(obj.mass) and obj.mass > 0, name
            assert np.isfinite(obj.com).all() and np.isfinite(obj.inertia).all(), name
            np.testing.assert_allclose(obj.inertia, obj.inertia.T, atol=0)
            assert np.linalg.eigvalsh(obj.inertia).min() >= 0, name
            assert obj.surface_points.shape == (1024, 3) and obj.surface_points.dtype == np.float32
            assert obj.urdf_path is not None and obj.mesh_path.is_file()
            assert len(obj.vertices) > 1000 and not obj.watertight
