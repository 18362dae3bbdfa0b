"""Write a canonical file with synthetic box-lifting sequences: ``generate(out, seed=0, variants=..., height=1.70)``.

Each variant is one sequence ``synth_<variant>`` of the same generated humanoid
(:mod:`wristmimic.synth.humanoid`), a dynamic box and a static table, with the reference made by inverse
kinematics (:mod:`wristmimic.synth.motion`). Kinematics are stored as in conversion: ``joint_angles`` = the IK
hinge angles, ``joint_quat`` their intrinsic XYZ rotation, body poses by MuJoCo forward kinematics; contact
labels from geometry with the conversion thresholds (:func:`wristmimic.convert.common.geometric_contacts`).
Nothing is read from any data set: every number comes from :mod:`wristmimic.synth.anthropometry`, the
variant's :class:`~wristmimic.synth.motion.MotionSpec` and the seed, and all of them are recorded in the file
(root attribute ``synth``; sequence ``extra``).
"""

from __future__ import annotations

import zlib
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from wristmimic.convert import contacts as C
from wristmimic.convert.common import box_record, contact_summary, geometric_contacts, humanoid_record
from wristmimic.errors import InputError
from wristmimic.format.records import HumanoidRecord, ObjectRecord, SequenceRecord
from wristmimic.format.writer import DatasetWriter
from wristmimic.humanoid.kinematics import FKResult, forward_kinematics, joint_quat_from_hinges
from wristmimic.humanoid.skeleton import Skeleton
from wristmimic.rotations import quat_rotate, quat_to_matrix
from wristmimic.synth.humanoid import SIDES, SynthHumanoid, build_humanoid
from wristmimic.synth.motion import REFERENCE_HEIGHT, Motion, MotionSpec, generate_motion, hand_in_box, scaled

GENERATOR_VERSION = "3"
VARIANTS: dict[str, dict[str, Any]] = {
    "default": {},
    "turn": {
        # tip the box front up by 90 deg about the axis through the palms, put it down on its back face: the
        # hands stay on the faces they hold (a yaw about the vertical put one forearm across the box)
        "turn_axis": "y",
        "turn_deg": -90.0,
        "frames": {"hold": 0, "turn": 45},
        "finger_pitch_deg": 55.0,  # fingers 55 deg down at the grasp, 35 deg up after the turn
        "grip": (0.06, 0.0),  # palms as far forward as the fingertips allow: higher on the turned box
        "retract_pull": 1.0,  # the wrists end the put-down at their range: no posture snap on release
        "clearance_margin": 0.004,  # arms 4 mm off the box in the IK (2 mm left +0.5 mm measured while it turns)
    },
    "small_box": {"box_size": (0.20, 0.22, 0.15)},
    "high_table": {"table_height": 0.90},
}
"""Variant name -> MotionSpec overrides (``frames`` entries update the default phase lengths)."""
TEXT = {
    "default": "lift a box off the table with both hands and put it back down",
    "turn": "lift a box off the table with both hands, tip it 90 degrees towards you and put it down on its back",
    "small_box": "lift a small box off the table with both hands and put it back down",
    "high_table": "lift a box off a high table with both hands and put it back down",
}
JITTER = {"box_dx": 0.015, "box_dy": 0.015, "box_yaw_deg": 5.0, "lift": 0.02}
"""Seeded uniform jitter (+-) of each variant: box position and yaw on the table, lift height."""
SURFACE_POINTS = 1024
SURFACE_SEED = 2024


def variant_spec(name: str, seed: int = 0, height: float = REFERENCE_HEIGHT) -> MotionSpec:
    """The MotionSpec of a variant for a stature, with the seeded jitter applied."""
    if name not in VARIANTS:
        raise InputError(None, "variant", f"unknown synthetic variant {name!r}", f"one of {', '.join(VARIANTS)}")
    over = dict(VARIANTS[name])
    base = MotionSpec()
    if "frames" in over:
        over["frames"] = {**base.frames, **over["frames"]}
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), zlib.crc32(name.encode())]))
    j = rng.uniform(-1.0, 1.0, 4)
    spec = scaled(replace(base, **over), height)
    return replace(
        spec,
        box_offset=(j[0] * JITTER["box_dx"], j[1] * JITTER["box_dy"], j[2] * JITTER["box_yaw_deg"]),
        lift=spec.lift + j[3] * JITTER["lift"],
    )


def box_object(
    name: str, size: tuple[float, float, float], density: float, *, static: bool, extra: dict | None = None
) -> ObjectRecord:
    """A solid box centred at its frame's origin: mesh, one hull (itself), mass, inertia, surface samples."""
    return box_record(
        name,
        size,
        density,
        static=static,
        inferred=False,
        n_surface=SURFACE_POINTS,
        surface_seed=SURFACE_SEED,
        source_file="wristmimic-synth",
        extra=extra,
    )


def contact_mesh(box: ObjectRecord) -> tuple[np.ndarray, np.ndarray]:
    """The box mesh used for contact labels: the stored mesh without its bottom face.

    The bottom rests on the table and is never touched by the humanoid. Leaving it out makes the mesh open, so
    :func:`wristmimic.convert.contacts.body_object_distance` reports plain surface distances: its inside test
    for closed meshes (the sign of the nearest surface sample's normal) calls points that lie just outside a
    face but closest to a sample on the adjacent face "inside" (distance 0), e.g. fingers passing 5-9 cm from
    the box's edges during the reach.
    """
    v, f = np.asarray(box.vertices), np.asarray(box.faces)
    bottom = np.all(np.isclose(v[f][:, :, 2], v[:, 2].min()), axis=1)
    return v, f[~bottom]


def _object_ids(spec: MotionSpec) -> tuple[str, str]:
    box = (
        "box"
        if tuple(spec.box_size) == MotionSpec().box_size
        else "box_" + "x".join(f"{s * 100:.0f}" for s in spec.box_size)
    )
    table = "table" if spec.table_height == MotionSpec().table_height else f"table_{spec.table_height * 100:.0f}cm"
    return box, table


def box_clearance(
    skel: Skeleton,
    fk: FKResult,
    center: np.ndarray,
    half: np.ndarray,
    spacing: float = 0.01,
    quat: np.ndarray | None = None,
) -> np.ndarray:
    """(T, B) signed distance (m, < 0 inside) of each body's geom surface points to a box (exact box SDF): the
    static table (``center`` (3,), axis-aligned) or the moving box (``center`` (T, 3), ``quat`` (T, 4) wxyz)."""
    pts, gidx = C.geom_surface_points(skel.model, spacing)
    body = skel.model.geom_bodyid[gidx] - 1
    T = fk.geom_pos.shape[0]
    center = np.broadcast_to(np.asarray(center, dtype=float), (T, 3))
    inv = None if quat is None else np.asarray(quat, dtype=float) * np.array([1.0, -1.0, -1.0, -1.0])
    out = np.full((T, skel.num_bodies), np.inf)
    for t0 in range(0, T, 16):  # frame chunks bound the memory
        sl = slice(t0, min(t0 + 16, T))
        world = fk.geom_pos[sl, gidx] + np.einsum("tpij,pj->tpi", fk.geom_mat[sl, gidx], pts) - center[sl, None]
        if inv is not None:  # into the box frame
            world = quat_rotate(np.broadcast_to(inv[sl, None], (*world.shape[:2], 4)), world)
        q = np.abs(world) - half
        sdf = np.linalg.norm(np.maximum(q, 0.0), axis=-1) + np.minimum(q.max(axis=-1), 0.0)  # (t, P)
        for b in np.unique(body):
            out[sl, b] = sdf[:, body == b].min(axis=1)
    return out


def quality(
    skel: Skeleton,
    humanoid: SynthHumanoid,
    spec: MotionSpec,
    motion: Motion,
    table: ObjectRecord,
    labels: np.ndarray,
    roles: dict[str, np.ndarray],
) -> dict[str, Any]:
    """Measured properties of a generated sequence (stored in the sequence's ``extra``)."""
    params = C.ContactParams()
    fk = forward_kinematics(skel.model, motion.qpos, geoms=True)
    T = len(motion.qpos)
    held = motion.held
    # palm point relative to the face plane it holds (box frame), while the box is held
    gaps = {}
    qinv = motion.box_quat * np.array([1.0, -1.0, -1.0, -1.0])
    for s, y in SIDES:
        w = skel.index(f"{s}_Wrist")
        palm = fk.body_pos[:, w] + quat_rotate(fk.body_quat[:, w], humanoid.palm_point[s])
        local = quat_rotate(qinv, palm - motion.box_pos)  # box frame; the hand holds the face at y = +-width/2
        gaps[s] = (y * local[:, 1] - spec.box_size[1] / 2)[held]
    feet_z = C.body_lowest_z(skel.model, motion.qpos, roles["feet"], params, fk=fk)
    ang = motion.qpos[:, skel.hinge_qposadr.reshape(-1)]
    speed = np.abs(np.diff(ang, axis=0)) * 30.0
    fingers = np.isin(np.repeat(skel.joint_bodies, 3), roles["fingers"])
    acc = np.linalg.norm(np.diff(fk.body_pos, n=2, axis=0), axis=-1) * 30.0**2 if T > 2 else np.zeros((1, 1))
    non_finger = roles["non_finger"]
    table_d = box_clearance(skel, fk, motion.table_pos, np.asarray([*spec.table_size, spec.table_height]) / 2)
    arms = [skel.index(f"{s}_{k}") for s, _ in SIDES for k in ("Shoulder", "Elbow")]
    arm_d = box_clearance(skel, fk, motion.box_pos, np.asarray(spec.box_size) / 2, 0.005, motion.box_quat)[:, arms]
    half_z = np.abs(quat_to_matrix(motion.box_quat)[:, 2]) @ (np.asarray(spec.box_size) / 2)  # turned box
    box_bottom = motion.box_pos[:, 2] - half_z
    hand_flags = C.hand_contact(labels, roles["left_hand"], roles["right_hand"])
    res = {k: float(np.nanmax(v)) for k, v in motion.residuals.items()}
    return {
        "palm_face_gap_hold_m": {s: [float(g.min()), float(g.max())] for s, g in gaps.items()},
        "hand_contact_fraction_hold": [float(x) for x in hand_flags[held].mean(axis=0)],
        "feet_lowest_z_m": [float(feet_z.min()), float(feet_z.max())],
        "max_joint_speed_rad_s": float(speed[:, ~fingers].max()) if len(speed) else 0.0,
        "max_finger_speed_rad_s": float(speed[:, fingers].max()) if len(speed) else 0.0,
        "max_body_acc_m_s2": float(acc[:, non_finger].max()),
        "table_clearance_m": float(table_d.min()),
        "arm_box_clearance_m": float(arm_d.min()),
        "box_bottom_minus_table_m": {
            "start": float(box_bottom[0] - spec.table_height),
            "end": float(box_bottom[-1] - spec.table_height),
            "max": float(box_bottom.max() - spec.table_height),
        },
        "ik_residual_max": res,
    }


def make_sequence(
    variant: str,
    seed: int,
    spec: MotionSpec,
    humanoid: SynthHumanoid,
    hid: str,
    hrec: HumanoidRecord,
    skel: Skeleton,
) -> tuple[SequenceRecord, dict[str, ObjectRecord], dict[str, Any]]:
    """One sequence and its objects (box, table)."""
    motion = generate_motion(skel, humanoid, spec)
    T = len(motion.qpos)
    box_id, table_id = _object_ids(spec)
    box = box_object(box_id, spec.box_size, spec.box_density, static=False)
    table = box_object(table_id, (*spec.table_size, spec.table_height), 1000.0, static=True, extra={"kind": "table"})
    angles = motion.qpos[:, skel.hinge_qposadr.reshape(-1)].reshape(T, skel.num_joints, 3)
    jq = joint_quat_from_hinges(angles)
    fk = forward_kinematics(skel.model, motion.qpos)
    params = C.ContactParams()
    dist, labels = geometric_contacts(
        skel, hrec.roles, motion.qpos, [contact_mesh(box)], motion.box_pos[:, None], motion.box_quat[:, None], params
    )
    summ = contact_summary(labels, hrec.roles, params)
    obj_pos = np.stack([motion.box_pos, np.broadcast_to(motion.table_pos, (T, 3))], axis=1)
    obj_quat = np.stack([motion.box_quat, np.broadcast_to(np.array([1.0, 0, 0, 0]), (T, 4))], axis=1)
    q = quality(skel, humanoid, spec, motion, table, labels, hrec.roles)
    pre_l, _ = hand_in_box(spec, humanoid, "L", spec.pregrasp_gap)
    seq = SequenceRecord(
        humanoid_id=hid,
        object_ids=[box_id, table_id],
        subject=hid,
        dataset="synthetic",
        root_pos=motion.qpos[:, 0:3],
        root_quat=motion.qpos[:, 3:7],
        joint_quat=jq,
        joint_angles=angles,
        body_pos=fk.body_pos,
        body_quat=fk.body_quat,
        source_body_pos=fk.body_pos,
        source_body_pos_valid=np.ones(skel.num_bodies, bool),
        object_pos=obj_pos,
        object_quat=obj_quat,
        contact_labels=labels,
        contact_geometric=labels,
        contact_distance=dist,
        hand_contact=summ["hand"],
        object_contact=summ["hand"].any(axis=1),
        first_contact_frame=summ["first"],
        contact_window=summ["window"],
        contact_meta={
            "labels_method": "geometry: humanoid geom surface points vs object surface samples (KD-tree); "
            "box mesh without its bottom face (never touched)",
            "geometric_method": "same as labels",
            "params": params.to_dict(),
            "t_b": params.t_b,
            "t_a": params.t_a,
        },
        text=TEXT.get(variant, variant),
        source_file="wristmimic-synth",
        extra={
            "variant": variant,
            "seed": int(seed),
            "generator_version": GENERATOR_VERSION,
            "spec": spec.to_dict(),
            "phases": [{"phase": p, "start": s, "frames": n} for p, s, n in motion.phases],
            "box_mass_kg": box.mass,
            "pregrasp_palm_in_box_m": pre_l.tolist(),
            "quality": q,
        },
    )
    return seq, {box_id: box, table_id: table}, q


def generate(
    out: str | Path, *, seed: int = 0, variants: tuple[str, ...] | list[str] = ("default",), height: float = 1.70
) -> Path:
    """Write the synthetic sequences ``synth_<variant>`` to ``out`` (atomic) and return its path."""
    variants = list(dict.fromkeys(variants))
    if not variants:
        raise InputError(None, "variants", "none given", f"one or more of {', '.join(VARIANTS)}")
    if not 1.2 <= float(height) <= 2.2:
        raise InputError(None, "height", f"{height} m", "a stature between 1.2 and 2.2 m")
    specs = {v: variant_spec(v, seed, height) for v in variants}  # raises on an unknown name before writing
    humanoid = build_humanoid(height)
    hid = f"synth_h{round(height * 100):d}"
    hrec, skel = humanoid_record(humanoid.mjcf, hid, f"wristmimic-synth (stature {height:.3f} m)")
    attrs = {
        "synth": {
            "generator_version": GENERATOR_VERSION,
            "seed": int(seed),
            "height_m": float(height),
            "variants": variants,
            "jitter": JITTER,
            "anthropometry": humanoid.anthropometry.to_dict(),
            "specs": {v: s.to_dict() for v, s in specs.items()},
        }
    }
    out = Path(out)
    with DatasetWriter(
        out,
        source_dataset="synthetic",
        source_format="wristmimic-synth",
        converter="wristmimic-synth",
        input_sha256={},
        extra_attrs=attrs,
    ) as w:
        w.add_humanoid(hid, hrec)
        for v in variants:
            seq, objs, _q = make_sequence(v, seed, specs[v], humanoid, hid, hrec, skel)
            for oid, rec in objs.items():
                if not w.has_object(oid):
                    w.add_object(oid, rec)
            w.add_sequence(f"synth_{v}", seq)
    return out
