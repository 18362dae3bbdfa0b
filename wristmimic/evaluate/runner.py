"""``evaluate``: run a protocol's trials for one policy, keep them interrupt-safe, write tables and a summary.

Output folder (default ``<run_dir>/eval/<protocol>``)::

    eval.json                         settings (checked when a rerun resumes)
    parts/<scene>/trials-<a>-<b>.parquet   completed trials a..b-1, each written atomically as it completes
    <scene>.parquet                   all trials, sorted by trial (see metrics.TRIAL_COLUMNS)
    summary.json, summary.csv         per-scene success rate (Wilson 95 % interval), errors, terminations
    timing.json                       wall time and trials/s of the last session (the only non-deterministic file)

A rerun of the same command runs only the trials no part file holds (a part that is truncated or corrupt, e.g.
after a power cut, is said on stderr, deleted and recomputed; intact parts are never rewritten); because every
trial is a pure function of its seed, the final files are identical to an uninterrupted run. A failed write (disk
full, quota, file size limit) stops with a one-line :class:`~wristmimic.safe_io.OutputError`: the parts already
written stay, the final table and summaries are written together or not at all.
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import re
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from wristmimic.env.config import WristThresholds
from wristmimic.env.terminations import REASONS
from wristmimic.errors import InputError, WristmimicError
from wristmimic.evaluate.metrics import TRIAL_COLUMNS, wilson_interval
from wristmimic.evaluate.policy import EvalPolicy
from wristmimic.evaluate.protocol import NOISE_MODES, Protocol, Split, available, load_split
from wristmimic.evaluate.trials import Records, TrialSettings, make_env, run_trials
from wristmimic.safe_io import OutputError, atomic_output, is_write_failure, sha256_file
from wristmimic.sim.backend import BACKENDS

EVAL_FORMAT, EVAL_VERSION = "wristmimic-eval", 1
DATASET_LABELS = {"omomo": "OMOMO", "parahome": "ParaHome"}
METHOD_LABELS = {
    "wristmimic": "WristMimic (Ours)",
    "decoupled": "Decoupled (No Wrist Constraints)",
    "reward-modulation-only": "+ reward weight modulation only",
    "reset-only": "+ phase specific reset only",
    "finger-guidance": "Ours + Finger Guidance",
    "intermimic": "InterMimic",
}
"""Display names of the environment variants, as in the paper's tables."""
TERMINATION_NAMES = [REASONS[k] for k in sorted(REASONS) if k != 0]
SUMMARY_COLUMNS = [
    "scene", "dataset", "dataset_label", "split", "method", "variant", "protocol", "noise", "trials", "successes",
    "success_rate", "success_ci_low", "success_ci_high", "obj_pos_err_cm", "obj_rot_err_deg", "wrist_pos_err_cm",
    "wrist_rot_err_deg", "contact_ratio", "completion_rate", "frames_completed_mean", "frames_total",
    *(f"terminated_{n}" for n in TERMINATION_NAMES),
    "strict_successes", "strict_success_rate", "strict_success_ci_low", "strict_success_ci_high", "obj_pos_err_peak_cm",
]  # fmt: skip
"""Columns of ``summary.csv`` in order."""


class EvalInterrupted(WristmimicError):
    """Ctrl-C during an evaluation; completed trials were kept."""

    def __init__(self, out: Path, completed: int, total: int):
        self.out, self.completed, self.total = out, completed, total
        super().__init__(f"{out}: interrupted after {completed:,}/{total:,} trials (kept; rerun to resume)")


@dataclass
class EvalResult:
    out: Path
    summary: dict[str, Any]
    trials_run: int
    """Trials run in this session (0 when everything was already complete)."""
    seconds: float
    frames: int = 0
    """Frames stepped by this session's trials."""
    parquet: Path = field(default_factory=Path)


def method_label(variant: str, env: dict[str, Any] | None, hand: str = "") -> str:
    """The variant's display name, with the grasp-phase wrist thresholds when they are not the default and the
    swapped hand (``[hand NAME]``) when the humanoid carries one."""
    label = METHOD_LABELS.get(variant, variant)
    wrist = (env or {}).get("wrist") or {}
    d = WristThresholds()
    gp, gr = wrist.get("grasp_pos", d.grasp_pos), wrist.get("grasp_rot", d.grasp_rot)
    if (gp, gr) != (d.grasp_pos, d.grasp_rot):
        label += f" [grasp {100 * gp:g} cm / {gr:g} rad]"
    if hand:
        label += f" [hand {hand}]"
    return label


def find_split(scene: str, name: str | None = None) -> Split | None:
    """The split ``name`` (the scene must belong to it), else the first split in ``eval/splits`` that lists it."""
    if name:
        split = load_split(name)
        if scene not in split.ids:
            raise InputError(split.path, "scenes", f"scene {scene!r} is not in split {split.name!r}")
        return split
    for n in available("splits"):
        s = load_split(n)
        if scene in s.ids:
            return s
    return None


def _settings_dict(
    protocol: Protocol, policy: EvalPolicy, trials: TrialSettings, env: dict[str, Any], backend: str = "cpu"
) -> dict:
    m = policy.metadata
    physics = {} if backend == "cpu" else {"backend": backend}  # CPU: as written before backends existed
    return {
        **physics,
        "format": EVAL_FORMAT,
        "version": EVAL_VERSION,
        "protocol": protocol.name,
        "scene": m["scene"],
        "variant": m.get("variant", ""),
        "checkpoint_sha256": m.get("checkpoint_sha256", ""),
        "dataset_sha256": m.get("dataset_sha256", ""),
        "ref_frames": m.get("ref_frames"),
        "base_seed": trials.base_seed,
        "noise": trials.noise,
        # the sigma of the sampled actions (mean over action dimensions; a run's ppo.deploy_std when set)
        **({"action_sigma": float(policy.sigma.mean())} if trials.noise == "actions" else {}),
        # the deployed weights where they are not the last update's: a moving average (ppo.deploy_ema) or the best
        # periodically evaluated policy (ppo.deploy_best), and their training iteration
        **(
            {"policy_weights": m["policy_weights"], "policy_weights_iteration": m.get("policy_weights_iteration")}
            if m.get("policy_weights", "latest") != "latest"
            else {}
        ),
        "max_object_position_error_m": trials.max_obj_pos_err_m,
        "min_contact_ratio": trials.min_contact_ratio,
        "early_termination": protocol.early_termination,
        "initial_state_noise": protocol.to_dict()["initial_state_noise"],
        "env": env,
    }


_PART = re.compile(r"^trials-(\d{8})-(\d{8})\.parquet$")


def _say(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


def _damaged(exc: BaseException) -> str:
    first = (str(exc).strip().splitlines() or [""])[0][:120]
    return f"truncated or corrupt ({type(exc).__name__}: {first})"


def _part_problem(path: Path, start: int, stop: int) -> str | None:
    """Why the part file ``path`` (trials ``start .. stop - 1``) cannot be used, or None if it is intact."""
    try:
        df = pd.read_parquet(path)
    except OSError as exc:
        if exc.errno is not None:  # the file system failed (permission, I/O error), not the file: keep it
            raise InputError(path, None, f"cannot be read ({os.strerror(exc.errno)})", "a readable part file") from None
        return _damaged(exc)  # pyarrow's own "I/O" errors: a corrupt page, footer or thrift header
    except Exception as exc:  # noqa: BLE001 - truncated, empty, not parquet: all mean "run these trials again"
        return _damaged(exc)
    missing = [c for c in TRIAL_COLUMNS if c not in df.columns]
    if missing:
        return f"lacks column(s) {', '.join(missing)}"
    if df["trial"].tolist() != list(range(start, stop)):
        return f"holds {len(df)} rows, not trials {start}-{stop - 1}"
    return None


def scan_parts(
    folder: Path, n_trials: int, say: Callable[[str], None] = _say
) -> tuple[list[tuple[int, int, Path]], list[tuple[int, int]]]:
    """The intact part files that cover trials ``0 .. n_trials - 1`` in order ([(start, stop, path)]), and the
    ranges no intact part covers ([(start, stop)], the trials still to run).

    Every part is read back; one that is truncated or corrupt is reported through ``say`` (one line) and
    deleted, so that its trials are run again. Intact parts are kept, also those after a gap.
    """
    parts: dict[int, tuple[int, Path]] = {}
    for p in sorted(folder.glob("trials-*.parquet")) if folder.is_dir() else []:
        m = _PART.match(p.name)
        if not m or int(m.group(2)) <= int(m.group(1)):
            continue
        a, b = int(m.group(1)), int(m.group(2))
        problem = _part_problem(p, a, b)
        if problem:
            say(f"{p}: {problem}; deleted, trials {a}-{b - 1} will be run again")
            with contextlib.suppress(FileNotFoundError):
                p.unlink()
            continue
        if b > parts.get(a, (0, p))[0]:
            parts[a] = (b, p)
    chain: list[tuple[int, int, Path]] = []
    gaps: list[tuple[int, int]] = []
    at = 0
    while at < n_trials:
        if at in parts:
            b, p = parts[at]
            chain.append((at, b, p))
            at = b
            continue
        nxt = min([a for a in parts if a > at] + [n_trials])
        gaps.append((at, nxt))
        at = nxt
    return chain, gaps


def _frame(records: list[Records], scene: str, noise: str) -> pd.DataFrame:
    cols = {k: np.concatenate([r[k] for r in records]) for k in records[0]}
    n = len(cols["trial"])
    df = pd.DataFrame({"scene": [scene] * n, "noise": [noise] * n, **cols})
    df = df[list(TRIAL_COLUMNS)].astype(TRIAL_COLUMNS)
    return df.sort_values("trial", kind="stable").reset_index(drop=True)


class _ChunkWriter:
    """Buffers completed trials and writes each contiguous block of ``chunk`` trials as one part file."""

    def __init__(self, folder: Path, scene: str, noise: str, start: int, stop: int, chunk: int):
        self.folder, self.scene, self.noise = folder, scene, noise
        self.start, self.flushed, self.stop, self.chunk = start, start, stop, chunk
        self.pending: dict[int, Records] = {}
        self.on_advance: Callable[[int], None] = lambda n: None
        self.writing: tuple[int, Path] | None = None
        """(end, part file) of the write in progress: Ctrl-C may come after its rename, before ``flushed`` moves."""

    def __call__(self, rec: Records) -> None:
        for i, t in enumerate(rec["trial"].tolist()):
            self.pending[t] = {k: v[i : i + 1] for k, v in rec.items()}
        self.on_advance(len(rec["trial"]))
        while self.stop - self.flushed >= 1:
            end = min(self.flushed + self.chunk, self.stop)
            if not all(t in self.pending for t in range(self.flushed, end)):
                break
            self.flush(end)

    def flush(self, end: int | None = None) -> None:
        """Write trials ``flushed .. end - 1`` (default: the longest contiguous completed run)."""
        self.settle()
        if end is None:
            end = self.flushed
            while end in self.pending:
                end += 1
        if end <= self.flushed:
            return
        df = _frame([self.pending[t] for t in range(self.flushed, end)], self.scene, self.noise)
        path = self.folder / f"trials-{self.flushed:08d}-{end:08d}.parquet"
        self.writing = (end, path)
        with atomic_output(path, suffix=".parquet") as tmp:
            df.to_parquet(tmp, index=False)
        self.settle()

    def settle(self) -> None:
        """Count the part being written as written if its file is in place (an interrupt after the rename); its
        trials stay pending otherwise, so that they are written again, not dropped."""
        if self.writing is not None and self.writing[1].is_file():
            for t in range(self.flushed, self.writing[0]):
                self.pending.pop(t, None)
            self.flushed = self.writing[0]
        self.writing = None


def summarize(df: pd.DataFrame, info: dict[str, Any]) -> dict[str, Any]:
    """One summary row (see :data:`SUMMARY_COLUMNS`) of a scene's trial table; ``info`` gives the labels."""
    n, s = len(df), int(df["success"].sum())
    lo, hi = wilson_interval(s, n)
    row: dict[str, Any] = {k: info.get(k, "") for k in ("scene", "dataset", "dataset_label", "split", "method")}
    row |= {"variant": info.get("variant", ""), "protocol": info.get("protocol", ""), "noise": info.get("noise", "")}
    if info.get("hand"):  # only evaluations of a humanoid with a swapped hand (summary.json; csv: in the method)
        row["hand"] = info["hand"]
    row |= {"trials": n, "successes": s, "success_rate": s / n if n else math.nan}
    row |= {"success_ci_low": lo, "success_ci_high": hi}
    for c in ("obj_pos_err_cm", "obj_rot_err_deg", "wrist_pos_err_cm", "wrist_rot_err_deg", "contact_ratio"):
        row[c] = float(df[c].mean()) if n else math.nan
    row["completion_rate"] = float((~df["terminated"]).mean()) if n else math.nan
    row["frames_completed_mean"] = float(df["frames_completed"].mean()) if n else math.nan
    row["frames_total"] = int(df["frames_total"].iloc[0]) if n else 0
    counts = df["termination_reason"].value_counts()
    for name in TERMINATION_NAMES:
        row[f"terminated_{name}"] = int(counts.get(name, 0))
    ss = int(df["strict_success"].sum())
    lo, hi = wilson_interval(ss, n)
    row |= {"strict_successes": ss, "strict_success_rate": ss / n if n else math.nan}
    row |= {"strict_success_ci_low": lo, "strict_success_ci_high": hi}
    row["obj_pos_err_peak_cm"] = float(df["obj_pos_err_peak_cm"].mean()) if n else math.nan
    return row


def write_summary(out: Path, row: dict[str, Any], settings: dict[str, Any], policy_meta: dict[str, Any]) -> None:
    """``summary.json`` (settings, policy, the row) and ``summary.csv`` (the row), both deterministic; written
    together or not at all."""
    with contextlib.ExitStack() as stack:
        _write_summary(stack, out, row, settings, policy_meta)


def _write_summary(
    stack: contextlib.ExitStack, out: Path, row: dict[str, Any], settings: dict[str, Any], policy_meta: dict[str, Any]
) -> None:
    """:func:`write_summary` into temporary files that ``stack`` renames into place when it closes."""
    keep = (
        "scene",
        "variant",
        "dataset",
        "dataset_sha256",
        "run_dir",
        "checkpoint_sha256",
        "iteration",
        "train_frames",
        "train_seed",
    )
    doc = {
        "format": EVAL_FORMAT,
        "version": EVAL_VERSION,
        "settings": settings,
        "policy": {k: policy_meta[k] for k in keep if k in policy_meta},
        "scenes": [row],
    }
    tmp = stack.enter_context(atomic_output(out / "summary.json"))
    tmp.write_text(json.dumps(doc, indent=2, sort_keys=True, allow_nan=True) + "\n")
    frame = pd.DataFrame([row])[SUMMARY_COLUMNS]
    tmp = stack.enter_context(atomic_output(out / "summary.csv"))
    frame.to_csv(tmp, index=False, float_format="%.6f", lineterminator="\n")


def _make_folder(path: Path) -> list[Path]:
    """Create ``path`` and its missing parents; returns those created (outermost first)."""
    created = [p for p in (path, *path.parents) if not p.exists()][::-1]
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        _remove_empty(created)
        if is_write_failure(exc):
            raise OutputError.from_os(path, exc) from None
        raise InputError(path, None, f"cannot create the output folder ({exc.strerror or exc})") from None
    return created


def _remove_empty(folders: list[Path]) -> None:
    for p in reversed(folders):
        with contextlib.suppress(OSError):
            p.rmdir()


def _check_dataset(meta: dict[str, Any], dataset: Path) -> tuple[str, str]:
    """(source dataset, swapped hand or "") of the run's dataset, after checking it is the one trained on."""
    if not dataset.is_file():
        raise InputError(
            dataset, None, "dataset of the run not found", "the file in the run's config.json (or --dataset)"
        )
    sha = meta.get("dataset_sha256")
    if sha and sha256_file(dataset) != sha:
        raise InputError(dataset, None, "differs from the run's dataset (sha256)", "the file the policy was trained on")
    from wristmimic.format.reader import open_dataset
    from wristmimic.format.validate import check_sequence

    with open_dataset(dataset) as ds:
        check_sequence(ds, meta["scene"])  # one-line error naming the known ids, or the data's first problem
        seq = ds.sequence(meta["scene"])
        return str(ds.attrs.get("source_dataset", "")), ds.humanoid(seq.humanoid_id).hand


def evaluate_policy(
    policy: EvalPolicy,
    protocol: Protocol,
    out: Path,
    *,
    trials: int | None = None,
    noise: str | None = None,
    seed: int | None = None,
    num_envs: int = 256,
    nthread: int | None = None,
    dataset: Path | None = None,
    split: str | None = None,
    chunk: int = 256,
    progress: bool = True,
    backend: str = "cpu",
    backend_options: dict | None = None,
    should_stop: Callable[[], bool] | None = None,
) -> EvalResult:
    """Run (or resume) ``protocol`` for ``policy`` into ``out`` on physics ``backend`` (``cpu`` / ``warp``; the
    backend is part of the evaluation's settings); raises :class:`EvalInterrupted` on Ctrl-C or when
    ``should_stop()`` (asked as trials complete) turns true; completed parts are kept and a rerun resumes."""
    meta = policy.metadata
    n_trials = protocol.trials if trials is None else int(trials)
    if n_trials < 1 or num_envs < 1 or chunk < 1:
        raise InputError(None, "--trials/--num-envs", "must be >= 1")
    if noise is not None and noise not in NOISE_MODES:
        raise InputError(None, "--noise", f"{noise!r}", f"one of {', '.join(NOISE_MODES)}")
    if seed is not None and not 0 <= seed < 2**63:
        raise InputError(None, "--seed", f"{seed}", "an integer in [0, 2^63)")
    if backend not in BACKENDS:
        raise InputError(None, "--backend", f"{backend!r}", f"one of {', '.join(BACKENDS)}")
    settings = replace(
        TrialSettings.from_protocol(protocol),
        base_seed=protocol.base_seed if seed is None else int(seed),
        noise=noise or protocol.noise,
    )
    ds_path = Path(dataset or meta["dataset"])
    source, hand = _check_dataset(meta, ds_path)
    sp = find_split(meta["scene"], split)
    env_dict = _env_dict(meta.get("env"))
    expected = _settings_dict(protocol, policy, settings, env_dict, backend)
    out = Path(out)
    created = _make_folder(out)
    manifest = out / "eval.json"
    if manifest.is_file():
        try:
            old = json.loads(manifest.read_text())
        except (OSError, ValueError) as exc:
            raise InputError(
                manifest, None, f"cannot be read ({type(exc).__name__})", "the settings of an evaluation, or delete it"
            ) from None
        diff = sorted(k for k in set(old) | set(expected) if old.get(k) != expected.get(k))
        if diff:
            raise InputError(
                out,
                "eval.json",
                f"holds an evaluation with other settings ({', '.join(diff)})",
                "another --out, or delete it",
            )
    else:
        try:
            with atomic_output(manifest) as tmp:
                tmp.write_text(json.dumps(expected, indent=2, sort_keys=True) + "\n")
        except OutputError:
            _remove_empty(created)  # nothing of this evaluation is left behind
            raise
    scene = meta["scene"]
    parts_dir = out / "parts" / scene
    _make_folder(parts_dir)
    done, gaps = scan_parts(parts_dir, n_trials)
    todo = sum(b - a for a, b in gaps)
    t0, frames = time.perf_counter(), 0
    if gaps:
        env = make_env(
            meta,
            min(num_envs, max(b - a for a, b in gaps)),
            protocol.early_termination,
            nthread,
            ds_path,
            backend,
            backend_options,
        )
        if hasattr(policy, "to"):
            policy.to(env.device)  # type: ignore[attr-defined]
        kept = n_trials - todo  # trials held by part files
        writer: _ChunkWriter | None = None
        try:
            with _progress(f"{scene} ({meta.get('variant', '')})", kept, n_trials, progress) as advance:

                def advance_or_stop(n: int) -> None:
                    advance(n)
                    if should_stop is not None and should_stop():
                        raise KeyboardInterrupt

                for a, b in gaps:
                    writer = _ChunkWriter(parts_dir, scene, settings.noise, a, b, chunk)
                    writer.on_advance = advance_or_stop
                    frames += run_trials(env, policy, settings, a, b, writer)
                    kept += b - a
                    writer = None
        except KeyboardInterrupt:
            if writer is not None:
                writer.flush()  # settles a part the interrupt came in, then writes every completed trial
                kept += writer.flushed - writer.start
            raise EvalInterrupted(out, kept, n_trials) from None
        finally:
            env.close()
        done, gaps = scan_parts(parts_dir, n_trials)
        if gaps:  # only if part files were deleted meanwhile
            raise InputError(parts_dir, None, f"trials {gaps[0][0]}-{gaps[0][1] - 1} vanished", "their part files")
    seconds = time.perf_counter() - t0
    df = pd.concat([pd.read_parquet(p) for _, _, p in done], ignore_index=True)
    df = df[df["trial"] < n_trials].sort_values("trial", kind="stable").reset_index(drop=True)
    df = df[list(TRIAL_COLUMNS)].astype(TRIAL_COLUMNS)
    info = {
        "scene": scene,
        "dataset": source,
        "dataset_label": sp.label if sp else DATASET_LABELS.get(source, source),
        "split": sp.name if sp else "",
        "method": method_label(meta.get("variant", ""), env_dict, hand),
        "variant": meta.get("variant", ""),
        "protocol": protocol.name,
        "noise": settings.noise,
    }
    if hand:
        info["hand"] = hand
    row = summarize(df, info)
    timing = {
        "seconds": seconds,
        "trials_run": todo,
        "trials_per_s": todo / seconds if todo and seconds else None,
        "frames": frames,
    }
    parquet = out / f"{scene}.parquet"
    with contextlib.ExitStack() as stack:  # the table, summaries and timing: all renamed into place, or none
        tmp = stack.enter_context(atomic_output(parquet, suffix=".parquet"))
        df.to_parquet(tmp, index=False)
        _write_summary(stack, out, row, expected | {"trials": n_trials}, meta)
        tmp = stack.enter_context(atomic_output(out / "timing.json"))
        tmp.write_text(json.dumps(timing, indent=2, sort_keys=True) + "\n")
    return EvalResult(out, row, todo, seconds, frames, parquet)


def _env_dict(env: Any) -> dict[str, Any]:
    if env is None:
        return {}
    if isinstance(env, dict):
        return env
    from wristmimic.rl.config import to_jsonable

    return to_jsonable(env)


def _progress(description: str, start: int, total: int, enabled: bool):  # noqa: ANN202
    """A rich bar over trials on stderr (a context yielding ``advance(n)``)."""
    import contextlib

    from rich.console import Console
    from rich.progress import (
        BarColumn,
        MofNCompleteColumn,
        Progress,
        TextColumn,
        TimeElapsedColumn,
        TimeRemainingColumn,
    )

    @contextlib.contextmanager
    def bar():  # noqa: ANN202
        if not enabled:
            yield lambda n: None
            return
        cols = (TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(), TextColumn("trials"),
                TimeElapsedColumn(), TimeRemainingColumn())  # fmt: skip
        with Progress(*cols, console=Console(stderr=True)) as p:
            task = p.add_task(description, total=total, completed=start)
            yield lambda n: p.update(task, advance=n)

    return bar()
