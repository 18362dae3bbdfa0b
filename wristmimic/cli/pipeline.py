"""``wristmimic run pipelines/NAME.toml``: convert -> train -> evaluate -> report, skipping up-to-date work."""

from __future__ import annotations

from pathlib import Path

import typer

from wristmimic.cli.errors import user_errors


def run_cmd(
    spec: Path = typer.Argument(..., help="Pipeline file (TOML), e.g. pipelines/omomo.toml."),
    nthread: int = typer.Option(None, "--nthread", help="Physics threads for training (default: all cores)."),
    quiet: bool = typer.Option(False, "--quiet", "-q", help="No progress bars."),
    ray: str = typer.Option(
        None,
        "--ray",
        metavar="ADDRESS",
        help="Run one train+evaluate job per scene as a Ray task: 'local' starts Ray on this machine; anything "
        "else is a cluster address for ray.init (auto, HOST:PORT, ray://HOST:10001). Needs the ray extra: "
        "pip install 'wristmimic\\[ray]'.",
    ),
    ray_cpus: int = typer.Option(
        None,
        "--ray-cpus-per-job",
        min=1,
        help="CPUs each job reserves and uses for physics and torch threads (default: \\[pipeline] "
        "ray_cpus_per_job, else --nthread, else 1).",
    ),
    ray_gpus: float = typer.Option(
        None,
        "--ray-gpus-per-job",
        min=0,
        help="GPUs each job reserves (default: \\[pipeline] ray_gpus_per_job, else 0).",
    ),
    ray_local_cpus: int = typer.Option(
        None, "--ray-local-cpus", min=1, help="CPUs of the Ray that --ray local starts (default: all cores)."
    ),
) -> None:
    """Run a pipeline's stages in order; a stage whose inputs (content hashes) and outputs are unchanged since
    the last run is skipped. Stages not implemented yet (evaluate, report) are reported as not available.

    With --ray, the jobs (train then evaluate one scene) that are not up to date run as Ray tasks; the driver
    ships each dataset through Ray's object store and gets each run folder back, so the nodes need no shared
    filesystem (they need the same wristmimic installed). A failed job is reported with its error and the
    others are kept; run again to retry it.

    Example: wristmimic run pipelines/omomo.toml

    Example: wristmimic run pipelines/omomo.toml --ray local --ray-cpus-per-job 2
    """
    from wristmimic.pipeline import run_pipeline

    with user_errors():
        options = None
        if ray is not None:
            from wristmimic.distributed import RayOptions

            options = RayOptions(ray, ray_cpus, ray_gpus, ray_local_cpus)
        ctx = run_pipeline(spec, progress=not quiet, nthread=nthread, echo=typer.echo, ray=options)
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
