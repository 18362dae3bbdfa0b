"""Validate canonical data: the whole file (:func:`validate`) or the part one command uses (:func:`check_sequence`).

Both share one implementation: per-item generators of :class:`Problem` (header, humanoid, object, sequence).
:func:`validate` runs them all and lists every problem; :func:`check_sequence`, the gate every command that
reads a sequence calls before working, runs those of one sequence, its humanoid and its objects and raises an
:class:`~wristmimic.errors.InputError` with the first problem's message.
"""

from __future__ import annotations

import json
import os
import xml.etree.ElementTree as ET
from collections.abc import Iterator
from dataclasses import dataclass
from itertools import chain
from pathlib import Path

import h5py
import numpy as np

from wristmimic.errors import InputError
from wristmimic.format import schema
from wristmimic.format.reader import Dataset, SequenceView, open_dataset
from wristmimic.humanoid.roles import ROLE_NAMES

QUAT_TOL = 1e-3
"""Largest accepted | |q| - 1 | of a stored quaternion."""
WORLD_BOUND_M = 100.0
"""Largest accepted |coordinate| of a world position (root, bodies, objects): capture rooms are well under 100 m
across (the shared OMOMO and ParaHome sequences stay within 2 m of the origin)."""
OBJECT_BOUND_M = 10.0
"""Largest accepted |coordinate| of object-frame geometry (meshes, hulls, surface points, COM)."""
OBJECT_SIZE_M = (0.005, 10.0)
"""Accepted range of an object's size (largest side of its visual mesh's bounding box)."""
MASS_KG = (1e-3, 1e4)
"""Accepted object mass: 1 g to 10 t (inferred static supports are solid boxes of 1000 kg/m^3)."""
DENSITY_KG_M3 = (1.0, 1e5)
"""Accepted object density."""
FRICTION = (0.0, 10.0)
"""Accepted URDF ``lateral_friction``."""
ANGLE_BOUND_RAD = float(np.pi) + QUAT_TOL
"""Largest accepted |joint angle|: the angles are Euler angles of the joint rotation, within [-pi, pi]."""

_WORLD_POSITIONS = ("root_pos", "body_pos", "source_body_pos", "object_pos")


@dataclass(frozen=True)
class Problem:
    """One problem: the key it concerns (``sequences/<sid>/root_pos``) and what is wrong (with what is expected)."""

    key: str
    problem: str

    def __str__(self) -> str:
        return f"{self.key}: {self.problem}"


def _s(v: object) -> str:
    return v.decode() if isinstance(v, bytes) else str(v)


def _nonfinite(where: str, a: np.ndarray, allow_inf: bool = False) -> Iterator[Problem]:
    if a.dtype.kind != "f" or np.isfinite(a.sum(dtype=np.float64)):  # a float64 sum of float32 cannot overflow
        return
    bad = np.isnan(a) if allow_inf else ~np.isfinite(a)
    if bad.any():
        yield Problem(where, f"{int(bad.sum())} non-finite values")


def _beyond(where: str, a: np.ndarray, bound: float, unit: str) -> Iterator[Problem]:
    """Finite values with |x| > bound (non-finite ones are reported by :func:`_nonfinite`)."""
    if a.dtype.kind != "f" or not a.size or (-bound <= a.min() and a.max() <= bound):
        return
    mag = np.abs(a)
    bad = np.isfinite(mag) & (mag > bound)
    if bad.any():
        yield Problem(
            where,
            f"{int(bad.sum())} values with |x| > {bound:g} {unit} (max {mag[bad].max():.3g}; expected |x| <= {bound:g})",
        )


def _quats(where: str, q: np.ndarray) -> Iterator[Problem]:
    n2 = np.einsum("...i,...i->...", q, q)
    if n2.size and (1 - QUAT_TOL) ** 2 <= n2.min() and n2.max() <= (1 + QUAT_TOL) ** 2:
        return
    n = np.linalg.norm(q.astype(np.float64), axis=-1)
    bad = np.abs(n - 1.0) > QUAT_TOL
    if bad.any():
        yield Problem(
            where, f"{int(bad.sum())} quaternions not unit (worst |q| = {n.flat[np.argmax(np.abs(n - 1))]:.4f})"
        )


def _in_range(where: str, what: str, v: float, lo: float, hi: float, unit: str) -> Iterator[Problem]:
    if not (np.isfinite(v) and lo <= v <= hi):
        u = f" {unit}" if unit else ""
        yield Problem(where, f"{what} {v:g}{u} implausible (expected {lo:g} to {hi:g}{u})")


# -- file header ---------------------------------------------------------------------------------------------
def header_problems(ds: Dataset, required: tuple[str, ...] = schema.ROOT_ATTRS) -> Iterator[Problem]:
    """Root attributes: ``required`` present, the conventions (fps, axes, units, quaternion order) as stated."""
    a = ds.h5.attrs
    for k in required:
        if k not in a:
            yield Problem("/", f"attribute {k} missing")
    expect = {"fps": schema.FPS, "up_axis": schema.UP_AXIS, "units": schema.UNITS, "quat_order": schema.QUAT_ORDER}
    for k, v in expect.items():
        if k in a and _s(a[k]) != str(v) and not (k == "fps" and float(a[k]) == float(v)):
            yield Problem("/", f"attribute {k} is {_s(a[k])!r}, expected {v!r}")


# -- humanoids -----------------------------------------------------------------------------------------------
def _mjcf_bodies(mjcf: str, compile_mjcf: bool) -> int:
    """Bodies below the world: MuJoCo's count after compiling, or the ``<body>`` elements of ``<worldbody>``."""
    if compile_mjcf:
        import mujoco

        return mujoco.MjModel.from_xml_string(mjcf).nbody - 1
    return sum(1 for wb in ET.fromstring(mjcf).iter("worldbody") for _ in wb.iter("body"))


def humanoid_problems(ds: Dataset, hid: str, compile_mjcf: bool = True) -> Iterator[Problem]:
    """Body tree, joints, role indices and that the MJCF (compiled, or only parsed when not ``compile_mjcf``: the
    gate leaves compiling to the scene) has the stored body count."""
    where = f"humanoids/{hid}"
    try:
        h = ds.humanoid(hid)
    except (KeyError, OSError) as exc:
        yield Problem(where, f"unreadable ({exc})")
        return
    B = len(h.body_names)
    if (
        h.parents.shape != (B,)
        or B == 0
        or h.parents[0] != -1
        or np.any(h.parents[1:] >= np.arange(1, B))
        or np.any(h.parents[1:] < 0)
    ):
        yield Problem(f"{where}/parents", "not a tree in body order (parent index < body index)")
    if h.joint_bodies.shape != (max(B - 1, 0),):
        yield Problem(f"{where}/joint_bodies", f"shape {h.joint_bodies.shape}, expected ({B - 1},)")
    elif not np.array_equal(np.sort(h.joint_bodies), np.arange(1, B)):
        yield Problem(f"{where}/joint_bodies", f"not every non-root body once (expected distinct indices in [1, {B}))")
    for r in ROLE_NAMES:
        if r not in h.roles:
            yield Problem(f"{where}/roles/{r}", "missing")
        elif h.roles[r].size and (h.roles[r].min() < 0 or h.roles[r].max() >= B):
            yield Problem(f"{where}/roles/{r}", f"body index out of range [0, {B})")
    try:
        nb = _mjcf_bodies(h.mjcf, compile_mjcf)
    except Exception as exc:  # noqa: BLE001 - MuJoCo raises ValueError with the compiler's message
        yield Problem(
            f"{where}/mjcf", f"does not {'compile' if compile_mjcf else 'parse'} ({str(exc).splitlines()[0][:100]})"
        )
    else:
        if nb != B:
            yield Problem(f"{where}/mjcf", f"{nb} bodies, body_names has {B}")


# -- objects -------------------------------------------------------------------------------------------------
def object_problems(ds: Dataset, oid: str) -> Iterator[Problem]:
    """Meshes, hull offsets, finite and plausible geometry, mass, density, inertia, friction."""
    where = f"objects/{oid}"
    try:
        o = ds.object(oid)
    except (KeyError, OSError, ValueError) as exc:
        yield Problem(where, f"unreadable ({exc})")
        return
    V = len(o.vertices)
    if V < 4 or o.faces.size == 0:
        yield Problem(f"{where}/visual", "empty mesh")
    elif o.faces.min() < 0 or o.faces.max() >= V:
        yield Problem(f"{where}/visual/faces", f"index out of range [0, {V})")
    for nm, arr in (
        ("visual/vertices", o.vertices),
        ("hulls/vertices", o.hull_vertices),
        ("surface_points", o.surface_points),
        ("com", o.com),
        ("inertia", o.inertia),
    ):
        a = np.asarray(arr)
        yield from _nonfinite(f"{where}/{nm}", a)
        if nm != "inertia":
            yield from _beyond(f"{where}/{nm}", a, OBJECT_BOUND_M, "m")
    if V and np.isfinite(o.vertices).all():
        size = float((o.vertices.max(axis=0) - o.vertices.min(axis=0)).max())
        yield from _in_range(f"{where}/visual/vertices", "size", size, *OBJECT_SIZE_M, "m")
    vo, fo = o.hull_vertex_offsets, o.hull_face_offsets
    if (
        len(vo) < 2
        or len(vo) != len(fo)
        or vo[0] != 0
        or fo[0] != 0
        or np.any(np.diff(vo) < 4)
        or np.any(np.diff(fo) < 4)
        or vo[-1] != len(o.hull_vertices)
        or fo[-1] != len(o.hull_faces)
    ):
        yield Problem(f"{where}/hulls", "offsets inconsistent or a hull with < 4 vertices/faces")
    else:
        for k in range(len(vo) - 1):
            fk = o.hull_faces[fo[k] : fo[k + 1]]
            if fk.min() < 0 or fk.max() >= vo[k + 1] - vo[k]:
                yield Problem(f"{where}/hulls", f"hull {k} face index out of range")
                break
    if not (np.isfinite(o.mass) and o.mass > 0):
        yield Problem(where, f"mass {o.mass} not positive")
    else:
        yield from _in_range(where, "mass", o.mass, *MASS_KG, "kg")
    yield from _in_range(where, "density", o.density, *DENSITY_KG_M3, "kg/m^3")
    if o.inertia.shape != (3, 3) or not np.allclose(o.inertia, o.inertia.T, atol=1e-9):
        yield Problem(f"{where}/inertia", "not a symmetric 3x3 matrix")
    elif np.isfinite(o.inertia).all():
        ev = np.linalg.eigvalsh(o.inertia)
        if ev.min() < -1e-12:
            yield Problem(f"{where}/inertia", "not positive semi-definite")
        elif ev.max() > ev.sum() - ev.max() + 1e-9 * max(ev.max(), 1e-12):
            yield Problem(f"{where}/inertia", f"principal moments {np.round(ev, 6).tolist()} break A + B >= C")
    if len(o.surface_points) == 0:
        yield Problem(f"{where}/surface_points", "empty")
    friction = o.urdf.get("lateral_friction")
    if friction is not None:
        try:
            mu = float(friction)
        except (TypeError, ValueError):
            mu = float("nan")
        yield from _in_range(f"{where}.urdf", "lateral_friction", mu, *FRICTION, "")


# -- sequences -----------------------------------------------------------------------------------------------
def _contact_problems(where: str, arrays: dict[str, np.ndarray], T: int, meta: dict) -> Iterator[Problem]:
    """First contact frames within the sequence, on a frame with hand contact; the window around the earliest."""
    fcf, win, hand = (arrays.get(f"contacts/{k}") for k in ("first_contact_frame", "window", "hand"))
    if fcf is not None:
        if np.any(fcf < -1) or np.any(fcf >= T):
            yield Problem(f"{where}/contacts/first_contact_frame", f"{fcf.tolist()} outside [-1, {T})")
            return
        if hand is not None:
            off = [h for h in range(2) if fcf[h] >= 0 and not hand[fcf[h], h]]
            if off:
                yield Problem(
                    f"{where}/contacts/first_contact_frame",
                    f"{fcf.tolist()}: no contact of hand {off[0]} at frame {fcf[off[0]]} "
                    "(expected a frame where contacts/hand is set)",
                )
    if win is None:
        return
    if not ((win == -1).all() or (0 <= win[0] <= win[1] < T)):
        yield Problem(f"{where}/contacts/window", f"{win.tolist()} is not [-1, -1] or 0 <= start <= end < {T}")
        return
    if fcf is None:
        return
    have = fcf[fcf >= 0]
    if not len(have):
        if not (win == -1).all():
            yield Problem(f"{where}/contacts/window", f"{win.tolist()} without a first contact (expected [-1, -1])")
        return
    tc = int(have.min())
    t_b, t_a = meta.get("t_b"), meta.get("t_a")
    if isinstance(t_b, int | np.integer) and isinstance(t_a, int | np.integer):
        want = [max(tc - int(t_b), 0), min(tc + int(t_a), T - 1)]
        if win.tolist() != want:
            yield Problem(
                f"{where}/contacts/window",
                f"{win.tolist()}, expected {want} (t_c {tc} - t_b {int(t_b)}, + t_a {int(t_a)}, clipped)",
            )
    elif not win[0] <= tc <= win[1]:
        yield Problem(f"{where}/contacts/window", f"{win.tolist()} does not contain the first contact frame {tc}")


def sequence_ref_problems(ds: Dataset, s: SequenceView, index_frames: int | None = None) -> Iterator[Problem]:
    """Attributes and references: frame count (``index_frames``: /index's), humanoid and objects exist."""
    f, where = ds.h5, f"sequences/{s.id}"
    if index_frames is not None and index_frames != s.num_frames:
        yield Problem(where, f"num_frames {s.num_frames} but index says {index_frames}")
    if s.num_frames < 1:
        yield Problem(where, f"num_frames {s.num_frames} (expected >= 1)")
    if s.humanoid_id not in f["humanoids"]:
        yield Problem(where, f"humanoid_id {s.humanoid_id!r} not in /humanoids")
    for oid in s.object_ids:
        if oid not in f["objects"]:
            yield Problem(where, f"object id {oid!r} not in /objects")


def sequence_array_problems(ds: Dataset, s: SequenceView) -> Iterator[Problem]:
    """Every array: shape, dtype, finite, within range, unit quaternions, labels, first contact frames and
    window (those of a missing humanoid are left to :func:`sequence_ref_problems`)."""
    f, where = ds.h5, f"sequences/{s.id}"
    T, O = s.num_frames, len(s.object_ids)
    if T < 1 or s.humanoid_id not in f["humanoids"]:
        return
    names = f["humanoids"][s.humanoid_id].get("body_names")
    if not isinstance(names, h5py.Dataset) or names.ndim != 1:
        return  # an unreadable humanoid: humanoid_problems says so
    B = names.shape[0]
    sym = {"T": T, "B": B, "J": B - 1, "O": O, "D": 3 * (B - 1)}
    arrays: dict[str, np.ndarray] = {}
    g = f[where]
    for name, (shape, dtype, _unit, _) in (schema.SEQUENCE_ARRAYS | schema.OPTIONAL_SEQUENCE_ARRAYS).items():
        key = f"{where}/{name}"
        d = g.get(name)
        if d is None:
            if name not in schema.OPTIONAL_SEQUENCE_ARRAYS:
                yield Problem(key, "missing")
            continue
        want = tuple(sym[x] if isinstance(x, str) else x for x in shape)
        ok = True
        if not isinstance(d, h5py.Dataset):
            yield Problem(key, "a group, expected a dataset")
            continue
        if d.shape != want:
            yield Problem(key, f"shape {d.shape}, expected {want}")
            ok = False
        if np.dtype(d.dtype) != np.dtype(dtype):
            yield Problem(key, f"dtype {d.dtype}, expected {dtype}")
            ok = False
        if not ok:
            continue
        try:
            arr = d[()]
        except OSError as exc:
            yield Problem(key, f"unreadable ({str(exc).splitlines()[0][:100]})")
            continue
        arrays[name] = arr
        yield from _nonfinite(key, arr, allow_inf=name == "contacts/distance")
        if name in _WORLD_POSITIONS:
            yield from _beyond(key, arr, WORLD_BOUND_M, "m")
        if name == "joint_angles":
            yield from _beyond(key, arr, ANGLE_BOUND_RAD, "rad")
        if name.endswith("quat") and arr.size:
            yield from _quats(key, arr)
        if name == "contacts/distance" and (arr < 0).any():
            yield Problem(key, f"{int((arr < 0).sum())} negative distances")
        if name in ("contacts/labels", "contacts/geometric") and arr.size and not -1 <= arr.min() <= arr.max() <= 1:
            bad = ~np.isin(arr, schema.CONTACT_LABELS)
            if bad.any():
                yield Problem(key, f"{int(bad.sum())} values outside {{-1, 0, 1}}")
    c = g.get("contacts")
    meta = {k: c.attrs[k] for k in ("t_b", "t_a") if k in c.attrs} if isinstance(c, h5py.Group) else {}
    yield from _contact_problems(where, arrays, T, meta)


def sequence_problems(ds: Dataset, sid: str, index_frames: int | None = None) -> Iterator[Problem]:
    """:func:`sequence_ref_problems`, then :func:`sequence_array_problems`."""
    try:
        s = ds.sequence(sid)
    except (KeyError, OSError, json.JSONDecodeError, ValueError) as exc:
        yield Problem(f"sequences/{sid}", f"unreadable attributes ({exc})")
        return
    yield from sequence_ref_problems(ds, s, index_frames)
    yield from sequence_array_problems(ds, s)


# -- the whole file ------------------------------------------------------------------------------------------
def validate(path: str | Path) -> list[str]:
    """Return every problem found in the file (empty list = valid)."""
    try:
        ds = open_dataset(path)
    except InputError as exc:
        return [str(exc)]
    with ds:
        found: list[Problem] = list(header_problems(ds))
        for hid in ds.humanoid_ids:
            found += humanoid_problems(ds, hid)
        for oid in ds.object_ids:
            found += object_problems(ds, oid)
        index = ds.index()
        groups = sorted(ds.h5["sequences"].keys())
        if sorted(r["id"] for r in index) != groups:
            found.append(
                Problem("index/sequence_ids", f"{len(index)} ids do not match the {len(groups)} sequence groups")
            )
        frames_in_index = {r["id"]: r["num_frames"] for r in index}
        for sid in groups:
            found += sequence_problems(ds, sid, frames_in_index.get(sid))
    return [str(p) for p in found]


# -- the gate ------------------------------------------------------------------------------------------------
_PASSED: set[tuple] = set()
"""(file identity, sequence id) of sequences that passed :func:`check_sequence` in this process."""


def _identity(path: Path) -> tuple:
    st = os.stat(path)
    return (str(path.resolve()), st.st_dev, st.st_ino, st.st_size, st.st_mtime_ns)


def check_sequence(ds_or_path: Dataset | str | Path, sequence_id: str) -> None:
    """The gate: check what a command uses of a canonical file (the header's conventions, sequence
    ``sequence_id``, its humanoid and its objects, not the rest of the file) and raise :class:`InputError` with
    the first problem, worded as :func:`validate` words it.

    A sequence that passed is not checked again in this process while the file is unchanged (same inode, size
    and modification time), so a command that opens the file several times (train: run check, environment,
    evaluation environment) pays once."""
    if not isinstance(ds_or_path, Dataset):
        with open_dataset(ds_or_path) as ds:
            check_sequence(ds, sequence_id)
        return
    ds = ds_or_path
    key = (_identity(ds.path), sequence_id)
    if key in _PASSED:
        return
    try:
        seq = ds.sequence(sequence_id)  # InputError naming the known ids
    except (KeyError, OSError, json.JSONDecodeError, ValueError) as exc:
        raise InputError(ds.path, f"sequences/{sequence_id}", f"unreadable attributes ({exc})") from None
    f = ds.h5
    try:  # /index's frame count of this sequence (validate also checks the index against the groups)
        ids = [_s(i) for i in f["index/sequence_ids"][()]]
        frames: int | None = int(f["index/num_frames"][ids.index(sequence_id)])
    except (KeyError, ValueError, IndexError, OSError):
        frames = None
    checks = chain(
        header_problems(ds, required=()),
        sequence_ref_problems(ds, seq, frames),
        humanoid_problems(ds, seq.humanoid_id, compile_mjcf=False) if seq.humanoid_id in f["humanoids"] else (),
        *(object_problems(ds, oid) for oid in seq.object_ids if oid in f["objects"]),
        sequence_array_problems(ds, seq),
    )
    for p in checks:
        raise InputError(ds.path, p.key, p.problem)
    _PASSED.add(key)
