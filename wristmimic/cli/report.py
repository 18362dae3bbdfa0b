"""``wristmimic report EVAL_DIRS... -o reports/NAME``: tables, plots and summary.md from evaluations."""

from __future__ import annotations

from pathlib import Path

import typer

from wristmimic.cli.errors import user_errors


def report_cmd(
    eval_dirs: list[Path] = typer.Argument(..., help="Evaluation folders (or folders to search for them)."),
    out: Path = typer.Option(..., "--out", "-o", help="Report folder, e.g. reports/omomo20."),
    title: str = typer.Option(None, "--title", help="Title of summary.md (default: the folder name)."),
    split: list[str] = typer.Option(None, "--split", help="Keep the scenes of this split (repeatable; eval/splits)."),
    plausibility: list[Path] = typer.Option(
        None,
        "--plausibility",
        help="Output of `wristmimic export` (repeatable): adds plausibility.csv and a table of the reference "
        "against its simulated rollouts for every evaluated scene (docs/plausibility.md). Exports beside an "
        "evaluation are used without this: any *.h5 in the evaluation folder, its parent or its run folder whose "
        "provenance (root attribute `export`) names the evaluated checkpoint's sha256 and scene.",
    ),
    find_exports: bool = typer.Option(
        True, "--find-exports/--no-find-exports", help="Look for exports beside the evaluations (see --plausibility)."
    ),
) -> None:
    """Write per-scene, per-dataset, method x dataset and ablation tables (CSV), plots (PNG) and summary.md.

    Success rates come with Wilson 95 % intervals; the same inputs give byte-identical files.

    Example: wristmimic report runs/*/eval/paper -o reports/omomo20

    Example: wristmimic report runs --split omomo20 --split parahome20 -o reports/paper --title "Paper splits"

    Example: wristmimic report runs/RUN/eval/paper --plausibility sim.h5 -o reports/RUN

    Example: wristmimic export runs/RUN -o runs/RUN/sim.h5 --from-eval runs/RUN/eval/paper; wristmimic report
    runs/RUN/eval/paper -o reports/RUN (sim.h5 is found in the run folder)
    """
    from wristmimic.report import build_report
    from wristmimic.safe_io import check_output_folder

    with user_errors():
        check_output_folder(out)
        r = build_report(eval_dirs, out, title, split or None, plausibility or None, find_exports)
        typer.echo(f"{r.out}: {r.scenes} scene(s), {r.trials:,} trials -> {', '.join(r.files)}")
        if r.exports:
            typer.echo(f"plausibility of the exports {', '.join(str(p) for p in r.exports)}")
