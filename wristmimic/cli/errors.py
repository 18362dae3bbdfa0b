"""Turn expected errors into one-line messages and a non-zero exit code."""

from __future__ import annotations

import contextlib
from collections.abc import Iterator

import typer

from wristmimic.errors import WristmimicError


@contextlib.contextmanager
def user_errors() -> Iterator[None]:
    """Print ``error: <message>`` on stderr and exit 1 for :class:`WristmimicError`."""
    try:
        yield
    except WristmimicError as exc:
        typer.echo(f"error: {exc}", err=True)
        raise typer.Exit(code=1) from None
    except KeyboardInterrupt:
        typer.echo("interrupted: no output written", err=True)
        raise typer.Exit(code=130) from None
