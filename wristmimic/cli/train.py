"""``wristmimic train DATASET.h5 --scene SEQ``: PPO per scene, or ``--resume RUN_DIR``."""

from __future__ import annotations

from pathlib import Path

import typer

from wristmimic.cli.errors import user_errors
from wristmimic.cli.options import backend_option, device_option
from wristmimic.errors import InputError


def _scenes(dataset: Path, scene: list[str] | None, scenes: str | None) -> list[str]:
    from wristmimic.format.reader import open_dataset

    if scenes is not None and scenes != "all":
        raise InputError(None, "--scenes", f"{scenes!r}", "'all' (use --scene SEQ for one scene)")
    if bool(scene) == (scenes is not None):
        raise InputError(None, "--scene", "give either --scene SEQ (repeatable) or --scenes all")
    if scene:
        return list(scene)
    with open_dataset(dataset) as ds:
        return list(ds.sequence_ids)


def train_cmd(
    dataset: Path = typer.Argument(None, help="Canonical HDF5 file (from `wristmimic convert`)."),
    scene: list[str] = typer.Option(None, "--scene", "-s", help="Sequence id to train (repeatable)."),
    scenes: str = typer.Option(None, "--scenes", help="'all': train every sequence of the file in turn."),
    variant: str = typer.Option("wristmimic", "--variant", help="Environment variant (see wristmimic.env.config)."),
    preset: str = typer.Option("cpu", "--preset", help="PPO preset: cpu (2-core machine) or paper (2,048 envs)."),
    max_frames: int = typer.Option(None, "--max-frames", help="Training budget in env frames (default: the preset's)."),
    num_envs: int = typer.Option(None, "--num-envs", help="Parallel worlds (default: the preset's)."),
    ref_frames: int = typer.Option(None, "--ref-frames", help="Use only the first N reference frames (short task)."),
    out: Path = typer.Option(Path("runs"), "--out", "-o", help="Parent folder of the run folders."),
    seed: int = typer.Option(0, "--seed", help="Seed of networks, action noise, minibatches and start frames."),
    resume: Path = typer.Option(None, "--resume", help="Continue this run folder exactly where it stopped."),
    checkpoint_seconds: float = typer.Option(
        None,
        "--checkpoint-seconds",
        help="Seconds between checkpoints (default 0: after every iteration, written in the background, so a kill "
        "loses at most the iteration being written and the one in progress; N > 0: after the first iteration, then "
        "every N seconds or the preset's checkpoint_every iterations).",
    ),
    init_from: Path = typer.Option(
        None,
        "--init-from",
        help="Warm start: begin from this run folder's (or checkpoint's) policy instead of fresh networks, e.g. a "
        "body-only stage (scripts/body_only.py) before the scene with its object. Needs the same observation and "
        "action sizes and network; observation statistics are re-estimated. config.json records the source, and the "
        "run folder keeps a copy of it as init.pt (start from that to repeat the run after the source trained on).",
    ),
    init_weights: str = typer.Option(
        "deployed", "--init-weights", help="Which weights --init-from takes: deployed (what evaluate loads) or latest."
    ),
    init_normalizer: str = typer.Option(
        "reset",
        "--init-normalizer",
        help="Observation statistics of --init-from: reset (re-estimated here; for another scene or a body-only "
        "copy) or source (kept; for the same scene with other starts or terms).",
    ),
    nthread: int = typer.Option(None, "--nthread", help="Physics threads (default: all cores)."),
    backend: str = backend_option(),
    device: str = device_option(),
    quiet: bool = typer.Option(False, "--quiet", "-q", help="No progress bar."),
    overrides: list[str] = typer.Option(
        None,
        "--set",
        help="Override one config field, SECTION.FIELD=VALUE (repeatable; SECTION: env, ppo or scene_config; value "
        "as JSON), e.g. --set env.object_controller.zero_by_frames=1500000. config.json records the result.",
    ),
) -> None:
    """Train one PPO policy per scene; each run folder gets config.json, metrics.csv and checkpoint.pt.

    Ctrl-C finishes the current iteration, saves a checkpoint and exits; --resume continues bit-for-bit. A
    checkpoint is written after every iteration (in the background, see --checkpoint-seconds), so a kill loses at
    most one finished iteration. Non-finite values (NaN, inf) stop training with the last good checkpoint kept.

    Example: wristmimic train datasets/omomo.h5 --scene sub2_largetable_000 --variant wristmimic --preset cpu

    Example: wristmimic train data.h5 --scene SEQ --set ppo.learning_rate=3e-4 --set env.residual_scale=0.4

    Example: wristmimic train kettle.h5 --scene s110_move_kettle --init-from runs/BODY_ONLY_RUN

    Example: wristmimic train --resume runs/sub2_largetable_000-wristmimic-seed0-20261123-120000
    """
    from wristmimic.rl.config import preset as make_preset
    from wristmimic.rl.overrides import with_overrides
    from wristmimic.rl.train import TrainSpec, default_run_dir, resume_run, start_run
    from wristmimic.safe_io import check_output_folder

    with user_errors():
        if max_frames is not None and max_frames < 1:
            raise InputError(None, "--max-frames", f"{max_frames}", "a positive number of frames")
        if resume is not None:
            if (
                scene
                or scenes
                or dataset
                or backend != "cpu"
                or device
                or checkpoint_seconds is not None
                or overrides
                or init_from
            ):
                raise InputError(None, "--resume", "takes dataset, scene, backend and config from the run folder")
            r = resume_run(resume, max_frames=max_frames, nthread=nthread, progress=not quiet)
            typer.echo(f"{r.run_dir}: {r.status} at iteration {r.iteration} ({r.frames:,} frames)")
            return
        if init_normalizer != "reset" and init_from is None:
            raise InputError(None, "--init-normalizer", f"{init_normalizer!r} without --init-from", "--init-from RUN")
        if dataset is None:
            raise InputError(None, "DATASET", "missing", "a canonical .h5 file (or --resume RUN_DIR)")
        if not dataset.is_file():
            raise InputError(dataset, None, "file not found")
        check_output_folder(out)
        ppo = make_preset(preset, max_frames=max_frames, num_envs=num_envs, checkpoint_seconds=checkpoint_seconds)
        for sid in _scenes(dataset, scene, scenes):
            spec = TrainSpec(
                dataset,
                sid,
                variant,
                seed,
                preset,
                ppo,
                ref_frames=ref_frames,
                backend=backend,
                device=device,
                init_from=init_from,
                init_weights=init_weights,
                init_normalizer=init_normalizer,
            )
            spec = with_overrides(spec, overrides or ())
            r = start_run(spec, default_run_dir(out, sid, variant, seed), nthread=nthread, progress=not quiet)
            typer.echo(f"{r.run_dir}: {r.status} at iteration {r.iteration} ({r.frames:,} frames)")
            if r.status == "interrupted":
                raise typer.Exit(code=130)
