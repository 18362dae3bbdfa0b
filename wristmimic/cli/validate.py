"""``wristmimic validate FILE``: check a canonical file, list every problem."""

from __future__ import annotations

from pathlib import Path

import typer

from wristmimic.format.validate import validate


def validate_cmd(
    file: Path = typer.Argument(..., help="Canonical .h5 file to check."),
    quiet: bool = typer.Option(False, "--quiet", "-q", help="Print nothing on success."),
) -> None:
    """Check shapes, dtypes, unit quaternions, finite values, label ranges and references between groups.

    Exit code 0 when the file is valid; 1 with every problem listed otherwise.

    Example: wristmimic validate datasets/omomo.h5
    """
    problems = validate(file)
    if problems:
        for p in problems:
            typer.echo(f"{file}: {p}" if not p.startswith(str(file)) else p, err=True)
        typer.echo(f"{len(problems)} problem(s) in {file}", err=True)
        raise typer.Exit(code=1)
    if not quiet:
        typer.echo(f"{file}: valid")
