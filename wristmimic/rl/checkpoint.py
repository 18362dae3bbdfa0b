"""Checkpoint files: written atomically, read with ``torch.load(weights_only=True)`` (tensors, plain containers
and JSON text only), plus the random-number-generator states a bit-for-bit resume needs."""

from __future__ import annotations

import os
import pickle
from pathlib import Path
from typing import Any

import numpy as np
import torch

from wristmimic.errors import InputError
from wristmimic.safe_io import atomic_output

CHECKPOINT_NAME = "checkpoint.pt"
CHECKPOINT_FORMAT = "wristmimic-ppo-checkpoint"
CHECKPOINT_VERSION = 1
RUN_FILES = ("config.json", "metrics.csv", CHECKPOINT_NAME)
"""The files of a run folder."""


def checkpoint_path(run_dir_or_file: str | Path) -> Path:
    """``RUN_DIR/checkpoint.pt`` for a run folder, else the file itself; :class:`InputError` if missing."""
    p = Path(run_dir_or_file)
    f = p / CHECKPOINT_NAME if p.is_dir() else p
    if not f.is_file():
        raise InputError(f, None, "no checkpoint found", f"a run folder with {CHECKPOINT_NAME} or a .pt file")
    return f


def save_checkpoint(path: Path, state: dict[str, Any]) -> None:
    """Write ``state`` (tagged with the format and version) so that a crash never leaves half a file: into a
    temporary file beside ``path``, flushed to disk, then renamed over it. A failed write (full disk, file size
    limit) raises :class:`InputError` with the system's reason; the previous ``path`` is untouched and the
    temporary file removed."""
    try:
        with atomic_output(path, suffix=".pt") as tmp, open(tmp, "wb") as f:
            torch.save({"format": CHECKPOINT_FORMAT, "version": CHECKPOINT_VERSION, **state}, f)
            f.flush()
            os.fsync(f.fileno())
    except (OSError, RuntimeError) as exc:  # torch's zip writer reports a failed write as RuntimeError
        raise InputError(path, None, f"not written ({_reason(exc)})", "a writable folder with free space") from None


def _reason(exc: BaseException) -> str:
    """The operating system's words for a failed write (``No space left on device``), else the first line."""
    e: BaseException | None = exc
    while e is not None:
        if isinstance(e, OSError) and e.strerror:
            return e.strerror
        e = e.__cause__ or e.__context__
    return (str(exc).strip().splitlines() or [type(exc).__name__])[0][:160]


def remove_stale_temporaries(run_dir: Path) -> list[Path]:
    """Delete the temporary files an atomic write leaves when its process is killed (``.checkpoint.pt.*.tmp``,
    ``.metrics.csv.*.tmp``, ``.config.json.*.tmp``) from a run folder; returns them."""
    stale = [p for name in RUN_FILES for p in Path(run_dir).glob(f".{name}.*.tmp")]
    for p in stale:
        p.unlink(missing_ok=True)
    return stale


def load_checkpoint(run_dir_or_file: str | Path) -> dict[str, Any]:
    """Load a checkpoint on the CPU without running code from the file."""
    path = checkpoint_path(run_dir_or_file)
    try:
        state = torch.load(path, weights_only=True, map_location="cpu")
    except (pickle.UnpicklingError, RuntimeError, EOFError, OSError) as exc:
        first = (str(exc).strip().splitlines() or [type(exc).__name__])[0][:160]
        raise InputError(path, None, f"cannot be loaded ({first})", "a wristmimic checkpoint") from None
    if not isinstance(state, dict) or state.get("format") != CHECKPOINT_FORMAT:
        raise InputError(path, "format", "not a wristmimic PPO checkpoint")
    if state.get("version") != CHECKPOINT_VERSION:
        raise InputError(path, "version", f"version {state.get('version')}", f"version {CHECKPOINT_VERSION}")
    return state


def rng_state(generator: torch.Generator) -> dict[str, Any]:
    """torch (global and the runner's generator) and numpy global RNG states as tensors and ints."""
    kind, keys, pos, has_gauss, cached = np.random.get_state()
    return {
        "torch": torch.get_rng_state(),
        "generator": generator.get_state(),
        "numpy_keys": torch.from_numpy(np.asarray(keys, dtype=np.int64)),
        "numpy_pos": int(pos),
        "numpy_has_gauss": int(has_gauss),
        "numpy_cached_gaussian": float(cached),
        "numpy_kind": str(kind),
    }


def set_rng_state(state: dict[str, Any], generator: torch.Generator) -> None:
    torch.set_rng_state(state["torch"])
    generator.set_state(state["generator"].cpu())
    keys = state["numpy_keys"].numpy().astype(np.uint32)
    np.random.set_state(
        (state["numpy_kind"], keys, state["numpy_pos"], state["numpy_has_gauss"], state["numpy_cached_gaussian"])
    )
