"""``wristmimic synth -o datasets/demo.h5``: write synthetic box-lifting sequences (no source data needed)."""

from __future__ import annotations

from pathlib import Path

import typer

from wristmimic.cli.errors import user_errors


def synth_cmd(
    out: Path = typer.Option(..., "--out", "-o", help="Output .h5 file (written atomically)."),
    seed: int = typer.Option(0, "--seed", help="Seed of the per-variant jitter (box placement, lift height)."),
    variant: list[str] = typer.Option(
        None,
        "--variant",
        "-v",
        help="Variant to generate (repeatable): default, turn, small_box, high_table [default: all].",
    ),
    height: float = typer.Option(1.70, "--height", help="Stature of the generated humanoid (m)."),
) -> None:
    """Generate a canonical file with a synthetic humanoid (SMPL-X body structure, 52 bodies, sized from
    published proportions of stature), a box on a table and, per variant, a reference made by inverse
    kinematics: stand, reach, grasp with both hands, lift, hold or turn, put down, release, retract (30 fps).
    Sequences are `synth_<variant>`; every parameter and the seed are recorded in the file.

    Example: wristmimic synth -o datasets/demo.h5 --variant default --variant turn
    """
    from wristmimic.safe_io import check_output_file
    from wristmimic.synth.generate import VARIANTS, generate

    with user_errors():
        check_output_file(out)
        p = generate(out, seed=seed, variants=tuple(variant or VARIANTS), height=height)
    names = ", ".join(f"synth_{v}" for v in (variant or VARIANTS))
    typer.echo(f"wrote {p}: {names}")
