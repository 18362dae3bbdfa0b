"""Safe reading of untrusted files and atomic writing of outputs."""

from __future__ import annotations

import contextlib
import errno
import hashlib
import io
import os
import pickle
import re
import signal
import socket
import sys
import tempfile
import threading
import time
import warnings
from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np

from wristmimic.errors import InputError, WristmimicError


def sha256_file(path: str | Path, chunk: int = 1 << 20) -> str:
    """Hex sha256 of a file's bytes."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        while block := f.read(chunk):
            h.update(block)
    return h.hexdigest()


_UMASK = os.umask(0)
os.umask(_UMASK)

#: errno values that mean "the data could not be stored" wherever they come from.
_WRITE_ERRNOS = frozenset({errno.ENOSPC, errno.EDQUOT, errno.EFBIG, errno.EIO, errno.EROFS})
#: Temporary files whose writer cannot be checked (another host, or named before the pid was embedded) are
#: removed when untouched for this long.
STALE_AFTER_S = 24 * 3600.0
_HOST = re.sub(r"[^A-Za-z0-9_-]", "_", socket.gethostname())[:40] or "host"
_RAND = r"[a-z0-9_]{8}"  # the random part tempfile.mkstemp adds
_OWNED_TMP = re.compile(rf"(?P<host>[A-Za-z0-9_-]+)-(?P<pid>\d+)\.{_RAND}(?:\.\w+)?")
_LEGACY_TMP = re.compile(rf"{_RAND}(?:\.\w+)?")


class OutputError(WristmimicError):
    """An output could not be written (disk full, quota, file size limit, I/O error).

    The message is one line: ``<file>: could not write (<reason>)``.
    """

    def __init__(self, path: str | Path, reason: str):
        self.path, self.reason = str(path), reason
        super().__init__(f"{path}: could not write ({reason})")

    @classmethod
    def from_os(cls, path: str | Path, exc: OSError) -> OutputError:
        """The error for ``exc`` raised while writing ``path`` (reason: the errno's text, else the message)."""
        if exc.errno:
            reason = os.strerror(exc.errno)
        else:
            reason = (str(exc).strip().splitlines() or [type(exc).__name__])[0][:160]
        return cls(path, reason)


def is_write_failure(exc: BaseException, *paths: str | Path) -> bool:
    """Whether ``exc`` is an :class:`OSError` from storing data: disk full, quota, file too large, I/O error,
    read-only file system, or any OSError naming one of ``paths``."""
    if not isinstance(exc, OSError):
        return False
    if exc.errno in _WRITE_ERRNOS:
        return True
    named = {str(p) for p in paths}
    return any(f is not None and str(f) in named for f in (exc.filename, exc.filename2))


def _pid_running(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # alive, another user's
        return True
    except OSError:
        return True  # cannot tell: keep the file
    return True


def _stale_reason(name: str, prefix: str, mtime: float) -> str | None:
    """Why the temporary file ``name`` (beside an output whose temporaries start with ``prefix``) is stale, or
    None if it is not a temporary of that output or its writer may still be running."""
    if not (name.startswith(prefix) and name.endswith(".tmp")):
        return None
    middle = name[len(prefix) : -len(".tmp")]
    owned = _OWNED_TMP.fullmatch(middle)
    if owned:
        host, pid = owned["host"], int(owned["pid"])
        if host == _HOST:
            if pid == os.getpid() or _pid_running(pid):
                return None
            return f"left by process {pid}, which is no longer running"
    elif not _LEGACY_TMP.fullmatch(middle):
        return None  # another output's temporary (its name starts the same)
    age = time.time() - mtime
    if age < STALE_AFTER_S:
        return None
    where = f"process {owned['pid']} on {owned['host']}" if owned else "an unknown process"
    return f"left by {where}, untouched for {age / 3600:.0f} h"


def remove_stale_temporaries(path: str | Path, report: Callable[[str], None] | None = None) -> list[Path]:
    """Delete temporary files of ``path`` left beside it by killed writers; returns what was removed.

    A temporary is ``.<name>.<host>-<pid>.<random><suffix>.tmp`` (see :func:`atomic_output`). It is stale when
    its writer ran on this host and that process no longer exists; one from another host (whose process cannot
    be checked), or without a pid (written by an older version), when untouched for :data:`STALE_AFTER_S`.
    Each removal is reported in one line (default: on stderr).
    """
    path = Path(path)
    parent = path.parent if str(path.parent) else Path(".")
    prefix = f".{path.name}."
    removed: list[Path] = []
    try:
        entries = [e for e in os.scandir(parent) if e.name.startswith(prefix) and e.name.endswith(".tmp")]
    except OSError:
        return removed
    for entry in entries:
        try:
            why = _stale_reason(entry.name, prefix, entry.stat(follow_symlinks=False).st_mtime)
            if why is None or not entry.is_file(follow_symlinks=False):
                continue
            os.unlink(entry.path)
        except OSError:  # vanished meanwhile, or not ours to delete
            continue
        removed.append(parent / entry.name)
        (report or _stderr)(f"removed stale temporary file {removed[-1]} ({why})")
    return removed


@contextlib.contextmanager
def defer_sigint() -> Iterator[None]:
    """Hold Ctrl-C back for the duration of the block and raise it when the block ends.

    Libraries with C state (HDF5 above all) must not be interrupted in the middle of a call: a KeyboardInterrupt
    raised inside an h5py conversion callback comes out as an unrelated ``TypeError`` and leaves the file's
    caches inconsistent. Only acts in the main thread while Python's default handler is installed; anywhere
    else it is a no-op.
    """
    if threading.current_thread() is not threading.main_thread() or (
        signal.getsignal(signal.SIGINT) is not signal.default_int_handler
    ):
        yield
        return
    pending: list[int] = []

    def hold(signum: int, frame: object) -> None:
        pending.append(signum)

    signal.signal(signal.SIGINT, hold)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, signal.default_int_handler)
    if pending:
        raise KeyboardInterrupt


def _stderr(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


def _fsync(path: Path, *, directory: bool = False) -> None:
    fd = os.open(path, os.O_RDONLY | (getattr(os, "O_DIRECTORY", 0) if directory else 0))
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


@contextlib.contextmanager
def atomic_output(path: str | Path, suffix: str = "") -> Iterator[Path]:
    """Yield a temporary path beside ``path``; on success sync it to disk and rename it onto ``path``, on
    failure delete it.

    Nothing half-written is ever left at ``path``. The temporary is ``.<name>.<host>-<pid>.<random><suffix>.tmp``
    so that one left by a killed process is recognised: stale temporaries of ``path`` are removed (and reported on
    stderr) first, see :func:`remove_stale_temporaries`. A failed write (disk full, quota, file size limit, I/O
    error) raised inside the block or while syncing/renaming becomes :class:`OutputError` (one line); a folder
    that is missing or not writable raises :class:`InputError`.
    """
    path = Path(path)
    parent = path.parent if str(path.parent) else Path(".")
    if not parent.is_dir():
        raise InputError(path, None, f"output folder {parent} does not exist")
    remove_stale_temporaries(path)
    tmp_path: Path | None = None
    try:
        with defer_sigint():  # a Ctrl-C between creating the temporary and guarding it would leave it behind
            try:
                fd, tmp = tempfile.mkstemp(
                    prefix=f".{path.name}.{_HOST}-{os.getpid()}.", suffix=suffix + ".tmp", dir=parent
                )
            except OSError as exc:
                if exc.errno in _WRITE_ERRNOS and exc.errno != errno.EROFS:  # no space (or inodes) left, I/O error
                    raise OutputError.from_os(path, exc) from None
                raise InputError(path, None, f"output folder is not writable ({exc.strerror})") from None
            tmp_path = Path(tmp)
            os.close(fd)
        yield tmp_path
        _fsync(tmp_path)  # the data is on disk before the name points at it (no empty file after a power cut)
        os.chmod(tmp_path, 0o666 & ~_UMASK)  # mkstemp makes 0600; give the file the usual permissions
        os.replace(tmp_path, path)
    except BaseException as exc:
        if tmp_path is None:
            raise
        with contextlib.suppress(OSError):
            tmp_path.unlink()
        if isinstance(exc, OSError) and is_write_failure(exc, tmp_path, path):
            raise OutputError.from_os(path, exc) from None
        raise
    with contextlib.suppress(OSError):  # persist the rename; some file systems refuse fsync on folders
        _fsync(parent, directory=True)


def load_pt_tensor(path: str | Path, *, ndim: int = 2) -> np.ndarray:
    """Load a ``.pt`` file that must hold one plain tensor; returns float64 numpy.

    Read with :func:`torch_load_untrusted`: a pickle carrying code is refused, and files saved on CUDA load on
    the CPU. Checks the rank and that every value is finite.
    """
    import torch

    path = Path(path)
    obj = torch_load_untrusted(path, "a tensor saved by torch.save")
    if not isinstance(obj, torch.Tensor):
        raise InputError(path, "<root>", f"holds a {type(obj).__name__}", "a single tensor")
    arr = obj.detach().to(torch.float64).numpy()
    if arr.ndim != ndim:
        raise InputError(path, "<tensor>", f"shape {tuple(arr.shape)}", f"a {ndim}-D tensor")
    bad = ~np.isfinite(arr)
    if bad.any():
        r, c = np.argwhere(bad)[0] if arr.ndim == 2 else (np.argwhere(bad)[0][0], -1)
        raise InputError(path, f"row {r} column {c}", f"{int(bad.sum())} non-finite values (NaN/inf)", "finite values")
    return arr


# --------------------------------------------------------------------------- torch files from elsewhere
#
# torch.load(weights_only=True) refuses pickles that name code, but its messages are long, suggest re-running
# with weights_only=False (which would run the code) and read the same for a refused pickle and for random
# bytes. torch_load_untrusted turns every failure into one line that says which it was.

_SCAN_LIMIT = 16 << 20
"""Bytes of a refused file that are parsed (never run) to find the global it names."""
_STRING_OPS = frozenset(
    {"STRING", "BINSTRING", "SHORT_BINSTRING", "UNICODE", "SHORT_BINUNICODE", "BINUNICODE", "BINUNICODE8"}
)
_QUIET_OPS = frozenset({"MEMOIZE", "PUT", "BINPUT", "LONG_BINPUT", "FRAME", "PROTO", "STOP"})


def _torch_own(name: str) -> bool:
    """A global every torch.save file names (tensor rebuilding, OrderedDict): not what made torch refuse it."""
    return name == "torch" or name.startswith("torch.") or name == "collections.OrderedDict"


def _pickle_global(data: bytes) -> tuple[bool, str | None]:
    """Parse (never run) the pickles at the start of ``data``: (whether at least one is complete, the first
    global other than torch's own that a complete one names, as ``module.name``)."""
    import io
    import pickletools

    stream = io.BytesIO(data)
    complete = False
    for _ in range(8):  # torch's legacy layout is several pickles in a row, then raw storage bytes
        if stream.tell() >= len(data):
            break
        pushed: list[object] = []  # per pushing opcode: its string, or None
        memo: dict[int, object] = {}
        found: str | None = None
        try:
            for op, arg, _pos in pickletools.genops(stream):
                name, named = op.name, None
                if name in ("GLOBAL", "INST"):
                    named = str(arg).replace(" ", ".")
                elif name == "STACK_GLOBAL":
                    mod, attr = ([None, None, *pushed])[-2:]
                    named = f"{mod}.{attr}" if isinstance(mod, str) and isinstance(attr, str) else "(unnamed)"
                elif name.startswith("EXT"):
                    named = f"(extension code {arg})"
                if found is None and named is not None and not _torch_own(named):
                    found = named
                if name == "MEMOIZE":
                    memo[len(memo)] = pushed[-1] if pushed else None
                elif name in ("PUT", "BINPUT", "LONG_BINPUT"):
                    memo[int(arg)] = pushed[-1] if pushed else None
                elif name in ("GET", "BINGET", "LONG_BINGET"):
                    pushed.append(memo.get(int(arg)))
                elif name not in _QUIET_OPS:
                    pushed.append(arg if name in _STRING_OPS and isinstance(arg, str) else None)
        except Exception:  # noqa: BLE001 - not (or no longer) a pickle: stop at the last complete one
            return complete, None
        complete = True
        if found is not None:
            return True, found
    return complete, None


def first_sentence(text: str, limit: int = 160) -> str:
    """The first sentence of ``text`` on one line; past ``limit`` characters cut at a word and marked `` ...``."""
    flat = " ".join(text.split())
    first = re.split(r"(?<=[.!?])\s", flat, maxsplit=1)[0].rstrip(".")
    if len(first) <= limit:
        return first
    return first[:limit].rsplit(" ", 1)[0] + " ..."


def _torch_load_error(path: Path, exc: Exception, what: str) -> InputError:
    """The one-line error for a file torch.load (weights_only) failed on."""
    import pickletools
    import zipfile

    refused = "not a plain tensor: contains code or objects"
    named = re.search(r"GLOBAL ([A-Za-z_][\w.]*)", str(exc))
    if named:
        return InputError(path, "<pickle>", f"{refused} (GLOBAL {named.group(1).rstrip('.')})", what)
    try:
        with open(path, "rb") as f:
            head = f.read(_SCAN_LIMIT)
    except OSError as err:
        return InputError(path, None, f"cannot be read ({err.strerror or type(err).__name__})", what)
    reason = None
    if not head:
        reason = "empty file"
    elif head.startswith(b"PK\x03\x04"):
        try:
            with zipfile.ZipFile(path) as z:
                pkl = [n for n in z.namelist() if n == "data.pkl" or n.endswith("/data.pkl")]
                head = z.read(pkl[0])[:_SCAN_LIMIT] if pkl else b""
        except (zipfile.BadZipFile, OSError, EOFError, ValueError, RuntimeError, NotImplementedError):
            reason = "truncated or corrupt zip archive"
        else:
            reason = None if pkl else "a zip archive without data.pkl"
    if reason is None:
        is_pickle, name = _pickle_global(head)
        opcode = re.search(r"Unsupported operand (\d+)", str(exc))
        if name is not None and isinstance(exc, pickle.UnpicklingError):
            return InputError(path, "<pickle>", f"{refused} (GLOBAL {name})", what)
        if not is_pickle:
            reason = "neither a zip archive nor a pickle"
        elif opcode and 0 <= int(opcode.group(1)) < 256:
            op = pickletools.code2op.get(chr(int(opcode.group(1))))
            reason = f"pickle opcode {op.name if op else opcode.group(1)}, which the safe loader does not read"
        elif isinstance(exc, pickle.UnpicklingError) or "weights_only" in str(exc):
            reason = "a pickle, but not in torch.save's layout"
        else:
            reason = first_sentence(str(exc)) or type(exc).__name__
    return InputError(path, "<file>", f"not a torch file (cannot be read: {reason})", what)


def torch_load_untrusted(path: str | Path, what: str, data: bytes | None = None) -> object:
    """``torch.load(path, weights_only=True, map_location="cpu")`` for a file from elsewhere (``data``: the file's
    bytes, already read; ``path`` then only names it).

    Tensors and plain containers load (on the CPU); nothing in the file is run. Every failure is one
    :class:`InputError` naming the file, with ``what`` (e.g. ``"a tensor saved by torch.save"``) as the
    expectation: ``<pickle>: not a plain tensor: contains code or objects (GLOBAL module.name)`` for a pickle
    that names code or other objects, ``<file>: not a torch file (cannot be read: ...)`` for random bytes,
    truncated or empty files, ``cannot be read (<OS error>)`` when the file cannot be opened. The messages never
    suggest ``weights_only=False``. torch's warnings (e.g. about the pickle protocol) are silenced.
    """
    import torch

    path = Path(path)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            return torch.load(path if data is None else io.BytesIO(data), weights_only=True, map_location="cpu")
    except Exception as exc:  # noqa: BLE001 - KeyError, EOFError, RuntimeError, OSError (EINVAL), ... for bad files
        raise _torch_load_error(path, exc, what) from None


# --------------------------------------------------------------------------- output paths


def _first_existing(path: Path) -> Path:
    """``path`` or its nearest ancestor that exists."""
    for p in (path, *path.parents):
        if p.exists():
            return p
    return Path(".")


def check_output_file(path: str | Path, key: str | None = "--out") -> None:
    """Refuse, before any work, a file to write that is an existing folder or lies below a file.

    ``key`` names the option in the message. A missing or read-only folder is left to :func:`atomic_output`.
    """
    path = Path(path)
    if path.is_dir():
        raise InputError(path, key, "is a folder", "a file name to write")
    above = _first_existing(path.parent if str(path.parent) else Path("."))
    if not above.is_dir():
        raise InputError(path, key, f"{above} is a file, not a folder", "a file name in a folder")


def check_output_folder(path: str | Path, key: str | None = "--out") -> None:
    """Refuse, before any work, a folder to write into that is a file, lies below a file or cannot be made."""
    path = Path(path)
    above = _first_existing(path)
    if above == path and not path.is_dir():
        raise InputError(path, key, "is a file, not a folder", "a folder to write into, made if missing")
    if not above.is_dir():
        raise InputError(path, key, f"{above} is a file, not a folder", "a folder to write into, made if missing")
    if not os.access(above, os.W_OK | os.X_OK):
        raise InputError(path, key, f"{above} is not writable", "a folder to write into, made if missing")


# --------------------------------------------------------------------------- restricted unpickling
#
# Raw dataset releases (ParaHome ``*.pkl``, OMOMO joblib ``*.p``) are pickles. A pickle can name any Python
# callable and run it while loading, so these files are read with an unpickler that resolves only the globals
# needed to rebuild numpy arrays, dtypes and scalars, and builtin containers; anything else is refused before
# it is called. joblib files (``joblib.dump``) are supported without importing joblib: their
# ``NumpyArrayWrapper`` records are rebuilt here from the raw array bytes that follow them (uncompressed, or
# gzip / bz2 / xz / lzma / zlib compressed). lz4 and the pre-0.10 joblib layout (arrays in side files) are refused.

_BUILTIN_NAMES = frozenset(
    {"dict", "list", "tuple", "set", "frozenset", "str", "bytes", "bytearray", "int", "float", "bool", "complex"}
    | {"slice", "range"}
)
_NUMPY_GLOBALS = {
    ("multiarray", "_reconstruct"),
    ("multiarray", "scalar"),
    ("numeric", "_frombuffer"),
}
_JOBLIB_WRAPPER = ("joblib.numpy_pickle", "NumpyArrayWrapper")
_COMPRESSED = (
    (b"\x1f\x8b", "gzip"),
    (b"BZh", "bz2"),
    (b"\xfd7zXZ", "xz"),
    (b"\x5d\x00\x00", "lzma"),
    (b"\x78", "zlib"),
)
_REFUSED_MAGIC = ((b"\x04\x22\x4d\x18", "lz4-compressed joblib"), (b"ZF", "pre-0.10 joblib (arrays in side files)"))


class _RefusedGlobal(Exception):
    def __init__(self, name: str):
        super().__init__(name)
        self.name = name


def _latin1_encode(text: str, encoding: str = "utf-8") -> bytes:
    """``_codecs.encode`` as protocol-2 pickles use it for bytes (latin-1 only)."""
    if encoding.replace("-", "").lower() not in ("latin1", "iso88591"):
        raise _RefusedGlobal(f"_codecs.encode with encoding {encoding!r}")
    return text.encode("latin-1")


def _numpy_global(module: str, name: str) -> object | None:
    """The numpy object ``module.name`` if it is on the allow-list, else None."""
    import importlib

    if module == "numpy" and name in ("dtype", "ndarray"):
        return getattr(np, name)
    prefix, _, sub = module.rpartition(".")
    if prefix not in ("numpy.core", "numpy._core") or (sub, name) not in _NUMPY_GLOBALS:
        return None
    for pkg in ("numpy._core", "numpy.core"):  # numpy 2 moved numpy.core to numpy._core
        try:
            return getattr(importlib.import_module(f"{pkg}.{sub}"), name)
        except (ImportError, AttributeError):
            continue
    return None


def _allowed_global(module: str, name: str) -> object:
    if module in ("builtins", "__builtin__") and name in _BUILTIN_NAMES:  # __builtin__: protocol < 3
        return getattr(__import__("builtins"), name)
    if (module, name) == ("_codecs", "encode"):
        return _latin1_encode
    if (module, name) == _JOBLIB_WRAPPER:
        return _JoblibArray
    obj = _numpy_global(module, name)
    if obj is None:
        raise _RefusedGlobal(f"{module}.{name}")
    return obj


class _JoblibArray:
    """Stand-in for joblib's ``NumpyArrayWrapper``: array metadata; the bytes follow in the stream."""

    _KEYS = frozenset({"subclass", "shape", "order", "dtype", "allow_mmap", "numpy_array_alignment_bytes"})

    def __setstate__(self, state: dict) -> None:
        if not isinstance(state, dict) or not set(state) <= self._KEYS:
            raise _RefusedGlobal("joblib NumpyArrayWrapper with unexpected state")
        self.__dict__.update(state)

    def read(self, fh: object, path: Path, remaining: int | None) -> np.ndarray:
        dtype, shape = self.__dict__.get("dtype"), tuple(self.__dict__.get("shape") or ())
        if not isinstance(dtype, np.dtype) or not all(isinstance(n, int) and n >= 0 for n in shape):
            raise InputError(path, "<joblib array>", "malformed array header", "a joblib.dump file")
        if dtype.hasobject:  # joblib pickles object arrays in a nested (protocol 2) pickle
            return _Restricted(fh, path).load()
        if self.__dict__.get("numpy_array_alignment_bytes") is not None:
            pad = fh.read(1)  # type: ignore[attr-defined]
            fh.read(int.from_bytes(pad, "little"))  # type: ignore[attr-defined]
        size = int(np.prod(shape, dtype=np.int64)) * dtype.itemsize
        if remaining is not None and size > remaining:
            raise InputError(path, "<joblib array>", f"array of {size} bytes in a {remaining}-byte file", "intact")
        data = fh.read(size)  # type: ignore[attr-defined]
        if len(data) != size:
            raise InputError(path, "<joblib array>", "file ends inside an array", "a complete joblib.dump file")
        arr = np.frombuffer(data, dtype=dtype).astype(dtype.newbyteorder("="))
        return arr.reshape(shape[::-1]).T if self.__dict__.get("order") == "F" else arr.reshape(shape)


class _Restricted(pickle._Unpickler):  # type: ignore[name-defined]  # pure-Python: BUILD can be hooked
    """Allow-list unpickler that also rebuilds joblib's arrays (used only when a file holds them)."""

    dispatch = dict(pickle._Unpickler.dispatch)  # type: ignore[attr-defined]

    def __init__(self, fh: object, path: Path, size: int | None = None):
        super().__init__(fh)
        self._fh, self._path, self._size = fh, path, size

    def find_class(self, module: str, name: str) -> object:
        return _allowed_global(module, name)

    def _load_build(self) -> None:
        pickle._Unpickler.load_build(self)  # type: ignore[attr-defined]
        top = self.stack[-1]
        if isinstance(top, _JoblibArray):
            remaining = None if self._size is None else self._size - self._fh.tell()  # type: ignore[attr-defined]
            self.stack[-1] = top.read(self._fh, self._path, remaining)

    dispatch[pickle.BUILD[0]] = _load_build


class _FastRestricted(pickle.Unpickler):
    """The C unpickler with the same allow-list (plain pickles); joblib arrays need :class:`_Restricted`."""

    def find_class(self, module: str, name: str) -> object:
        if (module, name) == _JOBLIB_WRAPPER:
            raise _RefusedGlobal("joblib")
        return _allowed_global(module, name)


def _open_stream(path: Path) -> tuple[object, int | None]:
    """A binary stream over the pickle bytes (decompressing joblib's formats) and its size if known."""
    import bz2
    import gzip
    import io
    import lzma
    import zlib

    with open(path, "rb") as f:
        head = f.read(8)
    for magic, what in _REFUSED_MAGIC:
        if head.startswith(magic):
            raise InputError(path, "<file>", f"{what} is not supported", "a pickle or an uncompressed/gzip joblib file")
    for magic, kind in _COMPRESSED:
        if head.startswith(magic):
            if kind == "zlib":
                return io.BytesIO(zlib.decompress(path.read_bytes())), None
            opener = {"gzip": gzip.open, "bz2": bz2.open, "xz": lzma.open, "lzma": lzma.open}[kind]
            return opener(path, "rb"), None
    return open(path, "rb"), path.stat().st_size


def safe_pickle_load(path: str | Path) -> object:
    """Load a pickle (or joblib file) that may hold only numpy arrays/dtypes/scalars and builtin containers.

    Allowed globals: numpy's ``_reconstruct``, ``scalar`` and ``_frombuffer`` (``numpy.core`` or
    ``numpy._core``), ``numpy.dtype``, ``numpy.ndarray``; builtins dict, list, tuple, set, frozenset, str, bytes,
    bytearray, int, float, bool, complex, slice, range; ``_codecs.encode`` (latin-1 only: bytes in protocol-2
    pickles); joblib's ``NumpyArrayWrapper`` (rebuilt here; nothing of joblib is imported). Any other global
    (a class, ``os.system``, ...) raises :class:`InputError` naming the file and the refused global, before
    anything is called. Corrupt or truncated files raise :class:`InputError` as well.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(path, None, "file not found")
    for fast in (True, False):
        try:
            stream, size = _open_stream(path)
            with stream:  # type: ignore[attr-defined]
                if fast:
                    return _FastRestricted(stream).load()  # type: ignore[arg-type]
                return _Restricted(stream, path, size).load()
        except _RefusedGlobal as exc:
            if fast and exc.name == "joblib":
                continue  # the file holds joblib arrays: read it again with the hooked unpickler
            raise InputError(
                path, "<pickle>", f"refused global {exc.name}", "numpy arrays and builtin containers only"
            ) from None
        except InputError:
            raise
        except Exception as exc:  # noqa: BLE001 - truncated / not a pickle / decompression errors
            if isinstance(exc, OSError) and exc.errno:  # the file itself cannot be read (permission, I/O error)
                raise InputError(path, None, f"cannot be read ({_exception_line(exc)})", "a pickle file") from None
            raise InputError(
                path, "<pickle>", f"cannot be unpickled ({_exception_line(exc)})", "a pickle file"
            ) from None
    raise AssertionError("unreachable")


def _exception_line(exc: BaseException, limit: int = 200) -> str:
    """``<type>: <message>`` of an exception on one line: the first line of its message, whole; past ``limit``
    characters its first sentence, cut at a word (marked `` ...``) only if that is still too long. An OSError
    with an errno gives its ``strerror``."""
    if isinstance(exc, OSError) and exc.errno:
        return exc.strerror or os.strerror(exc.errno)
    first = " ".join(next((ln for ln in str(exc).splitlines() if ln.strip()), "").split())
    detail = first if len(first) <= limit else first_sentence(first, limit)
    return f"{type(exc).__name__}: {detail}" if detail else type(exc).__name__


def safe_npz_load(path: str | Path) -> dict[str, np.ndarray]:
    """All arrays of an ``.npz``; object arrays are rebuilt with the restricted unpickler (no code runs)."""
    import io
    import zipfile

    path = Path(path)
    out: dict[str, np.ndarray] = {}
    try:
        with zipfile.ZipFile(path) as z:
            for member in z.namelist():
                if not member.endswith(".npy"):
                    continue
                with z.open(member) as fh:
                    version = np.lib.format.read_magic(fh)
                    fmt = np.lib.format
                    read_header = fmt.read_array_header_1_0 if version == (1, 0) else fmt.read_array_header_2_0
                    _, _, dtype = read_header(fh)
                    if dtype.hasobject:
                        obj = _Restricted(io.BytesIO(fh.read()), path).load()
                    else:
                        obj = None
                if obj is None:
                    with z.open(member) as fh:
                        obj = np.lib.format.read_array(fh, allow_pickle=False)
                out[member[: -len(".npy")]] = np.asarray(obj) if not isinstance(obj, np.ndarray) else obj
    except _RefusedGlobal as exc:
        raise InputError(path, "<npz>", f"refused global {exc.name}", "numeric arrays") from None
    except (zipfile.BadZipFile, ValueError, OSError, EOFError, pickle.UnpicklingError) as exc:
        raise InputError(
            path, "<npz>", f"cannot be read ({type(exc).__name__}: {str(exc)[:120]})", "an .npz file"
        ) from None
    return out
