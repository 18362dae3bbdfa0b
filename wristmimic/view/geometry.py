"""What to draw: a MuJoCo model's humanoid geoms and the objects' meshes as rerun archetypes.

Every shape is expressed in its body's (or object's) frame, so it is logged once, static, under the entity
whose per-frame ``Transform3D`` places that frame in the world. Quaternions are wxyz here (MuJoCo) and are
reordered to rerun's xyzw at the point where an archetype is built.
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np
import rerun as rr

from wristmimic.rotations import quat_rotate, wxyz_to_xyzw

Color = tuple[int, int, int, int]

_SHAPES = {
    mujoco.mjtGeom.mjGEOM_SPHERE: "sphere",
    mujoco.mjtGeom.mjGEOM_CAPSULE: "capsule",
    mujoco.mjtGeom.mjGEOM_CYLINDER: "cylinder",
    mujoco.mjtGeom.mjGEOM_BOX: "box",
    mujoco.mjtGeom.mjGEOM_ELLIPSOID: "ellipsoid",
    mujoco.mjtGeom.mjGEOM_MESH: "mesh",
}


@dataclass(frozen=True)
class GeomShape:
    """One geom of a body, in the body frame."""

    kind: str
    """sphere, capsule, cylinder, box, ellipsoid or mesh."""
    pos: np.ndarray  # (3,) geom centre in the body frame
    quat: np.ndarray  # (4,) wxyz geom orientation in the body frame
    size: np.ndarray  # (3,) MuJoCo geom_size: radius / (radius, half-length) / half sizes / radii
    vertices: np.ndarray | None = None  # (V, 3) mesh vertices, body frame (mesh geoms only)
    faces: np.ndarray | None = None  # (F, 3) int32 (mesh geoms only)


def body_geoms(model: mujoco.MjModel, body_id: int) -> list[GeomShape]:
    """The drawable geoms of one model body (planes, heightfields and SDFs are left out)."""
    out = []
    for g in np.flatnonzero(model.geom_bodyid == body_id):
        kind = _SHAPES.get(mujoco.mjtGeom(int(model.geom_type[g])))
        if kind is None:
            continue
        pos, quat = model.geom_pos[g].copy(), model.geom_quat[g].copy()
        verts = faces = None
        if kind == "mesh":
            m = int(model.geom_dataid[g])
            va, vn = int(model.mesh_vertadr[m]), int(model.mesh_vertnum[m])
            fa, fn = int(model.mesh_faceadr[m]), int(model.mesh_facenum[m])
            verts = (quat_rotate(quat, model.mesh_vert[va : va + vn]) + pos).astype(np.float32)
            faces = model.mesh_face[fa : fa + fn].astype(np.int32)
        out.append(GeomShape(kind, pos, quat, model.geom_size[g].copy(), verts, faces))
    return out


def humanoid_geoms(model: mujoco.MjModel, body_ids: np.ndarray) -> list[list[GeomShape]]:
    """Geoms of each humanoid body, in the order of ``body_ids`` (model body ids)."""
    return [body_geoms(model, int(b)) for b in body_ids]


def vertex_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(V, 3) unit area-weighted vertex normals of a triangle mesh (zero for unused vertices)."""
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    n = np.zeros_like(v)
    if len(f):
        fn = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
        for k in range(3):
            np.add.at(n, f[:, k], fn)
    length = np.linalg.norm(n, axis=-1, keepdims=True)
    return (n / np.where(length > 0, length, 1.0)).astype(np.float32)


def mesh_archetype(vertices: np.ndarray, faces: np.ndarray, color: Color) -> rr.Mesh3D:
    """A shaded triangle mesh of one colour (alpha < 255: translucent)."""
    return rr.Mesh3D(
        vertex_positions=np.asarray(vertices, dtype=np.float32),
        triangle_indices=np.asarray(faces, dtype=np.uint32),
        vertex_normals=vertex_normals(vertices, faces),
        albedo_factor=color,
    )


def geom_archetype(shape: GeomShape, color: Color, fill: str = "solid") -> rr.AsComponents:
    """The rerun primitive of one geom, placed in its body frame.

    MuJoCo capsules and cylinders are centred on the geom frame along its z axis with half-length
    ``size[1]``; rerun cylinders are centred too, rerun capsules start at the origin and extend ``length``
    along +z, hence the shift by ``-size[1]`` along the geom's z axis.
    """
    q = [wxyz_to_xyzw(shape.quat)]
    s = shape.size
    if shape.kind == "sphere":
        return rr.Ellipsoids3D(half_sizes=[[s[0]] * 3], centers=[shape.pos], colors=[color], fill_mode=fill)
    if shape.kind == "ellipsoid":
        return rr.Ellipsoids3D(half_sizes=[s], centers=[shape.pos], quaternions=q, colors=[color], fill_mode=fill)
    if shape.kind == "box":
        return rr.Boxes3D(half_sizes=[s], centers=[shape.pos], quaternions=q, colors=[color], fill_mode=fill)
    if shape.kind == "cylinder":
        return rr.Cylinders3D(
            lengths=[2 * s[1]], radii=[s[0]], centers=[shape.pos], quaternions=q, colors=[color], fill_mode=fill
        )
    if shape.kind == "capsule":
        start = shape.pos - quat_rotate(shape.quat, np.array([0.0, 0.0, s[1]]))
        return rr.Capsules3D(
            lengths=[2 * s[1]], radii=[s[0]], translations=[start], quaternions=q, colors=[color], fill_mode=fill
        )
    if shape.kind == "mesh" and shape.vertices is not None and shape.faces is not None:
        return mesh_archetype(shape.vertices, shape.faces, color)
    raise ValueError(f"cannot draw a {shape.kind} geom")


def entity_part(name: str) -> str:
    """``name`` escaped for use as one entity-path part (body and object names may hold any character)."""
    return rr.escape_entity_path_part(str(name))
