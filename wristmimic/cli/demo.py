"""``wristmimic demo``: the whole suite on the built-in synthetic scene."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import typer

from wristmimic.cli.errors import user_errors


def demo_cmd(
    out: Path = typer.Option(Path("outputs/demo"), "--out", "-o", help="Folder for every output of the demo."),
    quick: bool = typer.Option(False, "--quick", help="A tiny run for CI: under 3 minutes on 2 cores."),
    trials: int = typer.Option(None, "--trials", min=1, help="Evaluation trials [default: 256, quick: 32]."),
    train_frames: int = typer.Option(None, "--train-frames", min=1, help="Training budget in frames."),
    seed: int = typer.Option(0, "--seed", help="Seed of the scene, training and evaluation."),
    nthread: int = typer.Option(None, "--nthread", min=1, help="Physics threads [default: all cores]."),
) -> None:
    """Generate the built-in synthetic scene (no dataset or licensed file needed), train a WristMimic policy
    briefly on the CPU preset, evaluate it, write the report and a rerun recording, and say where they are.
    Takes 10-25 minutes on a 2-core machine, as fast as the host runs (--quick: under 3).

    Example: wristmimic demo --quick
    """
    from wristmimic.demo import QUICK, DemoConfig, run_demo
    from wristmimic.safe_io import check_output_file, check_output_folder

    base = QUICK if quick else DemoConfig()
    cfg = replace(
        base, out=out, seed=seed, trials=trials or base.trials, train_frames=train_frames or base.train_frames
    )
    with user_errors():  # before anything is said or done
        check_output_folder(out)
        for name in ("run", "eval", "report"):  # what the demo writes inside --out (demo.DemoConfig.out)
            check_output_folder(out / name)
        for name in ("demo.h5", "demo.rrd"):
            check_output_file(out / name)
    typer.echo(f"wristmimic demo: {'under 3' if quick else '10-25'} minutes on a 2-core machine; outputs in {cfg.out}/")
    with user_errors():
        r = run_demo(cfg, nthread=nthread, echo=typer.echo)
    took = ", ".join(f"{k} {v:.0f} s" for k, v in r.seconds.items())
    typer.echo(
        f"\ndone ({took}); the policy succeeds in {r.success_pct:.1f} % of {cfg.trials} quick-protocol trials "
        f"after {cfg.train_frames:,} training frames (the paper's rule: mean object error under 10 cm); "
        f"{r.strict_pct:.1f} % keep the object within 10 cm of its reference in every frame; evaluated: {r.deployed}."
    )
    typer.echo(f"  dataset     {r.dataset}   (wristmimic inspect {r.dataset})")
    typer.echo(
        f"  policy      {r.run_dir}/   (metrics.csv, checkpoint.pt; continue: wristmimic train --resume {r.run_dir})"
    )
    typer.echo(f"  evaluation  {r.eval_dir}/")
    typer.echo(f"  report      {r.report_dir}/summary.md")
    typer.echo(f"  recording   {r.recording}   (open with: rerun {r.recording})")
