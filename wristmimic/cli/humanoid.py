"""``wristmimic humanoid <source> ... -o OUT.xml``: generate a humanoid MJCF on its own."""

from __future__ import annotations

from pathlib import Path

import typer

from wristmimic.cli.errors import user_errors

app = typer.Typer(help="Generate humanoid MJCF files from source body descriptions.", no_args_is_help=True)


@app.command("parahome")
def parahome(
    bone_vectors: Path = typer.Argument(..., help="A raw ParaHome sequence's bone_vectors.pkl."),
    out: Path = typer.Option(..., "--out", "-o", help="Output MJCF .xml (written atomically)."),
    name: str = typer.Option(None, "--name", help="Model name [default: the sequence folder, e.g. s110]."),
) -> None:
    """The 61-body ParaHome humanoid (SkillMimic-V2 layout) with body offsets from the subject's bone vectors.

    Example: wristmimic humanoid parahome data/seq/s110/bone_vectors.pkl -o s110.xml
    """
    from wristmimic.humanoid.parahome import generate_parahome_humanoid
    from wristmimic.humanoid.skeleton import load_skeleton
    from wristmimic.safe_io import atomic_output

    with user_errors():
        mjcf = generate_parahome_humanoid(bone_vectors, name)
        skel = load_skeleton(mjcf, out)
        with atomic_output(out, ".xml") as tmp:
            tmp.write_text(mjcf)
    typer.echo(f"wrote {out}: {skel.num_bodies} bodies, {3 * skel.num_joints} hinges")
