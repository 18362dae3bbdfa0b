"""The canonical reference format (HDF5), version 1: names, shapes and dtypes in one place.

``docs/format.md`` documents every entry; :mod:`wristmimic.format.validate` checks a file against this.

Layout (T frames, B bodies, J = B - 1 joints, O objects of a sequence)::

    /                      attrs: ROOT_ATTRS
    /index/                sequence_ids (N,) str, num_frames (N,) i4, humanoid_ids (N,) str,
                           datasets (N,) str, splits (N,) str
    /humanoids/<hid>/      attrs: name, family, source_file (+ hand, hand_source, hand_ranges since 1.1);
                           mjcf () str; body_names (B,) str;
                           parents (B,) i4; joint_bodies (J,) i4; roles/<role> (n,) i4
    /objects/<oid>/        attrs: name, static, inferred, density, mass, mass_method, watertight,
                           mesh_sha256, source_file, urdf (JSON), surface_seed
                           visual/vertices (V,3) f4, visual/faces (F,3) i4
                           hulls/vertices (Nv,3) f4, hulls/faces (Nf,3) i4, hulls/vertex_offsets (H+1,) i8,
                           hulls/face_offsets (H+1,) i8; attrs method, params (JSON), coacd_version, cache_key
                           com (3,) f8, inertia (3,3) f8, surface_points (P,3) f4
    /sequences/<sid>/      attrs: humanoid_id, object_ids (JSON list), subject, text, dataset, split,
                           num_frames, source_file
                           SEQUENCE_ARRAYS (per frame, chunked along time) and contacts/*;
                           OPTIONAL_SEQUENCE_ARRAYS (sim/*, since 1.2: sequences exported from a simulation)
"""

from __future__ import annotations

FORMAT_NAME = "wristmimic-reference"
SCHEMA_VERSION = "1.2.0"
"""Semantic version. Readers reject another MAJOR; a MINOR adds optional content old readers ignore."""

FPS = 30.0
UP_AXIS = "z"
UNITS = "m"
QUAT_ORDER = "wxyz"
CHUNK_FRAMES = 64
COMPRESSION = {"compression": "gzip", "compression_opts": 4, "shuffle": True}

ROOT_ATTRS = (
    "format",
    "schema_version",
    "fps",
    "up_axis",
    "units",
    "quat_order",
    "source_dataset",
    "source_format",
    "converter",
    "converter_version",
    "created_utc",
    "input_sha256",
)

# name -> (shape with symbols, dtype, unit, meaning). Symbols: T frames, B bodies, J joints, O objects.
SEQUENCE_ARRAYS: dict[str, tuple[tuple[str | int, ...], str, str, str]] = {
    "root_pos": (("T", 3), "float32", "m", "world position of the root body"),
    "root_quat": (("T", 4), "float32", "wxyz", "world orientation of the root body"),
    "joint_quat": (("T", "J", 4), "float32", "wxyz", "joint rotation: rest^-1 * parent^-1 * body (per 3-DoF joint)"),
    "joint_angles": (("T", "J", 3), "float32", "rad", "x, y, z hinge angles (intrinsic XYZ Euler of joint_quat)"),
    "body_pos": (("T", "B", 3), "float32", "m", "world body positions: MuJoCo FK of the stored humanoid"),
    "body_quat": (("T", "B", 4), "float32", "wxyz", "world body orientations (source rotations, = FK)"),
    "source_body_pos": (("T", "B", 3), "float32", "m", "body positions as the source stored them"),
    "source_body_pos_valid": (("B",), "bool", "-", "which source_body_pos slots hold real data"),
    "object_pos": (("T", "O", 3), "float32", "m", "world position of each object's frame (object_ids order)"),
    "object_quat": (("T", "O", 4), "float32", "wxyz", "world orientation of each object's frame"),
    "contacts/labels": (("T", "B"), "int8", "-", "per-body contact label: 1 contact, 0 unknown, -1 must not touch"),
    "contacts/geometric": (("T", "B"), "int8", "-", "per-body label computed from geometry (cross-check)"),
    "contacts/distance": (("T", "B"), "float32", "m", "body-geom to dynamic-object surface distance (inf = far)"),
    "contacts/hand": (("T", 2), "bool", "-", "left, right hand in contact (any hand body labelled 1)"),
    "contacts/object": (("T",), "bool", "-", "object-level contact flag"),
    "contacts/first_contact_frame": ((2,), "int32", "frame", "t_c per hand (left, right); -1 if none"),
    "contacts/window": ((2,), "int32", "frame", "contact window [t_c - t_b, t_c + t_a], clipped; -1 if none"),
}
OPTIONAL_SEQUENCE_ARRAYS: dict[str, tuple[tuple[str | int, ...], str, str, str]] = {
    "sim/actions": (("T", "D"), "float32", "-", "policy action applied from frame t to t + 1 (last row repeated)"),
    "sim/pd_targets": (("T", "D"), "float32", "rad", "PD target of each hinge from frame t to t + 1 (last repeated)"),
    "sim/contact_force": (("T", "B", 3), "float32", "N", "net contact force on each body (all partners) at frame t"),
}
"""Since 1.2, only in sequences written by ``wristmimic export`` (D = 3 J hinges, joint_angles order); readers and
``validate`` check them when present and ignore their absence."""
PER_FRAME = [k for k, v in (SEQUENCE_ARRAYS | OPTIONAL_SEQUENCE_ARRAYS).items() if v[0][0] == "T"]

OBJECT_ARRAYS = {
    "visual/vertices": (("V", 3), "float32", "m", "visual mesh vertices, object frame"),
    "visual/faces": (("F", 3), "int32", "-", "visual mesh triangles"),
    "hulls/vertices": (("Nv", 3), "float32", "m", "all hull vertices, concatenated"),
    "hulls/faces": (("Nf", 3), "int32", "-", "hull triangles, indices local to each hull"),
    "hulls/vertex_offsets": (("H+1",), "int64", "-", "hull k owns vertices[vertex_offsets[k]:vertex_offsets[k+1]]"),
    "hulls/face_offsets": (("H+1",), "int64", "-", "hull k owns faces[face_offsets[k]:face_offsets[k+1]]"),
    "com": ((3,), "float64", "m", "centre of mass, object frame"),
    "inertia": ((3, 3), "float64", "kg m^2", "inertia tensor about the COM, object axes"),
    "surface_points": (("P", 3), "float32", "m", "seeded even surface samples, object frame"),
}

CONTACT_LABELS = (-1, 0, 1)
STATIC_OBJECT_NAMES = frozenset(
    {
        "table",
        "diningtable",
        "desk",
        "gasstove",
        "bookshelf",
        "sink",
        "refrigerator",
        "microwave",
        "washingmachine",
        "drawer",
    }
)
"""Furniture that is fixed in the world when it appears in a scene (paper supplement, ParaHome)."""
