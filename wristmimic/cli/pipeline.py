"""``wristmimic run pipelines/NAME.toml``: convert -> train -> evaluate -> report, skipping up-to-date work."""

from __future__ import annotations

from pathlib import Path

import typer

from wristmimic.cli.errors import user_errors


def run_cmd(
    spec: Path = typer.Argument(..., help="Pipeline file (TOML), e.g. pipelines/omomo.toml."),
    nthread: int = typer.Option(None, "--nthread", help="Physics threads for training (default: all cores)."),
    quiet: bool = typer.Option(False, "--quiet", "-q", help="No progress bars."),
) -> None:
    """Run a pipeline's stages in order; a stage whose inputs (content hashes) and outputs are unchanged since
    the last run is skipped. Stages not implemented yet (evaluate, report) are reported as not available.

    Example: wristmimic run pipelines/omomo.toml
    """
    from wristmimic.pipeline import run_pipeline

    with user_errors():
        ctx = run_pipeline(spec, progress=not quiet, nthread=nthread, echo=typer.echo)
    ran = sum(s == "ran" for _, s in ctx.summary)
    cached = sum(s == "up to date" for _, s in ctx.summary)
    missing = [u for u, s in ctx.summary if s == "not available yet"]
    typer.echo(
        f"pipeline {spec}: {ran} ran, {cached} up to date"
        + (f", not available yet: {', '.join(missing)}" if missing else "")
    )
    if missing:
        typer.echo(
            f"warning: stage(s) {', '.join(missing)} are not implemented yet; their outputs were not made", err=True
        )
