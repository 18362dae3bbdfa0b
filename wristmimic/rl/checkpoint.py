"""Checkpoint files: written atomically, read with ``torch.load(weights_only=True)`` (tensors, plain containers
and JSON text only), plus the random-number-generator states a bit-for-bit resume needs."""

from __future__ import annotations

import json
import os
from concurrent.futures import Future, ThreadPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np
import torch

from wristmimic.errors import InputError
from wristmimic.safe_io import OutputError, atomic_output, torch_load_untrusted

CHECKPOINT_NAME = "checkpoint.pt"
CHECKPOINT_FORMAT = "wristmimic-ppo-checkpoint"
CHECKPOINT_VERSION = 1
INIT_NAME = "init.pt"
"""A warm-started run's copy of the checkpoint it started from (``--init-from``), taken when it started, so the run
can be started again from it after the source has trained on (``--init-from RUN/init.pt``)."""
RUN_FILES = ("config.json", "metrics.csv", CHECKPOINT_NAME, INIT_NAME)
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
    except (OSError, RuntimeError, OutputError) as exc:  # torch's zip writer reports a failed write as RuntimeError
        reason = exc.reason if isinstance(exc, OutputError) else _reason(exc)
        raise InputError(path, None, f"not written ({reason})", "a writable folder with free space") from None


def snapshot(state: Any) -> Any:
    """A copy of ``state`` that shares no memory with the training: every tensor (and numpy array) copied into CPU
    memory, dicts, lists and tuples rebuilt, other values (numbers, text) kept; so that it can be written while
    training goes on."""
    if isinstance(state, torch.Tensor):
        return state.detach().to("cpu", copy=True)
    if isinstance(state, dict):
        return {k: snapshot(v) for k, v in state.items()}
    if type(state) in (list, tuple):
        return type(state)(snapshot(v) for v in state)
    if isinstance(state, np.ndarray):
        return state.copy()
    return state


class CheckpointWriter:
    """Writes checkpoints with :func:`save_checkpoint` in one background thread, at most one at a time.

    :meth:`submit` starts writing a :func:`snapshot` of the state and returns at once; :meth:`collect` waits for
    that write and takes its outcome, and must be called before the next :meth:`submit`: writes never queue up. A write that fails removes its temporary file and leaves the previous checkpoint as it was."""

    def __init__(self, path: Path):
        self.path = Path(path)
        self._pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="checkpoint-writer")
        self._pending: tuple[int, Future[None]] | None = None

    def submit(self, state: dict[str, Any], tag: int) -> None:
        """Start writing ``state`` (a snapshot: nothing the caller changes afterwards) tagged ``tag``."""
        if self._pending is not None:
            raise RuntimeError(f"checkpoint write {self._pending[0]} not collected before the next one")
        self._pending = (tag, self._pool.submit(save_checkpoint, self.path, state))

    def collect(self) -> tuple[int, BaseException | None] | None:
        """Wait for the write in flight: ``(tag, None)`` if it succeeded, ``(tag, error)`` if it failed (an
        :class:`InputError` for a failed write), None if there is none."""
        if self._pending is None:
            return None
        tag, future = self._pending
        exc = future.exception()  # an interrupted wait (a second Ctrl-C) keeps the write to collect again
        self._pending = None
        return tag, exc

    def close(self) -> None:
        """Wait for the write in flight (its outcome is dropped unless collected) and stop the thread."""
        self._pool.shutdown(wait=True)
        self._pending = None


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


_EXPECTED = "a checkpoint written by `wristmimic train`"
_STATE_TYPES: dict[str, tuple[type, ...]] = {
    "config": (str,),
    "metadata": (dict,),
    "policy": (dict,),
    "iteration": (int,),
    "frames": (int,),
    "seconds": (int, float),
    "optimizer": (dict,),
    "rng": (dict,),
    "env": (dict,),
    "obs": (torch.Tensor,),
    "episodes": (dict,),
    "storage_step": (int,),
}
"""Entries every checkpoint has (``Runner.state_dict``) and the types readers rely on."""
_CONFIG_KEYS = ("ppo", "env", "dataset")
_METADATA_TYPES: dict[str, tuple[type, ...]] = {
    "scene": (str,),
    "variant": (str,),
    "dataset_sha256": (str,),
    "seed": (int,),
}


def _kind(value: object) -> str:
    return "nothing" if value is None else f"a {type(value).__name__}"


def _check_state(path: Path, state: dict[str, Any]) -> None:
    """One-line :class:`InputError` for a checkpoint that lacks what evaluate, view or resume read."""
    for key, types in _STATE_TYPES.items():
        if key not in state:
            raise InputError(path, key, "missing", _EXPECTED)
        if not isinstance(state[key], types):
            raise InputError(path, key, f"holds {_kind(state[key])}", f"{' or '.join(t.__name__ for t in types)}")
    try:
        config = json.loads(state["config"])
    except json.JSONDecodeError as exc:
        raise InputError(path, "config", f"not valid JSON ({exc.msg})", "the run's config.json text") from None
    if not isinstance(config, dict):
        raise InputError(path, "config", f"holds a JSON {type(config).__name__}", "a JSON object")
    for key in _CONFIG_KEYS:
        if not isinstance(config.get(key), dict):
            raise InputError(path, f"config.{key}", "missing" if key not in config else "not an object", _EXPECTED)
    for key in ("path", "sha256"):
        if not isinstance(config["dataset"].get(key), str):
            raise InputError(path, f"config.dataset.{key}", "missing or not a string", _EXPECTED)
    for key, types in _METADATA_TYPES.items():
        if not isinstance(state["metadata"].get(key), types):
            raise InputError(
                path, f"metadata.{key}", "missing" if key not in state["metadata"] else "wrong type", _EXPECTED
            )
    for entry in ("policy", "deploy_policy", "ema_policy"):
        weights = state.get(entry)
        if weights is None and entry != "policy":
            continue
        if not isinstance(weights, dict):
            raise InputError(path, entry, f"holds {_kind(weights)}", "a dict of tensors")
        bad = next((k for k, v in weights.items() if not isinstance(v, torch.Tensor)), None)
        if bad is not None:
            raise InputError(path, f"{entry}.{bad}", f"holds {_kind(weights[bad])}", "a tensor")
        for keys in (("normalizer.mean",), ("log_std_param", "log_std")):
            if not any(k in weights for k in keys):
                raise InputError(path, f"{entry}.{keys[0]}", "missing", "the policy network's weights")


def _check_deploy(path: Path, state: dict[str, Any]) -> None:
    """The ``deploy`` record (which weights ``deploy_policy`` holds), where a checkpoint has one."""
    deploy = state.get("deploy")
    if deploy is None:
        return
    if not isinstance(deploy, dict) or deploy.get("weights") not in ("latest", "ema", "best"):
        raise InputError(path, "deploy", "not a deployment record", "{'weights': 'latest' | 'ema' | 'best', ...}")
    if (deploy["weights"] != "latest") != ("deploy_policy" in state):
        raise InputError(path, "deploy_policy", f"inconsistent with deploy weights {deploy['weights']!r}", _EXPECTED)
    for key in ("iteration", "frames"):
        if not isinstance(deploy.get(key), int):
            raise InputError(path, f"deploy.{key}", "missing or not an integer", _EXPECTED)


def load_checkpoint(run_dir_or_file: str | Path, data: bytes | None = None) -> dict[str, Any]:
    """Load a checkpoint on the CPU without running code from the file; one-line :class:`InputError` for a file
    that is not a complete wristmimic checkpoint (text, random bytes, a refused pickle, a missing config, ...).
    ``data``: the checkpoint file's bytes, already read."""
    path = checkpoint_path(run_dir_or_file)
    state = torch_load_untrusted(path, _EXPECTED, data)
    if not isinstance(state, dict) or state.get("format") != CHECKPOINT_FORMAT:
        raise InputError(path, "format", "not a wristmimic PPO checkpoint", _EXPECTED)
    if state.get("version") != CHECKPOINT_VERSION:
        raise InputError(path, "version", f"version {state.get('version')}", f"version {CHECKPOINT_VERSION}")
    _check_state(path, state)
    _check_deploy(path, state)
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
