"""Writing canonical files: everything goes to a temporary file that is renamed into place on success.

HDF5 (2.0, h5py 3.16) must never see a failed write: after one, flushing or closing the file crashes the process
(segmentation fault, after pages of ignored errors from h5py object destructors). The file is therefore written
through :class:`GuardedFile` (h5py's ``fileobj`` driver), which keeps the first OS error to itself and drops the
writes after it; :class:`DatasetWriter` checks it after every record and on close, closes the HDF5 file cleanly,
deletes the temporary file and raises :class:`~wristmimic.safe_io.OutputError` (one line).
"""

from __future__ import annotations

import contextlib
import errno
import functools
import json
import os
from collections.abc import Callable
from datetime import UTC, datetime
from pathlib import Path
from types import TracebackType
from typing import Any, TypeVar

import h5py
import numpy as np

from wristmimic import __version__
from wristmimic.format import schema
from wristmimic.format.records import HumanoidRecord, ObjectRecord, SequenceRecord
from wristmimic.safe_io import OutputError, atomic_output, defer_sigint

_STR = h5py.string_dtype()


class GuardedFile:
    """An unbuffered binary file for h5py's ``fileobj`` driver that never reports a failed write to HDF5.

    The first :class:`OSError` of a write or truncate is kept in :attr:`error`; that write and every later one are
    dropped (reported as done). Reads return what reached the file, zero-filled past its end as HDF5's own POSIX
    driver does.
    """

    def __init__(self, path: str | Path):
        """Create (or empty) the file at ``path``."""
        self._fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_TRUNC | getattr(os, "O_BINARY", 0), 0o600)
        self._pos = 0
        self._end = 0
        self.error: OSError | None = None

    def seek(self, offset: int, whence: int = os.SEEK_SET) -> int:
        base = {os.SEEK_SET: 0, os.SEEK_CUR: self._pos, os.SEEK_END: self._end}[whence]
        self._pos = base + offset
        return self._pos

    def tell(self) -> int:
        return self._pos

    def readinto(self, buf: Any) -> int:
        view = memoryview(buf).cast("B")
        data = os.pread(self._fd, len(view), self._pos)
        view[: len(data)] = data
        view[len(data) :] = bytes(len(view) - len(data))
        self._pos += len(view)
        return len(view)

    def read(self, size: int = -1) -> bytes:
        size = max(self._end - self._pos, 0) if size is None or size < 0 else size
        buf = bytearray(size)
        self.readinto(buf)
        return bytes(buf)

    def write(self, data: Any) -> int:
        view = memoryview(data).cast("B")
        if self.error is None:
            try:
                done = 0
                while done < len(view):
                    n = os.pwrite(self._fd, view[done:], self._pos + done)
                    if n <= 0:
                        raise OSError(errno.EIO, os.strerror(errno.EIO))
                    done += n
            except OSError as exc:
                self.error = exc
        self._pos += len(view)
        self._end = max(self._end, self._pos)
        return len(view)

    def truncate(self, size: int | None = None) -> int:
        size = self._pos if size is None else size
        if self.error is None:
            try:
                os.ftruncate(self._fd, size)
            except OSError as exc:
                self.error = exc
        self._end = size
        return size

    def flush(self) -> None:
        """Nothing to do: writes are not buffered."""

    def close(self) -> None:
        if self._fd >= 0:
            os.close(self._fd)
            self._fd = -1


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


_F = TypeVar("_F", bound=Callable[..., Any])


def _whole(method: _F) -> _F:
    """Run ``method`` with Ctrl-C held back until it returns, so HDF5 is never interrupted mid-call; the
    KeyboardInterrupt then arrives between records and the writer removes its temporary file cleanly."""

    @functools.wraps(method)
    def run(*args: Any, **kwargs: Any) -> Any:
        with defer_sigint():
            return method(*args, **kwargs)

    return run  # type: ignore[return-value]


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
        link_repeats: bool = False,
    ):
        """``link_repeats``: a sequence array that is the very same object as one written before it in that
        sequence (an export's ``source_body_pos`` is its ``body_pos``) becomes an HDF5 hard link to it: read
        back it is the same data, written and compressed once."""
        self.path = Path(path)
        self._link_repeats = link_repeats
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
        self._sink: GuardedFile | None = None

    def __enter__(self) -> DatasetWriter:
        self._ctx = atomic_output(self.path)
        tmp: Path | None = None
        try:
            with defer_sigint():  # Ctrl-C is raised inside this try, once the temporary file is guarded
                tmp = self._ctx.__enter__()
                self._sink = GuardedFile(tmp)
                self._f = h5py.File(self._sink, "w")
                for k, v in {
                    **self._attrs,
                    **{k: _json(v) if isinstance(v, dict | list) else v for k, v in self._extra.items()},
                }.items():
                    self._f.attrs[k] = v
                for g in ("humanoids", "objects", "sequences", "index"):
                    self._f.create_group(g)
            self.check()
        except BaseException as exc:
            if tmp is None:  # no temporary file was made (or atomic_output removed it)
                raise
            self._abort(exc)
        return self

    def __exit__(self, et: type[BaseException] | None, ev: BaseException | None, tb: TracebackType | None) -> None:
        assert self._ctx is not None
        if ev is None:
            try:
                self.check()
                with defer_sigint():
                    self._write_index()
                self._close()
                self.check()
            except BaseException as exc:
                ev = exc
            else:
                self._ctx.__exit__(None, None, None)  # sync and rename into place (OutputError if that fails)
                return
        self._abort(ev)

    def check(self) -> None:
        """Raise :class:`OutputError` if a write to the temporary file has failed (disk full, quota, ...)."""
        if self._sink is not None and self._sink.error is not None:
            raise OutputError.from_os(self.path, self._sink.error)

    @_whole
    def _close(self) -> None:
        """Close the HDF5 file (HDF5 flushes its caches through the guarded file), then the file itself."""
        try:
            if self._f is not None:
                self._f.close()
        finally:
            if self._sink is not None:
                self._sink.close()

    def _abort(self, exc: BaseException) -> None:
        """Close everything, delete the temporary file and raise :class:`OutputError` if a write failed (whatever
        else went wrong then is a consequence), else ``exc``."""
        with contextlib.suppress(BaseException):  # a second Ctrl-C while closing must not keep the temporary file
            self._close()
        if self._sink is not None and self._sink.error is not None and not isinstance(exc, KeyboardInterrupt):
            exc = OutputError.from_os(self.path, self._sink.error)
        assert self._ctx is not None
        self._ctx.__exit__(type(exc), exc, exc.__traceback__)  # deletes the temporary file
        raise exc

    @property
    def file(self) -> h5py.File:
        assert self._f is not None, "use DatasetWriter as a context manager"
        return self._f

    # -- content -------------------------------------------------------------------------------------------
    @_whole
    def set_attr(self, key: str, value: Any) -> None:
        """Set a root attribute once the content is known (dicts and lists as sorted JSON text)."""
        self.check()
        self.file.attrs[key] = _json(value) if isinstance(value, dict | list) else value
        self.check()

    def has_humanoid(self, hid: str) -> bool:
        return hid in self.file["humanoids"]

    def has_object(self, oid: str) -> bool:
        return oid in self.file["objects"]

    @_whole
    def add_humanoid(self, hid: str, h: HumanoidRecord) -> None:
        self.check()
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
        self.check()

    @_whole
    def add_object(self, oid: str, o: ObjectRecord) -> None:
        self.check()
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
        self.check()

    @_whole
    def add_sequence(self, sid: str, s: SequenceRecord) -> None:
        self.check()
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
        seen: dict[tuple[int, str], str] = {}  # (id of the array, dtype) -> name written
        for name, arr in s.arrays().items():
            dtype = (schema.SEQUENCE_ARRAYS | schema.OPTIONAL_SEQUENCE_ARRAYS)[name][1]
            if self._link_repeats and (id(arr), dtype) in seen:
                g[name] = g[seen[id(arr), dtype]]  # hard link: the same dataset under a second name
                continue
            seen[id(arr), dtype] = name
            a = np.asarray(arr).astype(dtype, copy=False)
            kw: dict[str, Any] = {}
            if name in schema.PER_FRAME and T > 0:
                kw = {"chunks": (min(schema.CHUNK_FRAMES, T), *a.shape[1:]), **schema.COMPRESSION}
            g.create_dataset(name, data=a, **kw)
        g["contacts"].attrs.update(
            {k: _json(v) if isinstance(v, dict | list) else v for k, v in s.contact_meta.items()}
        )
        self._index.append((sid, T, s.humanoid_id, s.dataset, s.split))
        self.check()

    def _write_index(self) -> None:
        idx = self.file["index"]
        rows = sorted(self._index)
        idx.create_dataset("sequence_ids", data=np.asarray([r[0] for r in rows], dtype=object), dtype=_STR)
        idx.create_dataset("num_frames", data=np.asarray([r[1] for r in rows], dtype=np.int32))
        idx.create_dataset("humanoid_ids", data=np.asarray([r[2] for r in rows], dtype=object), dtype=_STR)
        idx.create_dataset("datasets", data=np.asarray([r[3] for r in rows], dtype=object), dtype=_STR)
        idx.create_dataset("splits", data=np.asarray([r[4] for r in rows], dtype=object), dtype=_STR)
