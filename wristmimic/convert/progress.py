"""Progress bars for long conversions (rich), silent when disabled or not attached to a terminal."""

from __future__ import annotations

import contextlib
from collections.abc import Iterator
from typing import Any

from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn


class _Silent:
    def add_task(self, *_a: Any, **_k: Any) -> int:
        return 0

    def advance(self, *_a: Any, **_k: Any) -> None:
        return None


class _Bar:
    def __init__(self, p: Progress):
        self._p = p

    def add_task(self, description: str, total: int) -> Any:
        return self._p.add_task(description, total=total)

    def advance(self, task: Any, n: int = 1) -> None:
        self._p.update(task, advance=n)


@contextlib.contextmanager
def progress_bar(enabled: bool = True) -> Iterator[_Bar | _Silent]:
    """A rich progress display (stderr) with one bar per ``add_task``."""
    if not enabled:
        yield _Silent()
        return
    with Progress(
        TextColumn("{task.description}"),
        BarColumn(),
        MofNCompleteColumn(),
        TimeElapsedColumn(),
        transient=False,
        console=Console(stderr=True),
    ) as p:
        yield _Bar(p)
