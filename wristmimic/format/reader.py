"""Reading canonical files lazily: only what is asked for is read from disk.

>>> from wristmimic.format import open_dataset
>>> with open_dataset("datasets/omomo.h5") as ds:
...     ds.sequence_ids                       # from /index, no group walk
...     seq = ds.sequence("sub2_largetable_000")
...     seq.num_frames, seq["body_pos"][:10]  # reads 10 frames of one dataset
...     hum = ds.humanoid(seq.humanoid_id)    # HumanoidRecord (MJCF, bodies, roles)
...     objs = [ds.object(o) for o in seq.object_ids]
"""

from __future__ import annotations

import json
from pathlib import Path
from types import TracebackType
from typing import Any

import h5py
import numpy as np

from wristmimic.errors import InputError, SchemaVersionError
from wristmimic.format import schema
from wristmimic.format.records import HumanoidRecord, ObjectRecord, SequenceRecord

_RECORD_FIELDS = {
    "contacts/labels": "contact_labels",
    "contacts/geometric": "contact_geometric",
    "contacts/distance": "contact_distance",
    "contacts/hand": "hand_contact",
    "contacts/object": "object_contact",
    "contacts/first_contact_frame": "first_contact_frame",
    "contacts/window": "contact_window",
}


def _str(v: Any) -> str:
    return v.decode() if isinstance(v, bytes) else str(v)


def _json_attr(attrs: h5py.AttributeManager, key: str, default: Any) -> Any:
    return json.loads(_str(attrs[key])) if key in attrs else default


def major(version: str) -> int:
    return int(str(version).split(".")[0])


class SequenceView:
    """Lazy view of one sequence group; ``view[name]`` is the h5py dataset (slice it to read)."""

    def __init__(self, ds: Dataset, sid: str, group: h5py.Group):
        self._ds, self.id, self._g = ds, sid, group
        a = group.attrs
        self.humanoid_id: str = _str(a["humanoid_id"])
        self.object_ids: list[str] = _json_attr(a, "object_ids", [])
        self.num_frames: int = int(a["num_frames"])
        self.subject: str = _str(a.get("subject", ""))
        self.text: str = _str(a.get("text", ""))
        self.dataset: str = _str(a.get("dataset", ""))
        self.split: str = _str(a.get("split", ""))
        self.source_file: str = _str(a.get("source_file", ""))
        self.extra: dict[str, Any] = _json_attr(a, "extra", {})

    def __getitem__(self, name: str) -> h5py.Dataset:
        try:
            return self._g[name]
        except KeyError:
            raise InputError(self._ds.path, f"sequences/{self.id}/{name}", "missing") from None

    def __contains__(self, name: str) -> bool:
        return name in self._g

    def array(self, name: str, frames: slice | None = None) -> np.ndarray:
        """Read one array (optionally a frame slice) into memory."""
        d = self[name]
        return d[()] if frames is None or d.ndim == 0 else d[frames]

    @property
    def contact_meta(self) -> dict[str, Any]:
        return {
            k: (json.loads(v) if isinstance(v, str) and v[:1] in "[{" else v)
            for k, v in (
                (k, _str(v) if isinstance(v, bytes | str) else v) for k, v in self._g["contacts"].attrs.items()
            )
        }

    def load(self, frames: slice | None = None) -> SequenceRecord:
        """Every array of the sequence (optionally a frame range) as a :class:`SequenceRecord`."""
        kw: dict[str, Any] = {}
        for name, (shape, *_rest) in schema.SEQUENCE_ARRAYS.items():
            per_frame = shape[0] == "T"
            kw[_RECORD_FIELDS.get(name, name)] = self.array(name, frames if per_frame else None)
        optional = {
            name: self.array(name, frames) for name in schema.OPTIONAL_SEQUENCE_ARRAYS if name in self._g
        }  # schema 1.2: exported sequences only
        return SequenceRecord(
            humanoid_id=self.humanoid_id,
            object_ids=list(self.object_ids),
            subject=self.subject,
            dataset=self.dataset,
            text=self.text,
            split=self.split,
            source_file=self.source_file,
            contact_meta=self.contact_meta,
            extra=dict(self.extra),
            optional=optional,
            **kw,
        )


class Dataset:
    """An open canonical file. Use :func:`open_dataset`."""

    def __init__(self, path: str | Path):
        self.path = Path(path)
        if self.path.is_dir():
            raise InputError(self.path, None, "is a folder, expected a canonical .h5 file")
        if not self.path.is_file():
            raise InputError(self.path, None, "no such file")
        try:
            self._f = h5py.File(self.path, "r")
        except OSError as exc:
            raise InputError(
                self.path,
                None,
                f"not a readable HDF5 file ({str(exc).splitlines()[0][:120]})",
                "a canonical wristmimic .h5 file",
            ) from None
        try:
            self._check_header()
        except BaseException:
            self._f.close()
            raise

    def _check_header(self) -> None:
        a = self._f.attrs
        fmt = _str(a.get("format", ""))
        if fmt != schema.FORMAT_NAME:
            raise InputError(
                self.path,
                "/.format",
                f"is {fmt!r}" if fmt else "missing",
                f"{schema.FORMAT_NAME!r} (is this a wristmimic canonical file?)",
            )
        ver = _str(a.get("schema_version", ""))
        try:
            ok = major(ver) == major(schema.SCHEMA_VERSION)
        except ValueError:
            ok = False
        if not ok:
            raise SchemaVersionError(
                self.path,
                "/.schema_version",
                f"is {ver!r}; this wristmimic reads major {major(schema.SCHEMA_VERSION)}",
                f"{major(schema.SCHEMA_VERSION)}.x.y; convert the source again with this version",
            )
        for g in ("humanoids", "objects", "sequences", "index"):
            if g not in self._f:
                raise InputError(self.path, f"/{g}", "missing group", "a complete canonical file")

    # -- context -------------------------------------------------------------------------------------------
    def close(self) -> None:
        self._f.close()

    def __enter__(self) -> Dataset:
        return self

    def __exit__(self, et: type[BaseException] | None, ev: BaseException | None, tb: TracebackType | None) -> None:
        self.close()

    @property
    def h5(self) -> h5py.File:
        """The underlying h5py file (read-only)."""
        return self._f

    # -- metadata ------------------------------------------------------------------------------------------
    @property
    def attrs(self) -> dict[str, Any]:
        out = {k: (_str(v) if isinstance(v, bytes | str) else v) for k, v in self._f.attrs.items()}
        if "input_sha256" in out:
            out["input_sha256"] = json.loads(out["input_sha256"])
        return out

    @property
    def sequence_ids(self) -> list[str]:
        return [_str(s) for s in self._f["index/sequence_ids"][()]] if "sequence_ids" in self._f["index"] else []

    def index(self) -> list[dict[str, Any]]:
        """One dict per sequence: id, num_frames, humanoid_id, dataset, split (from /index)."""
        i = self._f["index"]
        if "sequence_ids" not in i:
            return []
        cols = {k: i[k][()] for k in ("sequence_ids", "num_frames", "humanoid_ids", "datasets", "splits")}
        return [
            {
                "id": _str(cols["sequence_ids"][n]),
                "num_frames": int(cols["num_frames"][n]),
                "humanoid_id": _str(cols["humanoid_ids"][n]),
                "dataset": _str(cols["datasets"][n]),
                "split": _str(cols["splits"][n]),
            }
            for n in range(len(cols["sequence_ids"]))
        ]

    @property
    def humanoid_ids(self) -> list[str]:
        return sorted(self._f["humanoids"].keys())

    @property
    def object_ids(self) -> list[str]:
        return sorted(self._f["objects"].keys())

    # -- content -------------------------------------------------------------------------------------------
    def sequence(self, sid: str) -> SequenceView:
        if sid not in self._f["sequences"]:
            raise InputError(
                self.path,
                f"sequences/{sid}",
                "no such sequence",
                f"one of {self.sequence_ids[:8]}{'...' if len(self.sequence_ids) > 8 else ''}",
            )
        return SequenceView(self, sid, self._f["sequences"][sid])

    def humanoid(self, hid: str) -> HumanoidRecord:
        if hid not in self._f["humanoids"]:
            raise InputError(self.path, f"humanoids/{hid}", "no such humanoid", f"one of {self.humanoid_ids}")
        g = self._f["humanoids"][hid]
        return HumanoidRecord(
            name=_str(g.attrs["name"]),
            family=_str(g.attrs["family"]),
            mjcf=_str(g["mjcf"][()]),
            body_names=[_str(b) for b in g["body_names"][()]],
            parents=g["parents"][()],
            joint_bodies=g["joint_bodies"][()],
            roles={k: g["roles"][k][()] for k in g["roles"]},
            source_file=_str(g.attrs.get("source_file", "")),
            hand=_str(g.attrs.get("hand", "")),
            hand_source=_str(g.attrs.get("hand_source", "")),
            hand_ranges=_str(g.attrs.get("hand_ranges", "")),
        )

    def object(self, oid: str) -> ObjectRecord:
        if oid not in self._f["objects"]:
            raise InputError(self.path, f"objects/{oid}", "no such object", f"one of {self.object_ids}")
        g = self._f["objects"][oid]
        a = g.attrs
        h = g["hulls"]
        meta = {
            k: (json.loads(_str(v)) if k == "params" else (_str(v) if isinstance(v, bytes | str) else v))
            for k, v in h.attrs.items()
        }
        return ObjectRecord(
            name=_str(a["name"]),
            static=bool(a["static"]),
            inferred=bool(a["inferred"]),
            vertices=g["visual/vertices"][()],
            faces=g["visual/faces"][()],
            hull_vertices=h["vertices"][()],
            hull_faces=h["faces"][()],
            hull_vertex_offsets=h["vertex_offsets"][()],
            hull_face_offsets=h["face_offsets"][()],
            hull_meta=meta,
            mass=float(a["mass"]),
            com=g["com"][()],
            inertia=g["inertia"][()],
            mass_method=_str(a["mass_method"]),
            density=float(a["density"]),
            watertight=bool(a["watertight"]),
            surface_points=g["surface_points"][()],
            surface_seed=int(a["surface_seed"]),
            mesh_sha256=_str(a["mesh_sha256"]),
            urdf=_json_attr(a, "urdf", {}),
            source_file=_str(a.get("source_file", "")),
            extra=_json_attr(a, "extra", {}),
        )


def open_dataset(path: str | Path) -> Dataset:
    """Open a canonical file for reading; checks ``format`` and the ``schema_version`` major."""
    return Dataset(path)
