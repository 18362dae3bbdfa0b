"""``wristmimic humanoid <source> ... -o OUT.xml``: generate a humanoid MJCF on its own; ``swap-hands``, ``hands``."""

from __future__ import annotations

from pathlib import Path

import typer

from wristmimic.cli.errors import user_errors

app = typer.Typer(
    help="Generate humanoid MJCF files from source body descriptions; swap a humanoid's hands.", no_args_is_help=True
)


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
    from wristmimic.safe_io import atomic_output, check_output_file

    with user_errors():
        check_output_file(out)
        mjcf = generate_parahome_humanoid(bone_vectors, name)
        skel = load_skeleton(mjcf, out)
        with atomic_output(out, ".xml") as tmp:
            tmp.write_text(mjcf)
    typer.echo(f"wrote {out}: {skel.num_bodies} bodies, {3 * skel.num_joints} hinges")


@app.command("swap-hands")
def swap_hands_cmd(
    dataset: Path = typer.Argument(..., help="Canonical .h5 file holding the sequence."),
    sequence: str = typer.Argument(..., help="Sequence id, e.g. sub2_largetable_000 (see `wristmimic inspect`)."),
    hand: str = typer.Option(
        ...,
        "--hand",
        help="A built-in hand (smplx-intermimic, smplx-free, parahome-box; see `wristmimic humanoid hands`) or an "
        "MJCF file holding a right hand below a palm body.",
    ),
    out: Path = typer.Option(..., "--out", "-o", help="Output .h5 (written atomically; one sequence)."),
    palm: str = typer.Option("palm", "--palm", help="MJCF hand: name of the (right) palm body."),
    left_palm: str = typer.Option(
        None, "--left-palm", help="MJCF hand: name of a left palm body [default: mirror the right hand]."
    ),
    ranges: str = typer.Option(
        None,
        "--ranges",
        help="Finger joint ranges: intermimic (InterMimic's, by position along each finger), free ([-pi, pi]) or "
        "hand (the MJCF's own) [default: the built-in hand's; hand for an MJCF].",
    ),
) -> None:
    """Replace both hands of the sequence's humanoid with another hand and write the sequence with it.

    The hand's palm frame is placed at each wrist body's frame, so the wrist reference is unchanged; the new
    humanoid's roles (fingers, fingertips, contact bodies) come from the new hand, and the reference keeps body,
    wrist and object targets (new finger bodies hold their rest pose; they are no targets). An MJCF hand is given
    as a right hand in the humanoid's T-pose convention (x forward = thumb side, fingers along -y, palm facing -z);
    its left hand is the mirror image unless --left-palm names one.

    Example: wristmimic humanoid swap-hands datasets/parahome.h5 s110_move_kettle --hand smplx-free -o free.h5
    """
    from wristmimic.humanoid.hands import swap_hands
    from wristmimic.safe_io import check_output_file

    with user_errors():
        check_output_file(out)
        r = swap_hands(dataset, sequence, hand, out, palm=palm, left_palm=left_palm, ranges=ranges)
    typer.echo(
        f"wrote {r.out}: {r.sequence_id} with hand {r.hand} ({r.hand_source}); humanoid {r.humanoid_id}: "
        f"{r.num_bodies[0]} -> {r.num_bodies[1]} bodies, {r.num_fingers[0]} -> {r.num_fingers[1]} finger bodies; "
        f"wrist pose under reference replay: max deviation {r.wrist_deviation[0]:.2g} m / "
        f"{r.wrist_deviation[1]:.2g} rad"
    )


@app.command("hands")
def hands_cmd() -> None:
    """List the built-in hands of `wristmimic humanoid swap-hands`."""
    from wristmimic.humanoid.hands import BUILTIN_HANDS

    for h in BUILTIN_HANDS.values():
        typer.echo(f"{h.name:<18} ranges {h.ranges:<11} {h.description}")
    typer.echo("or an MJCF file: --hand hand.xml --palm PALM_BODY (a right hand; the left one is mirrored)")
