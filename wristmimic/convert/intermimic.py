"""InterMimic / InterAct ``.pt`` files (OMOMO) -> canonical HDF5.

Source layout (like ``../shared/data/intermimic_omomo``)::

    SRC/omomo.xml                      SMPL-X humanoid (52 bodies, 51 x 3 hinges), Isaac Gym MJCF
    SRC/motions/<seq>.pt               float32 (T, 591) tensors, 30 fps, Z-up, quaternions xyzw
    SRC/objects/<obj>.urdf             + SRC/objects/<obj>/<obj>.obj

Every one of the 591 columns is mapped or verified unused (:data:`COLUMNS`). Joint rotations are derived
from the global body quaternions (cols 383:591) as ``parent^-1 * child`` and decomposed into intrinsic XYZ
Euler angles for the x, y, z hinges, so that MuJoCo FK of the embedded humanoid reproduces the stored body
rotations exactly (the stored exp-maps, cols 9:162, equal these local rotations and are checked, but fed
straight to hinges they are 5-7 cm off at the wrists). Finger slots of the stored positions (cols 162:318)
do not follow the body order, so body positions come from FK; the source positions are kept with a
validity mask (non-finger slots).

The shipped ``omomo.xml`` is one generic body, but the stored positions are FK of a skeleton generated per
subject. By default each subject gets its own humanoid (``<xml stem>_<subject>``): bone offsets read back from
the stored positions (:mod:`wristmimic.humanoid.fit`; FK then matches them to 0.01 mm) and foot boxes deepened
so that the lowest foot point over each sequence's first 30 frames is on the floor (InterAct's floor rule; the
subjects wear shoes). With the generic body, sub2's feet float 8-11 cm and its hands sit 4 cm off the object.
"""

from __future__ import annotations

import re
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from wristmimic.convert.common import (
    ConvertOptions,
    ConvertReport,
    contact_summary,
    geometric_contacts,
    humanoid_record,
    kinematics,
    write_objects,
)
from wristmimic.convert.contacts import label_agreement
from wristmimic.convert.progress import progress_bar
from wristmimic.errors import InputError
from wristmimic.format.records import SequenceRecord
from wristmimic.format.writer import DatasetWriter
from wristmimic.humanoid.fit import FIT_TOL_M, fit_offsets, lowest_foot_height, refit_mjcf, thicken_feet
from wristmimic.humanoid.kinematics import hinge_angles, local_from_global, qpos_from
from wristmimic.humanoid.skeleton import Skeleton
from wristmimic.rotations import quat_angle, quat_normalize, rotvec_to_quat, xyzw_to_wxyz
from wristmimic.safe_io import load_pt_tensor, sha256_file

NUM_COLUMNS = 591
NUM_BODIES = 52
COLUMNS: dict[str, tuple[int, int, str]] = {
    "root_pos": (0, 3, "root (pelvis) position, world, m -> root_pos; equals cols 162:165"),
    "root_quat": (3, 7, "root quaternion xyzw -> root_quat (wxyz); equals cols 383:387"),
    "unused_7_9": (7, 9, "unused: verified all zero"),
    "dof_expmap": (9, 162, "51 x 3 exp-maps of the local joint rotations: verified equal to the derived joint_quat"),
    "body_pos": (162, 318, "52 x 3 body positions -> source_body_pos (finger slots unreliable: mask false)"),
    "object_pos": (318, 321, "object position -> object_pos"),
    "object_quat": (321, 325, "object quaternion xyzw -> object_quat (wxyz)"),
    "unused_325_330": (325, 330, "unused: verified all zero"),
    "object_contact": (330, 331, "object-level contact flag {0,1} -> contacts/object"),
    "body_contact": (331, 383, "52 per-body labels {-1,0,1} -> contacts/labels"),
    "body_quat": (383, 591, "52 x 4 global body quaternions xyzw -> body_quat (wxyz)"),
}
EXPMAP_TOL_DEG = 0.5
FLOOR_FRAMES = 30
"""InterAct puts the lowest body vertex over a sequence's first 30 frames on the floor."""
FOOT_TOL_M, FOOT_ITERATIONS = 1e-4, 6
"""Feet are deepened until their lowest point over those frames is within this of the floor (at most this often)."""
_SEQ_RE = re.compile(r"^(?P<subject>sub\d+)_(?P<object>[a-z]+)_(?P<num>\d+)$")


@dataclass
class IntermimicSource:
    """Where the pieces of an InterMimic-layout folder are."""

    root: Path
    humanoid: Path
    motions: list[Path]
    objects_dir: Path


def discover(src: Path, humanoid: Path | None = None, sequences: list[str] | None = None) -> IntermimicSource:
    """Find the humanoid, motion files and objects folder of an InterMimic-layout folder."""
    src = Path(src)
    if not src.is_dir():
        raise InputError(src, None, "not a folder", "a folder with motions/, objects/ and a humanoid .xml")
    if humanoid is None:
        xmls = sorted(src.glob("*.xml"))
        if len(xmls) != 1:
            raise InputError(src, "*.xml", f"found {len(xmls)} humanoid MJCF files", "exactly one (or --humanoid)")
        humanoid = xmls[0]
    if not Path(humanoid).is_file():
        raise InputError(humanoid, None, "humanoid MJCF not found")
    motions = sorted((src / "motions").glob("*.pt"))
    if not motions:
        raise InputError(src / "motions", "*.pt", "no motion files", "InterMimic (T, 591) .pt tensors")
    if sequences:
        by_stem = {m.stem: m for m in motions}
        missing = [s for s in sequences if s not in by_stem]
        if missing:
            raise InputError(src / "motions", missing[0], "no such sequence", f"one of {sorted(by_stem)[:6]}...")
        motions = [by_stem[s] for s in sequences]
    objects_dir = src / "objects"
    if not objects_dir.is_dir():
        raise InputError(objects_dir, None, "objects folder missing", "objects/<name>.urdf and meshes")
    return IntermimicSource(src, Path(humanoid), motions, objects_dir)


def parse_sequence_name(stem: str) -> tuple[str, str]:
    """``sub2_largetable_000`` -> (subject ``sub2``, object ``largetable``)."""
    m = _SEQ_RE.match(stem)
    if not m:
        raise InputError(
            stem + ".pt",
            "file name",
            "cannot read subject and object from the name",
            "sub<N>_<object>_<NNN>.pt (or pass --object)",
        )
    return m["subject"], m["object"]


def read_motion(path: Path) -> np.ndarray:
    """Load and check one (T, 591) InterMimic motion tensor (float64)."""
    data = load_pt_tensor(path)
    if data.shape[1] != NUM_COLUMNS or data.shape[0] < 2:
        raise InputError(path, "<tensor>", f"shape {data.shape}", f"(T >= 2, {NUM_COLUMNS}) InterMimic columns")
    for name in ("unused_7_9", "unused_325_330"):
        a, b, _ = COLUMNS[name]
        if np.any(data[:, a:b] != 0):
            raise InputError(
                path,
                f"columns {a}:{b}",
                "non-zero values in columns InterMimic leaves unused",
                "zeros (is this an InterMimic OMOMO file?)",
            )
    lab = data[:, 331:383]
    if not np.isin(lab, (-1.0, 0.0, 1.0)).all():
        raise InputError(path, "columns 331:383", "contact labels outside {-1, 0, 1}", "{-1, 0, 1}")
    if not np.isin(data[:, 330], (0.0, 1.0)).all():
        raise InputError(path, "column 330", "object contact flag outside {0, 1}", "{0, 1}")
    for a, b, key in ((3, 7, "columns 3:7"), (321, 325, "columns 321:325")):
        n = np.linalg.norm(data[:, a:b], axis=-1)
        if np.any(np.abs(n - 1) > 1e-3):
            raise InputError(path, key, f"quaternion norm {n.min():.3f}..{n.max():.3f}", "unit quaternions")
    return data


def convert_intermimic(
    src: str | Path,
    out: str | Path,
    *,
    sequences: list[str] | None = None,
    humanoid: str | Path | None = None,
    object_name: str | None = None,
    options: ConvertOptions | None = None,
    fit_subjects: bool = True,
) -> ConvertReport:
    """Convert an InterMimic-layout folder into one canonical file at ``out`` (atomic). ``fit_subjects``: one
    humanoid per subject fitted to the stored body positions (else the MJCF as shipped for every sequence)."""
    opts = options or ConvertOptions()
    source = discover(Path(src), Path(humanoid) if humanoid else None, sequences)
    report = ConvertReport(Path(out))
    mjcf = source.humanoid.read_text()
    hid = source.humanoid.stem
    hrec, skel = humanoid_record(mjcf, hid, source.humanoid.name)
    if skel.num_bodies != NUM_BODIES:
        raise InputError(source.humanoid, "bodies", f"{skel.num_bodies} bodies", f"{NUM_BODIES} (SMPL-X)")
    roles = hrec.roles
    valid = np.ones(NUM_BODIES, bool)
    valid[roles["fingers"]] = False

    # read every motion first: bad input fails before any expensive work
    motions = {p.stem: read_motion(p) for p in source.motions}
    paths = {p.stem: p for p in source.motions}
    obj_names = {s: object_name or parse_sequence_name(s)[1] for s in motions}
    inputs = {str(p.relative_to(source.root)): sha256_file(p) for p in [source.humanoid, *source.motions]}
    humans: dict[str, tuple[str, object, Skeleton]] = {}  # sequence -> (humanoid id, record, skeleton)
    if fit_subjects:
        # a subject's humanoid is fitted to all of its motion files in the folder, whichever were selected
        subjects = {_subject(sid) for sid in motions}
        fit_paths = {p.stem: p for p in sorted((source.root / "motions").glob("*.pt")) if _subject(p.stem) in subjects}
        fit_motions = {s: motions[s] if s in motions else read_motion(p) for s, p in fit_paths.items()}
        inputs |= {str(p.relative_to(source.root)): sha256_file(p) for p in fit_paths.values() if p.stem not in motions}
        by_subject: dict[str, list[str]] = {}
        for sid in fit_motions:
            by_subject.setdefault(_subject(sid), []).append(sid)
        for subj, sids in by_subject.items():
            sub_id = f"{hid}_{subj}" if subj else hid
            sub = subject_humanoid(mjcf, skel, roles, {s: fit_motions[s] for s in sids}, fit_paths)
            srec, sskel = humanoid_record(sub.mjcf, sub_id, f"{source.humanoid.name} {sub.note}")
            humans.update({s: (sub_id, srec, sskel) for s in sids if s in motions})
    else:
        humans = {s: (hid, hrec, skel) for s in motions}

    with (
        DatasetWriter(
            out, source_dataset="omomo", source_format="intermimic-pt", converter="intermimic", input_sha256=inputs
        ) as w,
        progress_bar(opts.show_progress) as bar,
    ):
        for h_id, h_rec, _ in {h[0]: h for h in humans.values()}.values():
            w.add_humanoid(h_id, h_rec)
        # the manipulated object moves: dynamic whatever its name
        assets = write_objects(
            w, sorted(set(obj_names.values())), source.objects_dir, source.root, opts, report, inputs, bar, static=False
        )
        task = bar.add_task("sequences", total=len(motions))
        for sid, data in motions.items():
            t0 = time.perf_counter()
            h_id, h_rec, h_skel = humans[sid]
            rec = _sequence(sid, data, paths[sid], h_skel, h_rec.roles, valid, assets[obj_names[sid]], h_id, opts)
            w.add_sequence(sid, rec)
            report.sequences.append(sid)
            report.seconds_per_sequence[sid] = time.perf_counter() - t0
            report.fk_rotation_error_deg[sid] = rec.extra["fk_rotation_error_deg"]
            bar.advance(task)
        w.set_attr("input_sha256", inputs)
    return report


def _subject(sid: str) -> str:
    m = _SEQ_RE.match(sid)
    return m["subject"] if m else ""


@dataclass
class SubjectHumanoid:
    """A humanoid fitted to one subject's sequences."""

    mjcf: str
    offsets: np.ndarray
    """(B, 3) bone offsets (m) in the parent frame."""
    spread_m: float
    """Largest spread of a fitted bone over all frames (m)."""
    foot_depth_m: float
    """How far the foot boxes were deepened (m)."""

    @property
    def note(self) -> str:
        return (
            f"(bone offsets fitted to the body positions, columns 162:318; spread {1000 * self.spread_m:.3f} mm; "
            f"foot boxes +{1000 * self.foot_depth_m:.1f} mm)"
        )


def _body_quat(data: np.ndarray) -> np.ndarray:
    return quat_normalize(xyzw_to_wxyz(data[:, 383:591].reshape(len(data), NUM_BODIES, 4)))


def subject_humanoid(
    mjcf: str, skel: Skeleton, roles: dict, motions: dict[str, np.ndarray], paths: dict[str, Path]
) -> SubjectHumanoid:
    """The generic ``mjcf`` with bone offsets read from the stored positions of one subject's ``motions`` and feet
    deepened to the floor over each sequence's first :data:`FLOOR_FRAMES` frames."""
    valid = np.ones(NUM_BODIES, bool)
    valid[roles["fingers"]] = False
    pos = np.concatenate([d[:, 162:318].reshape(len(d), NUM_BODIES, 3) for d in motions.values()])
    quat = np.concatenate([_body_quat(d) for d in motions.values()])
    offsets, spread = fit_offsets(skel, pos, quat, valid)
    offsets = np.round(offsets, 6)  # micrometres: the same humanoid whichever frames were averaged
    if spread.max() > FIT_TOL_M:
        b = int(spread.argmax())
        raise InputError(
            paths[next(iter(motions))],
            "columns 162:318",
            f"body positions are not forward kinematics of one skeleton (bone {skel.body_names[b]} varies "
            f"{1000 * spread[b]:.1f} mm over frames)",
            f"bone offsets constant to {1000 * FIT_TOL_M:g} mm (or convert with --generic-humanoid)",
        )
    fitted = refit_mjcf(mjcf, skel, offsets)
    feet = [skel.body_names[b] for b in roles["feet"]]
    poses = []
    for d in motions.values():
        head = d[:FLOOR_FRAMES]
        bq = _body_quat(head)
        poses.append(qpos_from(skel, head[:, 0:3], bq[:, 0], hinge_angles(local_from_global(skel, bq))))
    depth = 0.0
    for _ in range(FOOT_ITERATIONS):  # a tilted foot reaches down less than its box grows: repeat
        low = min(lowest_foot_height(fitted, q, feet) for q in poses)
        if low <= FOOT_TOL_M:
            break
        fitted, depth = thicken_feet(fitted, feet, low), depth + low
    return SubjectHumanoid(fitted, offsets, float(spread.max()), depth)


def _sequence(
    sid: str, data: np.ndarray, path: Path, skel, roles, valid: np.ndarray, asset, hid: str, opts: ConvertOptions
) -> SequenceRecord:
    T = data.shape[0]
    body_quat = _body_quat(data)
    root_pos = data[:, 0:3]
    root_quat = quat_normalize(xyzw_to_wxyz(data[:, 3:7]))
    if np.degrees(quat_angle(root_quat, body_quat[:, 0])).max() > EXPMAP_TOL_DEG:
        raise InputError(path, "columns 3:7", "root quaternion differs from body 0 quaternion (cols 383:387)")
    joint_quat = local_from_global(skel, body_quat)
    expmap_err = float(np.degrees(quat_angle(joint_quat, rotvec_to_quat(data[:, 9:162].reshape(T, 51, 3)))).max())
    if expmap_err > EXPMAP_TOL_DEG:
        raise InputError(
            path,
            "columns 9:162",
            f"exp-maps are {expmap_err:.2f} deg off the rotations in 383:591",
            "the local rotations of the stored body quaternions",
        )
    kin = kinematics(skel, root_pos, root_quat, joint_quat, body_quat, str(path))
    obj_pos = data[:, None, 318:321]
    obj_quat = quat_normalize(xyzw_to_wxyz(data[:, None, 321:325]))
    dist, geo = geometric_contacts(
        skel, roles, kin.qpos, [(asset.vertices, asset.faces)], obj_pos, obj_quat, opts.contact
    )
    shipped = data[:, 331:383].astype(np.int8)
    summ = contact_summary(shipped, roles, opts.contact)
    subject = _subject(sid)
    agree = label_agreement(geo, shipped)
    agree_hands = label_agreement(geo, shipped, np.concatenate([roles["left_hand"], roles["right_hand"]]))
    return SequenceRecord(
        humanoid_id=hid,
        object_ids=[asset.name],
        subject=subject,
        dataset="omomo",
        root_pos=root_pos,
        root_quat=root_quat,
        joint_quat=joint_quat,
        joint_angles=kin.joint_angles,
        body_pos=kin.body_pos,
        body_quat=body_quat,
        source_body_pos=data[:, 162:318].reshape(T, NUM_BODIES, 3),
        source_body_pos_valid=valid,
        object_pos=obj_pos,
        object_quat=obj_quat,
        contact_labels=shipped,
        contact_geometric=geo,
        contact_distance=dist,
        hand_contact=summ["hand"],
        object_contact=data[:, 330] > 0.5,
        first_contact_frame=summ["first"],
        contact_window=summ["window"],
        contact_meta={
            "labels_method": "source:intermimic (InterAct SMPL-X surface recipe)",
            "geometric_method": "humanoid geom surface points vs object surface samples (KD-tree)",
            "params": opts.contact.to_dict(),
            "t_b": opts.contact.t_b,
            "t_a": opts.contact.t_a,
            "agreement_geometric_vs_labels": agree,
            "agreement_hands": agree_hands,
        },
        source_file=str(path.name),
        extra={"fk_rotation_error_deg": kin.fk_rotation_error_deg, "expmap_vs_joint_quat_deg": expmap_err},
    )
