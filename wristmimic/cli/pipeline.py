"""``wristmimic run pipelines/NAME.toml``: convert -> train -> evaluate -> report, skipping up-to-date work."""

from __future__ import annotations

from pathlib import Path

import typer

from wristmimic.cli.errors import user_errors


def check_outputs(spec_path: Path) -> None:
    """Refuse, before any stage runs, output paths of the pipeline file that are the wrong kind of path: a folder
    where a file is written (``[convert] output``) or a file where a folder is (the work folder, ``[hands]
    output_dir``, ``[report] output``), or one below a file. The error names the pipeline file and the key."""
    from wristmimic.errors import InputError
    from wristmimic.pipeline import STATE_FILE, load_spec
    from wristmimic.safe_io import check_output_file, check_output_folder

    spec = load_spec(spec_path)

    def path_of(table: str, key: str, default: Path | None) -> Path | None:
        value = spec.get(table, {}).get(key, default)
        if value is not None and not isinstance(value, (str, Path)):
            raise InputError(spec_path, f"{table}.{key}", f"{value!r}", "a path (a string)")
        return None if value is None else Path(value)

    meta = spec.get("pipeline", {})
    work_dir = path_of("pipeline", "work_dir", Path("runs") / "pipelines" / str(meta.get("name", spec_path.stem)))
    checks = [(work_dir, "pipeline.work_dir", check_output_folder)]
    checks.append((work_dir / STATE_FILE, "pipeline.work_dir", check_output_file))
    if "convert" in spec:
        checks.append((path_of("convert", "output", None), "convert.output", check_output_file))
    if "hands" in spec:
        checks.append((path_of("hands", "output_dir", work_dir / "hands"), "hands.output_dir", check_output_folder))
    if "report" in spec:
        checks.append((path_of("report", "output", work_dir / "report"), "report.output", check_output_folder))
    for path, key, check in checks:
        if path is None:
            continue  # a missing required key is the stage's own error
        try:
            check(path, None)
        except InputError as exc:
            problem = f"{path} {exc.problem}" if exc.problem.startswith("is ") else exc.problem
            raise InputError(spec_path, key, problem, exc.expected) from None


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
        check_outputs(spec)
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
