"""Pieces every converter shares: humanoid records, object records with hulls, kinematics, contacts."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from wristmimic.convert import contacts as C
from wristmimic.convert.hulls import HullParams, convex_decompose, hull_params_for, pack_hulls
from wristmimic.convert.objects import ObjectAsset
from wristmimic.errors import InputError
from wristmimic.format.records import HumanoidRecord, ObjectRecord
from wristmimic.format.schema import STATIC_OBJECT_NAMES
from wristmimic.humanoid.kinematics import forward_kinematics, qpos_from
from wristmimic.humanoid.roles import compute_roles, detect_profile
from wristmimic.humanoid.skeleton import Skeleton, load_skeleton
from wristmimic.rotations import quat_angle

Progress = Callable[[str], None]
"""Called with a short status text; converters advance their own bars through :class:`ConvertOptions`."""


@dataclass
class ConvertOptions:
    """Options shared by the converters."""

    hull_cache_dir: Path | None = None
    """Where coacd results are cached (None: the default cache folder)."""
    use_hull_cache: bool = True
    hull_params: HullParams = field(default_factory=HullParams)
    """Base coacd parameters; the hull count per object follows the paper (kettle, cup 80; chair 50)."""
    contact: C.ContactParams = field(default_factory=C.ContactParams)
    object_density: float = 1000.0
    surface_points: int = 1024
    surface_seed: int = 2024
    show_progress: bool = True


@dataclass
class ConvertReport:
    """What a conversion did (for the CLI and the benchmark)."""

    output: Path
    sequences: list[str] = field(default_factory=list)
    skipped: dict[str, str] = field(default_factory=dict)
    seconds_per_sequence: dict[str, float] = field(default_factory=dict)
    seconds_per_object: dict[str, float] = field(default_factory=dict)
    hull_cache_hits: dict[str, bool] = field(default_factory=dict)
    fk_rotation_error_deg: dict[str, float] = field(default_factory=dict)


def humanoid_record(mjcf: str, name: str, source_file: str | Path) -> tuple[HumanoidRecord, Skeleton]:
    """Parse and role-tag a humanoid MJCF."""
    skel = load_skeleton(mjcf, source_file)
    profile = detect_profile(skel, str(source_file))
    rec = HumanoidRecord(
        name=name,
        family=profile.family,
        mjcf=mjcf,
        body_names=list(skel.body_names),
        parents=skel.parents,
        joint_bodies=skel.joint_bodies,
        roles=compute_roles(skel, profile),
        source_file=str(source_file),
    )
    return rec, skel


def object_record(
    asset: ObjectAsset, opts: ConvertOptions, *, static: bool | None = None
) -> tuple[ObjectRecord, float, bool]:
    """Object record with coacd hulls (cached). Returns (record, hull seconds, cache hit)."""
    params = hull_params_for(asset.name, opts.hull_params)
    hs = convex_decompose(asset.vertices, asset.faces, params, opts.hull_cache_dir, use_cache=opts.use_hull_cache)
    hv, hf, vo, fo = pack_hulls(hs)
    is_static = asset.name.lower() in STATIC_OBJECT_NAMES if static is None else static
    rec = ObjectRecord(
        name=asset.name,
        static=is_static,
        inferred=False,
        vertices=asset.vertices,
        faces=asset.faces,
        hull_vertices=hv,
        hull_faces=hf,
        hull_vertex_offsets=vo,
        hull_face_offsets=fo,
        hull_meta={
            "method": "coacd",
            "params": params.to_dict(),
            "seed": params.seed,
            "coacd_version": hs.coacd_version,
            "cache_key": hs.cache_key,
        },
        mass=asset.mass,
        com=asset.com,
        inertia=asset.inertia,
        mass_method=asset.mass_method,
        density=asset.density,
        watertight=asset.watertight,
        surface_points=asset.surface_points,
        surface_seed=asset.surface_seed,
        mesh_sha256=asset.mesh_sha256,
        urdf=asset.urdf,
        source_file=str(asset.urdf_path or asset.mesh_path),
    )
    return rec, hs.seconds, hs.cache_hit


def write_objects(
    writer: Any,
    names: Sequence[str],
    objects_dir: Path,
    source_root: Path,
    opts: ConvertOptions,
    report: ConvertReport,
    inputs: dict[str, str],
    bar: Any,
    *,
    static: bool | None = None,
) -> dict[str, ObjectAsset]:
    """Load each object (URDF + OBJ), decompose it (cached), write it; record timings and input hashes."""
    import time

    from wristmimic.convert.objects import load_object
    from wristmimic.safe_io import sha256_file

    assets: dict[str, ObjectAsset] = {}
    task = bar.add_task("objects (coacd hulls)", total=len(names))
    for name in sorted(names):
        t0 = time.perf_counter()
        asset = load_object(
            name,
            objects_dir,
            density=opts.object_density,
            n_surface=opts.surface_points,
            surface_seed=opts.surface_seed,
        )
        rec, _, hit = object_record(asset, opts, static=static)
        writer.add_object(name, rec)
        assets[name] = asset
        report.seconds_per_object[name] = time.perf_counter() - t0
        report.hull_cache_hits[name] = hit
        if asset.urdf_path is not None:
            inputs[str(asset.urdf_path.relative_to(source_root))] = sha256_file(asset.urdf_path)
        inputs[str(asset.mesh_path.relative_to(source_root))] = asset.mesh_sha256
        bar.advance(task)
    return assets


def box_record(
    name: str,
    size: Sequence[float],
    density: float,
    *,
    static: bool,
    inferred: bool,
    n_surface: int,
    surface_seed: int,
    source_file: str,
    extra: dict[str, Any] | None = None,
) -> ObjectRecord:
    """A solid box centred at its frame's origin (full ``size`` in m): mesh, one hull (the box itself),
    analytic mass and inertia, seeded surface samples. Used for inferred supports and synthetic scenes."""
    import hashlib

    import trimesh

    mesh = trimesh.creation.box(extents=np.asarray(size, float))
    v = np.asarray(mesh.vertices, np.float64)
    f = np.asarray(mesh.faces, np.int32)
    dx, dy, dz = (float(x) for x in size)
    mass = dx * dy * dz * float(density)
    inertia = np.diag([dy**2 + dz**2, dx**2 + dz**2, dx**2 + dy**2]) * mass / 12.0
    rng = np.random.default_rng(surface_seed)
    pts = trimesh.sample.sample_surface(mesh, n_surface, seed=int(rng.integers(2**31)))[0]
    return ObjectRecord(
        name=name,
        static=static,
        inferred=inferred,
        vertices=v,
        faces=f,
        hull_vertices=v,
        hull_faces=f,
        hull_vertex_offsets=np.array([0, len(v)]),
        hull_face_offsets=np.array([0, len(f)]),
        hull_meta={"method": "box", "params": {}, "seed": 0},
        mass=mass,
        com=np.zeros(3),
        inertia=inertia,
        mass_method="box",
        density=float(density),
        watertight=True,
        surface_points=np.asarray(pts, np.float32),
        surface_seed=surface_seed,
        mesh_sha256=hashlib.sha256(v.astype(np.float32).tobytes() + f.tobytes()).hexdigest(),
        source_file=source_file,
        extra={"size_m": [dx, dy, dz], **(extra or {})},
    )


@dataclass
class Kinematics:
    """Per-frame kinematics of a converted sequence."""

    qpos: np.ndarray
    joint_quat: np.ndarray
    joint_angles: np.ndarray
    body_pos: np.ndarray
    body_quat: np.ndarray
    fk_rotation_error_deg: float


def kinematics(
    skel: Skeleton,
    root_pos: np.ndarray,
    root_quat: np.ndarray,
    joint_quat: np.ndarray,
    target_body_quat: np.ndarray | None,
    source: str,
) -> Kinematics:
    """Hinge angles from joint rotations, then MuJoCo FK. If the source stored global body rotations,
    check FK reproduces them (raises if worse than 0.5 degrees)."""
    from wristmimic.humanoid.kinematics import hinge_angles

    angles = hinge_angles(joint_quat)
    qpos = qpos_from(skel, root_pos, root_quat, angles)
    fk = forward_kinematics(skel.model, qpos)
    err = 0.0
    if target_body_quat is not None:
        err = float(np.degrees(quat_angle(fk.body_quat, target_body_quat)).max())
        if err > 0.5:
            raise InputError(
                source,
                "body rotations",
                f"forward kinematics is {err:.2f} deg off the stored rotations",
                "< 0.5 deg (does the humanoid match the motion file?)",
            )
    return Kinematics(qpos, joint_quat, angles, fk.body_pos, fk.body_quat, err)


def geometric_contacts(
    skel: Skeleton,
    roles: dict[str, np.ndarray],
    qpos: np.ndarray,
    meshes: Sequence[tuple[np.ndarray, np.ndarray]],
    obj_pos: np.ndarray,
    obj_quat: np.ndarray,
    params: C.ContactParams,
) -> tuple[np.ndarray, np.ndarray]:
    """(distance (T,B) float32, labels (T,B) int8) of the humanoid against the dynamic objects."""
    T = qpos.shape[0]
    if not meshes:
        dist = np.full((T, skel.num_bodies), np.inf, np.float32)
    else:
        dist = C.body_object_distance(skel.model, qpos, list(meshes), obj_pos, obj_quat, params)
    feet = roles["feet"]
    feet_z = C.body_lowest_z(skel.model, qpos, feet, params)
    labels = C.labels_from_distance(dist, params, feet=feet, feet_height=feet_z)
    return dist, labels


def geometric_contact_meta(params: C.ContactParams, against: str = "object surface samples") -> dict[str, Any]:
    """``contacts`` attributes of a sequence whose labels come from geometry."""
    return {
        "labels_method": f"geometry: humanoid geom surface points vs {against} (KD-tree)",
        "geometric_method": "same as labels",
        "params": params.to_dict(),
        "t_b": params.t_b,
        "t_a": params.t_a,
    }


def contact_summary(labels: np.ndarray, roles: dict[str, np.ndarray], params: C.ContactParams) -> dict[str, Any]:
    """Per-hand flags, first contact frames and the contact window from per-body labels."""
    hand = C.hand_contact(labels, roles["left_hand"], roles["right_hand"])
    first = C.first_contact_frames(hand, params.min_run)
    window = C.contact_window(first, labels.shape[0], params.t_b, params.t_a)
    return {"hand": hand, "first": first, "window": window}
