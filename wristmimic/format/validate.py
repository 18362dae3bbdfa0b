"""Validate a canonical file against the schema; every problem is collected, none stops the check."""

from __future__ import annotations

import json
from pathlib import Path

import h5py
import numpy as np

from wristmimic.errors import InputError
from wristmimic.format import schema
from wristmimic.format.reader import open_dataset
from wristmimic.humanoid.roles import ROLE_NAMES

QUAT_TOL = 1e-3


def _s(v: object) -> str:
    return v.decode() if isinstance(v, bytes) else str(v)


def _check_shape(problems: list[str], where: str, name: str, d: h5py.Dataset, sym: dict[str, int]) -> bool:
    shape, dtype, _unit, _ = schema.SEQUENCE_ARRAYS[name]
    want = tuple(sym[s] if isinstance(s, str) else s for s in shape)
    ok = True
    if d.shape != want:
        problems.append(f"{where}: shape {d.shape}, expected {want}")
        ok = False
    if np.dtype(d.dtype) != np.dtype(dtype):
        problems.append(f"{where}: dtype {d.dtype}, expected {dtype}")
        ok = False
    return ok


def _check_quats(problems: list[str], where: str, q: np.ndarray) -> None:
    n = np.linalg.norm(q.astype(np.float64), axis=-1)
    bad = np.abs(n - 1.0) > QUAT_TOL
    if bad.any():
        problems.append(
            f"{where}: {int(bad.sum())} quaternions not unit (worst |q| = {n.flat[np.argmax(np.abs(n - 1))]:.4f})"
        )


def _check_finite(problems: list[str], where: str, a: np.ndarray, allow_inf: bool = False) -> None:
    if a.dtype.kind != "f":
        return
    bad = np.isnan(a) if allow_inf else ~np.isfinite(a)
    if bad.any():
        problems.append(f"{where}: {int(bad.sum())} non-finite values")


def validate(path: str | Path) -> list[str]:
    """Return every problem found in the file (empty list = valid)."""
    try:
        ds = open_dataset(path)
    except InputError as exc:
        return [str(exc)]
    problems: list[str] = []
    with ds:
        f = ds.h5
        a = f.attrs
        for k in schema.ROOT_ATTRS:
            if k not in a:
                problems.append(f"/: attribute {k} missing")
        expect = {"fps": schema.FPS, "up_axis": schema.UP_AXIS, "units": schema.UNITS, "quat_order": schema.QUAT_ORDER}
        for k, v in expect.items():
            if k in a and _s(a[k]) != str(v) and not (k == "fps" and float(a[k]) == float(v)):
                problems.append(f"/: attribute {k} is {_s(a[k])!r}, expected {v!r}")

        humanoid_bodies: dict[str, int] = {}
        for hid in ds.humanoid_ids:
            g = f["humanoids"][hid]
            where = f"humanoids/{hid}"
            try:
                h = ds.humanoid(hid)
            except (KeyError, OSError) as exc:
                problems.append(f"{where}: unreadable ({exc})")
                continue
            B = len(h.body_names)
            humanoid_bodies[hid] = B
            if (
                h.parents.shape != (B,)
                or h.parents[0] != -1
                or np.any(h.parents[1:] >= np.arange(1, B))
                or np.any(h.parents[1:] < 0)
            ):
                problems.append(f"{where}/parents: not a tree in body order (parent index < body index)")
            if h.joint_bodies.shape != (B - 1,):
                problems.append(f"{where}/joint_bodies: shape {h.joint_bodies.shape}, expected ({B - 1},)")
            for r in ROLE_NAMES:
                if r not in h.roles:
                    problems.append(f"{where}/roles/{r}: missing")
                elif h.roles[r].size and (h.roles[r].min() < 0 or h.roles[r].max() >= B):
                    problems.append(f"{where}/roles/{r}: body index out of range [0, {B})")
            if "mjcf" in g:
                try:
                    import mujoco

                    m = mujoco.MjModel.from_xml_string(h.mjcf)
                    if m.nbody - 1 != B:
                        problems.append(f"{where}/mjcf: {m.nbody - 1} bodies, body_names has {B}")
                except Exception as exc:  # noqa: BLE001
                    problems.append(f"{where}/mjcf: does not compile ({str(exc).splitlines()[0][:100]})")

        for oid in ds.object_ids:
            where = f"objects/{oid}"
            try:
                o = ds.object(oid)
            except (KeyError, OSError) as exc:
                problems.append(f"{where}: unreadable ({exc})")
                continue
            V = len(o.vertices)
            if V < 4 or o.faces.size == 0:
                problems.append(f"{where}/visual: empty mesh")
            elif o.faces.min() < 0 or o.faces.max() >= V:
                problems.append(f"{where}/visual/faces: index out of range [0, {V})")
            for nm, arr in (
                ("visual/vertices", o.vertices),
                ("hulls/vertices", o.hull_vertices),
                ("surface_points", o.surface_points),
                ("com", o.com),
                ("inertia", o.inertia),
            ):
                _check_finite(problems, f"{where}/{nm}", np.asarray(arr))
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
                problems.append(f"{where}/hulls: offsets inconsistent or a hull with < 4 vertices/faces")
            else:
                for k in range(len(vo) - 1):
                    fk = o.hull_faces[fo[k] : fo[k + 1]]
                    if fk.min() < 0 or fk.max() >= vo[k + 1] - vo[k]:
                        problems.append(f"{where}/hulls: hull {k} face index out of range")
                        break
            if not (np.isfinite(o.mass) and o.mass > 0):
                problems.append(f"{where}: mass {o.mass} not positive")
            if o.inertia.shape != (3, 3) or not np.allclose(o.inertia, o.inertia.T, atol=1e-9):
                problems.append(f"{where}/inertia: not a symmetric 3x3 matrix")
            elif np.linalg.eigvalsh(o.inertia).min() < -1e-12:
                problems.append(f"{where}/inertia: not positive semi-definite")
            if len(o.surface_points) == 0:
                problems.append(f"{where}/surface_points: empty")

        index = ds.index()
        groups = sorted(f["sequences"].keys())
        if sorted(r["id"] for r in index) != groups:
            problems.append(f"index/sequence_ids: {len(index)} ids do not match the {len(groups)} sequence groups")
        frames_in_index = {r["id"]: r["num_frames"] for r in index}
        for sid in groups:
            where = f"sequences/{sid}"
            try:
                s = ds.sequence(sid)
            except (KeyError, OSError, json.JSONDecodeError) as exc:
                problems.append(f"{where}: unreadable attributes ({exc})")
                continue
            T, O = s.num_frames, len(s.object_ids)
            if frames_in_index.get(sid, T) != T:
                problems.append(f"{where}: num_frames {T} but index says {frames_in_index[sid]}")
            if s.humanoid_id not in humanoid_bodies:
                problems.append(f"{where}: humanoid_id {s.humanoid_id!r} not in /humanoids")
                continue
            for oid in s.object_ids:
                if oid not in f["objects"]:
                    problems.append(f"{where}: object id {oid!r} not in /objects")
            B = humanoid_bodies[s.humanoid_id]
            sym = {"T": T, "B": B, "J": B - 1, "O": O}
            for name in schema.SEQUENCE_ARRAYS:
                if name not in s:
                    problems.append(f"{where}/{name}: missing")
                    continue
                d = s[name]
                if not _check_shape(problems, f"{where}/{name}", name, d, sym):
                    continue
                arr = d[()]
                _check_finite(problems, f"{where}/{name}", arr, allow_inf=name == "contacts/distance")
                if name.endswith("quat") and arr.size:
                    _check_quats(problems, f"{where}/{name}", arr)
                if name in ("contacts/labels", "contacts/geometric") and arr.size:
                    bad = ~np.isin(arr, schema.CONTACT_LABELS)
                    if bad.any():
                        problems.append(f"{where}/{name}: {int(bad.sum())} values outside {{-1, 0, 1}}")
                if name == "contacts/first_contact_frame" and (np.any(arr < -1) or np.any(arr >= T)):
                    problems.append(f"{where}/{name}: {arr.tolist()} outside [-1, {T})")
                if name == "contacts/window":
                    ok = (arr == -1).all() or (0 <= arr[0] <= arr[1] < T)
                    if not ok:
                        problems.append(f"{where}/{name}: {arr.tolist()} is not [-1, -1] or 0 <= start <= end < {T}")
    return problems
