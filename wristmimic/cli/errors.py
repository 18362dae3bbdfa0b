"""Turn expected errors into one-line messages and a non-zero exit code."""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterator

import typer

from wristmimic.errors import WristmimicError


def os_error_line(exc: OSError) -> str:
    """``<filename>: <strerror>`` (``<filename> -> <filename2>: ...`` for a rename) on one line.

    Without an errno (an OSError raised with a bare message) the first line of the message is used."""
    if exc.errno and exc.strerror:
        reason = exc.strerror
    elif exc.errno:
        reason = os.strerror(exc.errno)
    else:
        reason = next((ln.strip() for ln in str(exc).splitlines() if ln.strip()), "") or type(exc).__name__
    names = [str(f) for f in (exc.filename, exc.filename2) if f is not None]
    return ": ".join([" -> ".join(names), reason] if names else [reason])


def _is_device_oom(exc: BaseException) -> bool:
    """torch's (CUDA) out-of-memory error, a RuntimeError rather than a MemoryError; torch is not imported."""
    return any(c.__name__ == "OutOfMemoryError" and c.__module__.startswith("torch") for c in type(exc).__mro__)


def _memory_line(exc: BaseException) -> str:
    """``out of memory (<first sentence of the message>)``: one line however long the message is."""
    from wristmimic.safe_io import first_sentence

    detail = first_sentence(str(exc), 200)
    return f"out of memory ({detail})" if detail else "out of memory"


@contextlib.contextmanager
def user_errors() -> Iterator[None]:
    """Print one line on stderr and exit instead of a traceback: ``error: <message>`` and exit 1 for
    :class:`WristmimicError`, for any :class:`OSError` nothing else caught (``error: <file>: <reason>``, e.g. a
    folder without write permission or an I/O error) and for running out of memory (:class:`MemoryError`, torch's
    ``OutOfMemoryError``); exit 130 on Ctrl-C. Any other exception is a bug and keeps its traceback."""
    try:
        yield
    except WristmimicError as exc:
        typer.echo(f"error: {exc}", err=True)
        raise typer.Exit(code=1) from None
    except OSError as exc:
        typer.echo(f"error: {os_error_line(exc)}", err=True)
        raise typer.Exit(code=1) from None
    except MemoryError as exc:
        typer.echo(f"error: {_memory_line(exc)}", err=True)
        raise typer.Exit(code=1) from None
    except Exception as exc:
        if not _is_device_oom(exc):
            raise  # a bug: the traceback is what a report needs
        typer.echo(f"error: {_memory_line(exc)}", err=True)
        raise typer.Exit(code=1) from None
    except KeyboardInterrupt:
        typer.echo("interrupted: no output written", err=True)
        raise typer.Exit(code=130) from None
