"""Safe reading of untrusted files and atomic writing of outputs."""

from __future__ import annotations

import contextlib
import hashlib
import os
import pickle
import tempfile
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from wristmimic.errors import InputError


def sha256_file(path: str | Path, chunk: int = 1 << 20) -> str:
    """Hex sha256 of a file's bytes."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        while block := f.read(chunk):
            h.update(block)
    return h.hexdigest()


@contextlib.contextmanager
def atomic_output(path: str | Path, suffix: str = "") -> Iterator[Path]:
    """Yield a temporary path beside ``path``; on success rename it onto ``path``, on failure delete it.

    Nothing half-written is ever left at ``path``. Raises :class:`InputError` if the folder is not writable.
    """
    path = Path(path)
    parent = path.parent if str(path.parent) else Path(".")
    if not parent.is_dir():
        raise InputError(path, None, f"output folder {parent} does not exist")
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=suffix + ".tmp", dir=parent)
    except OSError as exc:
        raise InputError(path, None, f"output folder is not writable ({exc.strerror})") from None
    os.close(fd)
    tmp_path = Path(tmp)
    try:
        yield tmp_path
        os.replace(tmp_path, path)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            tmp_path.unlink()
        raise


def load_pt_tensor(path: str | Path, *, ndim: int = 2) -> np.ndarray:
    """Load a ``.pt`` file that must hold one plain tensor; returns float64 numpy.

    Uses ``torch.load(weights_only=True, map_location="cpu")``: a pickle carrying code is refused, and
    files saved on CUDA load on the CPU. Checks the rank and that every value is finite.
    """
    import torch

    path = Path(path)
    try:
        obj = torch.load(path, weights_only=True, map_location="cpu")
    except pickle.UnpicklingError as exc:
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else "refused"
        raise InputError(
            path, "<pickle>", f"not a plain tensor file: {first[:200]}", "a tensor saved by torch.save"
        ) from None
    except Exception as exc:  # truncated zip, not a torch file, ...
        raise InputError(
            path,
            "<file>",
            f"cannot be read by torch.load ({type(exc).__name__}: "
            f"{str(exc).splitlines()[0][:160] if str(exc) else ''})",
            "a tensor saved by torch.save",
        ) from None
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
