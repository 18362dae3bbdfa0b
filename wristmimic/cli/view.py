"""``wristmimic view SOURCE -o FILE.rrd``: a rerun recording of converted data or of a policy's rollout."""

from __future__ import annotations

from pathlib import Path

import typer

from wristmimic.cli.errors import user_errors
from wristmimic.errors import InputError


def view_cmd(
    source: Path = typer.Argument(..., help="Canonical .h5 file, or a run folder / checkpoint.pt of `train`."),
    out: Path = typer.Option(..., "--out", "-o", help="Recording to write (.rrd); open it with `rerun FILE.rrd`."),
    sequence: str = typer.Option(None, "--sequence", "-s", help="Sequence id (a dataset only)."),
    reference_only: bool = typer.Option(False, "--reference-only", help="A run: its reference, no rollout."),
    trial_seed: int = typer.Option(
        None, "--trial-seed", help="Replay the sampled-action trial with this seed (an evaluation table's `seed`)."
    ),
    deterministic: bool = typer.Option(False, "--deterministic", help="Mean actions (the default)."),
    start_frame: int = typer.Option(0, "--start-frame", min=0, help="Reference frame the rollout starts from."),
    frames: int = typer.Option(None, "--frames", min=1, help="A dataset: only its first N frames."),
    hulls: bool = typer.Option(False, "--hulls", help="Add collision hulls (hidden in the default layout)."),
    dataset: Path = typer.Option(
        None, "--dataset", help="A run's (or an exported sequence's reference) dataset if it moved (the same file)."
    ),
    no_plausibility: bool = typer.Option(
        False, "--no-plausibility", help="An exported sequence: leave out the per-frame plausibility plots."
    ),
) -> None:
    """Write an .rrd recording: the humanoid and objects of the reference (orange) and, for a trained run, one
    rollout of its policy from frame 0 (blue) with object, wrist and body error curves, contacts, the contact
    window and its phases. The rollout runs as evaluation runs a trial: the policy mean, plus the trial's
    action noise with --trial-seed. A sequence written by `wristmimic export` (<scene>__sim_<seed>) is shown
    the same way beside the reference its provenance names, with the plausibility of both per frame. The layout
    (3D view beside the plots) is embedded.

    Example: wristmimic view datasets/omomo.h5 --sequence sub2_largetable_000 -o ref.rrd

    Example: wristmimic view runs/sub2_largetable_000-wristmimic-seed0-20261123-120000 -o rollout.rrd

    Example: wristmimic view runs/RUN/checkpoint.pt --trial-seed 3 -o trial3.rrd

    Example: wristmimic view sim.h5 --sequence sub2_largetable_000__sim_mean -o sim.rrd
    """
    from wristmimic.format.reader import open_dataset
    from wristmimic.format.validate import check_sequence
    from wristmimic.safe_io import check_output_file
    from wristmimic.view.exported import export_provenance, record_export
    from wristmimic.view.record import record_reference
    from wristmimic.view.run import RunViewOptions, record_run, source_kind

    with user_errors():
        if out.suffix != ".rrd":
            raise InputError(out, None, "not an .rrd file name", "FILE.rrd")
        check_output_file(out)
        if trial_seed is not None and deterministic:
            raise InputError(None, "--deterministic", "conflicts with --trial-seed", "one of them")
        if source_kind(source) == "dataset":
            exported = False
            if sequence is not None:
                with open_dataset(source) as ds:
                    if sequence in ds.sequence_ids:
                        check_sequence(ds, sequence)  # the data gate before anything reads the sequence
                        exported = export_provenance(ds, sequence) is not None
            run_only = {
                "--reference-only": reference_only,
                "--trial-seed": trial_seed is not None,
                "--deterministic": deterministic,
                "--start-frame": start_frame != 0,
                "--dataset": dataset is not None and not exported,
            }
            given = [k for k, v in run_only.items() if v]
            if given:
                raise InputError(source, given[0], "is for a trained run", "a run folder or checkpoint")
            if sequence is None:
                raise InputError(source, "--sequence", "missing", "a sequence id (see `wristmimic inspect`)")
            if exported:
                if frames is not None:
                    raise InputError(source, "--frames", "is for a converted sequence", "nothing (all exported frames)")
                s = record_export(source, sequence, out, dataset=dataset, hulls=hulls, plausibility=not no_plausibility)
            else:
                s = record_reference(source, sequence, out, hulls=hulls, max_frames=frames)
        else:
            if sequence is not None or frames is not None:
                flag = "--sequence" if sequence is not None else "--frames"
                raise InputError(source, flag, "is for a dataset", "nothing: a run has its scene and frames")
            opts = RunViewOptions(reference_only, trial_seed, start_frame, hulls, dataset)
            s = record_run(source, out, opts)
    sim = f", simulation {s.sim_frames} frames ({s.end_reason})" if s.sim_frames else ""
    typer.echo(f"wrote {s.path} ({s.bytes / 1024:.0f} KiB): reference {s.ref_frames} frames{sim}")
