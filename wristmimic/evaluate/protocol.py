"""Evaluation protocols and scene splits as data: ``eval/protocols/<name>.toml`` and ``eval/splits/<name>.toml``.

A protocol fixes how trials are run and judged (trial count, start frame, noise, base seed, success thresholds);
a split names the scenes of a benchmark (the paper's 20 OMOMO and 20 ParaHome sequences). Both are loaded by
name (a file in ``eval/``) or by path, and validated with one-line :class:`InputError` messages.

>>> protocol = load_protocol("paper")      # eval/protocols/paper.toml
>>> split = load_split("parahome20")       # eval/splits/parahome20.toml
"""

from __future__ import annotations

import os
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import wristmimic
from wristmimic.errors import InputError

NOISE_MODES = ("actions", "initial-state")
"""How trials differ: sampled actions from the policy's Gaussian, or a perturbed frame-0 state (mean actions)."""
TERMINATION_MODES = ("run", "base")
"""Early terminations at evaluation: the run's own (its variant's), or the base ones only (no wrist resets)."""


def eval_dir() -> Path:
    """The folder holding ``protocols/`` and ``splits/``: ``$WRISTMIMIC_EVAL_DIR`` or ``eval/`` of the checkout."""
    env = os.environ.get("WRISTMIMIC_EVAL_DIR")
    return Path(env) if env else Path(wristmimic.__file__).resolve().parents[1] / "eval"


@dataclass(frozen=True)
class InitialStateNoise:
    """Gaussian perturbation of the frame-0 state in ``initial-state`` mode (standard deviations)."""

    joint_angle_rad: float = 0.05
    """Added to every hinge angle."""
    root_position_m: float = 0.01
    """Added to the root position (x, y, z)."""


@dataclass(frozen=True)
class Protocol:
    """How trials run and when one succeeds (paper: 10,000 trials per scene from frame 0)."""

    name: str
    description: str
    trials: int
    """Trials per scene."""
    start_frame: int
    """Frame every trial starts from (only 0 is supported: the paper's protocol)."""
    noise: str
    """One of :data:`NOISE_MODES`."""
    base_seed: int
    """Trial k's seed is ``trial_seed(base_seed, k)`` (wristmimic.evaluate.noise)."""
    max_object_position_error_m: float
    """Success needs the trial's mean object position error below this (paper: 0.10 m)."""
    min_contact_ratio: float
    """Success needs hand contact kept for at least this share of the reference contact duration (paper: 0.8)."""
    early_termination: str = "run"
    """One of :data:`TERMINATION_MODES`."""
    initial_state_noise: InitialStateNoise = InitialStateNoise()
    path: str = ""
    """The file it was read from."""

    def to_dict(self) -> dict[str, Any]:
        """Plain values (for ``summary.json``), without the file path."""
        return {
            "name": self.name,
            "trials": self.trials,
            "start_frame": self.start_frame,
            "noise": self.noise,
            "base_seed": self.base_seed,
            "max_object_position_error_m": self.max_object_position_error_m,
            "min_contact_ratio": self.min_contact_ratio,
            "early_termination": self.early_termination,
            "initial_state_noise": {
                "joint_angle_rad": self.initial_state_noise.joint_angle_rad,
                "root_position_m": self.initial_state_noise.root_position_m,
            },
        }


@dataclass(frozen=True)
class SplitScene:
    """One scene of a split: its sequence id as our converters name it, and where it comes from."""

    id: str
    subject: str = ""
    clip: str = ""
    start: int | None = None
    end: int | None = None
    note: str = ""


@dataclass(frozen=True)
class Split:
    """A benchmark's scene list for one dataset."""

    name: str
    dataset: str
    """``source_dataset`` of the canonical file (``omomo``, ``parahome``)."""
    label: str
    """Display name in tables (``OMOMO``, ``ParaHome``)."""
    description: str
    scenes: tuple[SplitScene, ...]
    path: str = ""

    @property
    def ids(self) -> list[str]:
        return [s.id for s in self.scenes]


def _resolve(name_or_path: str | Path, kind: str) -> Path:
    p = Path(name_or_path)
    if p.suffix == ".toml" or p.is_file():
        if not p.is_file():
            raise InputError(p, None, f"{kind} file not found")
        return p
    folder = eval_dir() / kind
    f = folder / f"{name_or_path}.toml"
    if not f.is_file():
        known = sorted(x.stem for x in folder.glob("*.toml")) if folder.is_dir() else []
        raise InputError(
            f, None, f"unknown {kind[:-1]} {str(name_or_path)!r}", f"one of {', '.join(known) or '(none)'}"
        )
    return f


def _read(path: Path) -> dict[str, Any]:
    try:
        return tomllib.loads(path.read_text())
    except tomllib.TOMLDecodeError as exc:
        raise InputError(path, None, f"not valid TOML ({exc})") from None


def _get(d: dict[str, Any], key: str, typ: type | tuple[type, ...], path: Path, prefix: str = "") -> Any:
    full = prefix + key
    if key not in d:
        raise InputError(path, full, "missing")
    v = d[key]
    ok = isinstance(v, typ) and not (isinstance(v, bool) and typ in (int, float, (int, float)))
    if not ok:
        names = " or ".join(t.__name__ for t in (typ if isinstance(typ, tuple) else (typ,)))
        raise InputError(path, full, f"{v!r} is a {type(v).__name__}", f"a {names}")
    return v


def _unknown(d: dict[str, Any], allowed: set[str], path: Path, prefix: str = "") -> None:
    extra = sorted(set(d) - allowed)
    if extra:
        raise InputError(path, prefix + extra[0], "unknown key", f"one of {', '.join(sorted(allowed))}")


def load_protocol(name_or_path: str | Path) -> Protocol:
    """Read and validate a protocol by name (``eval/protocols/<name>.toml``) or path."""
    path = _resolve(name_or_path, "protocols")
    d = _read(path)
    _unknown(
        d,
        {"name", "description", "trials", "start_frame", "noise", "base_seed", "early_termination", "success",
         "initial_state_noise"},
        path,
    )  # fmt: skip
    trials = _get(d, "trials", int, path)
    if trials < 1:
        raise InputError(path, "trials", f"{trials}", "an integer >= 1")
    start = _get(d, "start_frame", int, path)
    if start != 0:
        raise InputError(path, "start_frame", f"{start}", "0 (trials start at the first frame, as in the paper)")
    noise = _get(d, "noise", str, path)
    if noise not in NOISE_MODES:
        raise InputError(path, "noise", f"{noise!r}", f"one of {', '.join(NOISE_MODES)}")
    seed = _get(d, "base_seed", int, path)
    if not 0 <= seed < 2**63:
        raise InputError(path, "base_seed", f"{seed}", "an integer in [0, 2^63)")
    term = d.get("early_termination", "run")
    if term not in TERMINATION_MODES:
        raise InputError(path, "early_termination", f"{term!r}", f"one of {', '.join(TERMINATION_MODES)}")
    success = _get(d, "success", dict, path)
    _unknown(success, {"max_object_position_error_m", "min_contact_ratio"}, path, "success.")
    pos = float(_get(success, "max_object_position_error_m", (int, float), path, "success."))
    ratio = float(_get(success, "min_contact_ratio", (int, float), path, "success."))
    if pos <= 0:
        raise InputError(path, "success.max_object_position_error_m", f"{pos}", "a distance > 0 (m)")
    if not 0.0 <= ratio <= 1.0:
        raise InputError(path, "success.min_contact_ratio", f"{ratio}", "a share in [0, 1]")
    isn = d.get("initial_state_noise", {})
    if not isinstance(isn, dict):
        raise InputError(path, "initial_state_noise", "not a table", "[initial_state_noise]")
    _unknown(isn, {"joint_angle_rad", "root_position_m"}, path, "initial_state_noise.")
    noise_cfg = InitialStateNoise(
        **{k: float(_get(isn, k, (int, float), path, "initial_state_noise.")) for k in isn}  # type: ignore[arg-type]
    )
    if min(noise_cfg.joint_angle_rad, noise_cfg.root_position_m) < 0:
        raise InputError(path, "initial_state_noise", "negative standard deviation", "values >= 0")
    return Protocol(
        name=str(d.get("name", path.stem)),
        description=str(d.get("description", "")),
        trials=trials,
        start_frame=start,
        noise=noise,
        base_seed=seed,
        max_object_position_error_m=pos,
        min_contact_ratio=ratio,
        early_termination=term,
        initial_state_noise=noise_cfg,
        path=str(path),
    )


def load_split(name_or_path: str | Path) -> Split:
    """Read and validate a split by name (``eval/splits/<name>.toml``) or path."""
    path = _resolve(name_or_path, "splits")
    d = _read(path)
    _unknown(d, {"name", "dataset", "label", "description", "scenes"}, path)
    dataset = _get(d, "dataset", str, path)
    scenes_raw = _get(d, "scenes", list, path)
    if not scenes_raw:
        raise InputError(path, "scenes", "empty", "at least one [[scenes]] entry")
    scenes: list[SplitScene] = []
    seen: set[str] = set()
    for i, s in enumerate(scenes_raw):
        key = f"scenes[{i}]."
        if not isinstance(s, dict):
            raise InputError(path, f"scenes[{i}]", "not a table", "[[scenes]] entries")
        _unknown(s, {"id", "subject", "clip", "start", "end", "note"}, path, key)
        sid = _get(s, "id", str, path, key)
        if not sid or sid in seen:
            raise InputError(path, key + "id", f"{sid!r} is empty or repeated", "unique sequence ids")
        seen.add(sid)
        start, end = s.get("start"), s.get("end")
        for k, v in (("start", start), ("end", end)):
            if v is not None and (not isinstance(v, int) or isinstance(v, bool) or v < 0):
                raise InputError(path, key + k, f"{v!r}", "a frame index >= 0")
        if start is not None and end is not None and end <= start:
            raise InputError(path, key + "end", f"{end} <= start {start}", "end > start")
        scenes.append(
            SplitScene(sid, str(s.get("subject", "")), str(s.get("clip", "")), start, end, str(s.get("note", "")))
        )
    return Split(
        name=str(d.get("name", path.stem)),
        dataset=dataset,
        label=str(d.get("label", dataset)),
        description=str(d.get("description", "")),
        scenes=tuple(scenes),
        path=str(path),
    )


def available(kind: str) -> list[str]:
    """Names of the protocols (``kind="protocols"``) or splits (``"splits"``) in :func:`eval_dir`."""
    folder = eval_dir() / kind
    return sorted(p.stem for p in folder.glob("*.toml")) if folder.is_dir() else []
