"""``wristmimic scene DATASET.h5 SEQ -o scene.xml``: export the MuJoCo scene of one sequence as MJCF."""

from __future__ import annotations

from pathlib import Path

import typer

from wristmimic.cli.errors import user_errors


def scene_cmd(
    dataset: Path = typer.Argument(..., help="Canonical .h5 file."),
    sequence: str = typer.Argument(..., help="Sequence id (see `wristmimic inspect`)."),
    out: Path = typer.Option(..., "--out", "-o", help="MJCF file to write (meshes inline)."),
    timestep: float = typer.Option(1.0 / 120.0, help="Physics timestep (s)."),
    substeps: int = typer.Option(4, min=1, help="Physics steps per 30 Hz control step."),
) -> None:
    """Build the simulation scene of one sequence (PD humanoid, object hulls, supports, floor, sensors) and
    write it as MJCF for inspection, e.g. in MuJoCo's viewer (`python -m mujoco.viewer --mjcf scene.xml`).

    Example: wristmimic scene datasets/omomo.h5 sub2_largetable_000 -o scene.xml
    """
    from wristmimic.safe_io import check_output_file
    from wristmimic.scene import SceneConfig, export_scene_xml

    with user_errors():
        check_output_file(out)
        p = export_scene_xml(dataset, sequence, out, SceneConfig(timestep=timestep, substeps=substeps))
    typer.echo(f"wrote {p}")
