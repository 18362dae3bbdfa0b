"""Writing canonical files: everything goes to a temporary file that is renamed into place on success."""

from __future__ import annotations

import contextlib
import json
from datetime import UTC, datetime
from pathlib import Path
from types import TracebackType
from typing import Any

import h5py
import numpy as np

from wristmimic import __version__
from wristmimic.format import schema
from wristmimic.format.records import HumanoidRecord, ObjectRecord, SequenceRecord
from wristmimic.safe_io import atomic_output

_STR = h5py.string_dtype()


def _json(obj: Any) -> str:
    def default(o: Any) -> Any:
        if isinstance(o, np.ndarray):
            return o.tolist()
        if isinstance(o, np.generic):
            return o.item()
        if isinstance(o, Path):
            return str(o)
        raise TypeError(f"not JSON serialisable: {type(o).__name__}")

    return json.dumps(obj, sort_keys=True, default=default)


class DatasetWriter:
    """Context manager that writes one canonical file atomically.

    >>> with DatasetWriter("out.h5", source_dataset="omomo", source_format="intermimic-pt",
    ...                    converter="intermimic", input_sha256={...}) as w:
    ...     w.add_humanoid("omomo", humanoid); w.add_object("largetable", obj); w.add_sequence("seq", seq)
    """

    def __init__(
        self,
        path: str | Path,
        *,
        source_dataset: str,
        source_format: str,
        converter: str,
        input_sha256: dict[str, str],
        extra_attrs: dict[str, Any] | None = None,
    ):
        self.path = Path(path)
        self._attrs = {
            "format": schema.FORMAT_NAME,
            "schema_version": schema.SCHEMA_VERSION,
            "fps": schema.FPS,
            "up_axis": schema.UP_AXIS,
            "units": schema.UNITS,
            "quat_order": schema.QUAT_ORDER,
            "source_dataset": source_dataset,
            "source_format": source_format,
            "converter": converter,
            "converter_version": __version__,
            "created_utc": datetime.now(UTC).strftime("%Y-%m-%dT%H:%M:%SZ"),
            "input_sha256": _json(input_sha256),
        }
        self._extra = extra_attrs or {}
        self._index: list[tuple[str, int, str, str, str]] = []
        self._ctx: contextlib.AbstractContextManager[Path] | None = None
        self._f: h5py.File | None = None

    def __enter__(self) -> DatasetWriter:
        self._ctx = atomic_output(self.path)
        tmp = self._ctx.__enter__()
        try:
            self._f = h5py.File(tmp, "w")
        except BaseException:
            self._ctx.__exit__(*__import__("sys").exc_info())
            raise
        for k, v in {
            **self._attrs,
            **{k: _json(v) if isinstance(v, dict | list) else v for k, v in self._extra.items()},
        }.items():
            self._f.attrs[k] = v
        for g in ("humanoids", "objects", "sequences", "index"):
            self._f.create_group(g)
        return self

    def __exit__(self, et: type[BaseException] | None, ev: BaseException | None, tb: TracebackType | None) -> None:
        assert self._f is not None and self._ctx is not None
        try:
            if et is None:
                self._write_index()
        finally:
            self._f.close()
            if et is None:
                self._ctx.__exit__(None, None, None)
            else:
                self._ctx.__exit__(et, ev, tb)

    @property
    def file(self) -> h5py.File:
        assert self._f is not None, "use DatasetWriter as a context manager"
        return self._f

    # -- content -------------------------------------------------------------------------------------------
    def has_humanoid(self, hid: str) -> bool:
        return hid in self.file["humanoids"]

    def has_object(self, oid: str) -> bool:
        return oid in self.file["objects"]

    def add_humanoid(self, hid: str, h: HumanoidRecord) -> None:
        g = self.file["humanoids"].create_group(hid)
        g.attrs.update({"name": h.name, "family": h.family, "source_file": h.source_file})
        if h.hand:  # schema 1.1: only humanoids with a swapped hand carry these
            g.attrs.update({"hand": h.hand, "hand_source": h.hand_source, "hand_ranges": h.hand_ranges})
        g.create_dataset("mjcf", data=h.mjcf, dtype=_STR)
        g.create_dataset("body_names", data=np.asarray(h.body_names, dtype=object), dtype=_STR)
        g.create_dataset("parents", data=np.asarray(h.parents, dtype=np.int32))
        g.create_dataset("joint_bodies", data=np.asarray(h.joint_bodies, dtype=np.int32))
        r = g.create_group("roles")
        for name, idx in sorted(h.roles.items()):
            r.create_dataset(name, data=np.asarray(idx, dtype=np.int32))

    def add_object(self, oid: str, o: ObjectRecord) -> None:
        g = self.file["objects"].create_group(oid)
        g.attrs.update(
            {
                "name": o.name,
                "static": bool(o.static),
                "inferred": bool(o.inferred),
                "density": float(o.density),
                "mass": float(o.mass),
                "mass_method": o.mass_method,
                "watertight": bool(o.watertight),
                "mesh_sha256": o.mesh_sha256,
                "source_file": o.source_file,
                "urdf": _json(o.urdf),
                "surface_seed": int(o.surface_seed),
                "extra": _json(o.extra),
            }
        )
        v = g.create_group("visual")
        v.create_dataset("vertices", data=np.asarray(o.vertices, np.float32), **schema.COMPRESSION)
        v.create_dataset("faces", data=np.asarray(o.faces, np.int32), **schema.COMPRESSION)
        h = g.create_group("hulls")
        h.create_dataset("vertices", data=np.asarray(o.hull_vertices, np.float32).reshape(-1, 3))
        h.create_dataset("faces", data=np.asarray(o.hull_faces, np.int32).reshape(-1, 3))
        h.create_dataset("vertex_offsets", data=np.asarray(o.hull_vertex_offsets, np.int64))
        h.create_dataset("face_offsets", data=np.asarray(o.hull_face_offsets, np.int64))
        h.attrs.update({k: _json(v) if isinstance(v, dict | list) else v for k, v in o.hull_meta.items()})
        g.create_dataset("com", data=np.asarray(o.com, np.float64))
        g.create_dataset("inertia", data=np.asarray(o.inertia, np.float64))
        g.create_dataset("surface_points", data=np.asarray(o.surface_points, np.float32))

    def add_sequence(self, sid: str, s: SequenceRecord) -> None:
        g = self.file["sequences"].create_group(sid)
        T = s.num_frames
        g.attrs.update(
            {
                "humanoid_id": s.humanoid_id,
                "object_ids": _json(list(s.object_ids)),
                "subject": s.subject,
                "text": s.text,
                "dataset": s.dataset,
                "split": s.split,
                "num_frames": T,
                "source_file": s.source_file,
                "extra": _json(s.extra),
            }
        )
        for name, arr in s.arrays().items():
            dtype = schema.SEQUENCE_ARRAYS[name][1]
            a = np.asarray(arr).astype(dtype, copy=False)
            kw: dict[str, Any] = {}
            if name in schema.PER_FRAME and T > 0:
                kw = {"chunks": (min(schema.CHUNK_FRAMES, T), *a.shape[1:]), **schema.COMPRESSION}
            g.create_dataset(name, data=a, **kw)
        g["contacts"].attrs.update(
            {k: _json(v) if isinstance(v, dict | list) else v for k, v in s.contact_meta.items()}
        )
        self._index.append((sid, T, s.humanoid_id, s.dataset, s.split))

    def _write_index(self) -> None:
        idx = self.file["index"]
        rows = sorted(self._index)
        idx.create_dataset("sequence_ids", data=np.asarray([r[0] for r in rows], dtype=object), dtype=_STR)
        idx.create_dataset("num_frames", data=np.asarray([r[1] for r in rows], dtype=np.int32))
        idx.create_dataset("humanoid_ids", data=np.asarray([r[2] for r in rows], dtype=object), dtype=_STR)
        idx.create_dataset("datasets", data=np.asarray([r[3] for r in rows], dtype=object), dtype=_STR)
        idx.create_dataset("splits", data=np.asarray([r[4] for r in rows], dtype=object), dtype=_STR)
