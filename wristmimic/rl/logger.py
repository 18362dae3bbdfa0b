"""Training logs: per-iteration episode statistics, ``metrics.csv`` rows and the live progress bar."""

from __future__ import annotations

import contextlib
import csv
import io
import math
import os
from collections.abc import Iterator
from pathlib import Path

import torch
from rich.console import Console
from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn, TimeRemainingColumn

from wristmimic.env.terminations import REASONS
from wristmimic.errors import InputError
from wristmimic.safe_io import atomic_output

_REASON_CODES = tuple(code for code in sorted(REASONS) if code != 0)
"""Termination reasons counted per iteration (code 0 = none)."""

TIME_COLUMNS = ("seconds", "frames_per_s")
"""Wall-clock columns of ``metrics.csv``: the only ones that differ between two runs with the same seed."""


class EpisodeStats:
    """Accumulates one iteration's step and episode statistics over all worlds.

    Attributes:
        num_frames: frames of the reference. An episode succeeded when it started at frame 0 and reached frame
            ``num_frames - 1`` unterminated; ``success_rate`` is over the episodes from frame 0 that ended.
        episodes_total, successes_total: frame-0 episodes ended and succeeded since the start of training
            (kept in checkpoints).
    """

    def __init__(self, num_frames: int):
        self.num_frames = int(num_frames)
        self.episodes_total = 0
        self.successes_total = 0
        self._codes: torch.Tensor | None = None
        self._reset_iteration()

    def _reset_iteration(self) -> None:
        self._steps = 0
        self._names: list[str] = []
        self._sums: torch.Tensor | None = None  # float64 on the environment's device: no host sync per step

    def record(self, reward: torch.Tensor, terminated: torch.Tensor, info: dict) -> None:
        """One environment step of every world (``info`` as returned by ``WristMimicEnv.step``). Sums stay on
        the environment's device until :meth:`flush`."""
        self._steps += 1
        done = terminated | info["time_outs"]
        from_zero = done & (info["episode_start"] == 0)
        success = from_zero & info["time_outs"] & (info["frame"] >= self.num_frames - 1)
        terms = {k: v for k, v in info["terms"].items() if k.startswith("reward/")}
        if self._codes is None or self._codes.device != reward.device:  # made once: no host-to-device copy per step
            self._codes = torch.tensor(_REASON_CODES, device=reward.device)
        codes = self._codes
        by_reason = ((info["termination_reason"][:, None] == codes[None]) & terminated[:, None]).sum(0)
        values = [
            reward.double().mean(),
            (info["episode_frames"] * done).sum().double(),
            done.sum().double(),
            from_zero.sum().double(),
            success.sum().double(),
            *(v.double().mean() for v in terms.values()),
        ]
        row = torch.cat([torch.stack(values), by_reason.double()])
        if self._sums is None:
            self._names = ["reward", "length_sum", "episodes", "from_zero", "success", *terms]
            self._sums = row
        else:
            self._sums = self._sums + row

    def flush(self) -> dict[str, float]:
        """This iteration's means (NaN where no episode ended), then start a new iteration."""
        names = self._names or ["reward", "length_sum", "episodes", "from_zero", "success"]
        sums = self._sums.cpu().tolist() if self._sums is not None else [0.0] * (len(names) + len(_REASON_CODES))
        named, reasons = dict(zip(names, sums, strict=False)), sums[len(names) :]
        steps = max(self._steps, 1)
        n, n0 = int(named["episodes"]), int(named["from_zero"])
        success = int(named["success"])
        self.successes_total += success
        self.episodes_total += n0
        row = {
            "reward_mean": named["reward"] / steps,
            "episode_length_mean": named["length_sum"] / n if n else math.nan,
            "episodes": n,
            "episodes_from_zero": n0,
            "success_rate": success / n0 if n0 else math.nan,
            "success_rate_total": self.successes_total / self.episodes_total if self.episodes_total else math.nan,
        }
        row.update({name: named[name] / steps for name in sorted(names[5:])})
        row.update({f"termination/{REASONS[c]}": int(v) for c, v in zip(_REASON_CODES, reasons, strict=True)})
        self._reset_iteration()
        return row

    def state_dict(self) -> dict[str, int]:
        return {"episodes_total": self.episodes_total, "successes_total": self.successes_total}

    def load_state_dict(self, state: dict[str, int]) -> None:
        self.episodes_total, self.successes_total = int(state["episodes_total"]), int(state["successes_total"])


def _fmt(v: object) -> str:
    return repr(float(v)) if isinstance(v, float) else str(v)


class MetricsCsv:
    """``metrics.csv``: one row per iteration, header from the first row.

    ``keep_until``: continue an existing file after a checkpoint of that iteration: rows after it (written before
    a crash or a failure), a half-written last row and anything after it are dropped, so every iteration appears
    exactly once. A row that cannot be written (full disk) is cut off again and raises :class:`InputError`."""

    def __init__(self, path: Path, keep_until: int | None = None):
        self.path = path
        self.columns: list[str] | None = None
        if keep_until is not None and path.exists():
            with open(path, newline="", encoding="utf-8") as f:
                rows = list(csv.reader(f))
            if rows:
                self.columns = rows[0]
                kept = []
                for r in rows[1:]:
                    if len(r) != len(self.columns) or not r[0].isdigit() or int(r[0]) > keep_until:
                        break
                    kept.append(r)
                if len(kept) < len(rows) - 1:
                    with atomic_output(path) as tmp, open(tmp, "w", newline="", encoding="utf-8") as f:
                        csv.writer(f).writerows([rows[0], *kept])

    def write(self, row: dict[str, object]) -> None:
        new = self.columns is None
        columns = list(row) if new else self.columns
        buf = io.StringIO()
        w = csv.writer(buf)
        if new:
            w.writerow(columns)
        w.writerow([_fmt(row.get(c, "")) for c in columns])  # type: ignore[union-attr]
        data = buf.getvalue().encode("utf-8")
        try:
            fd = os.open(self.path, os.O_WRONLY | os.O_CREAT | (os.O_TRUNC if new else os.O_APPEND), 0o666)
        except OSError as exc:
            raise InputError(self.path, None, f"cannot be opened ({exc.strerror})") from None
        try:
            end = os.lseek(fd, 0, os.SEEK_END)
            view = memoryview(data)
            while view:
                view = view[os.write(fd, view) :]
        except OSError as exc:
            with contextlib.suppress(OSError):
                os.ftruncate(fd, end)  # no half row: the file ends with its last complete row
                if new:
                    self.path.unlink()  # nor a file without one
            raise InputError(
                self.path, None, f"row of iteration {row.get('iteration')} not written ({exc.strerror})"
            ) from None
        finally:
            os.close(fd)
        self.columns = columns


class _NoBar:
    def update(self, frames: int, row: dict[str, float]) -> None:
        return None


class _Bar:
    def __init__(self, progress: Progress, task: int):
        self._p, self._task = progress, task

    def update(self, frames: int, row: dict[str, float]) -> None:
        success = row["success_rate_total"]
        self._p.update(
            self._task,
            completed=frames,
            fps=f"{row['frames_per_s']:,.0f}",
            reward=f"{row['reward_mean']:.3f}",
            length=f"{row['episode_length_mean']:.1f}",
            success="-" if math.isnan(success) else f"{100 * success:.1f}%",
        )


@contextlib.contextmanager
def train_progress(description: str, start: int, total: int, enabled: bool = True) -> Iterator[_Bar | _NoBar]:
    """A rich bar over frames with frames/s, mean reward, mean episode length and success so far (stderr)."""
    if not enabled:
        yield _NoBar()
        return
    columns = (
        TextColumn("{task.description}"),
        BarColumn(),
        TextColumn("{task.completed:,}/{task.total:,} frames"),
        TextColumn("{task.fields[fps]} fps  reward {task.fields[reward]}  ep len {task.fields[length]}"),
        TextColumn("success {task.fields[success]}"),
        TimeElapsedColumn(),
        TimeRemainingColumn(),
    )
    with Progress(*columns, console=Console(stderr=True)) as p:
        task = p.add_task(description, total=total, completed=start, fps="-", reward="-", length="-", success="-")
        yield _Bar(p, task)
