"""``wristmimic convert <source> SRC -o OUT.h5``: source files -> one canonical HDF5 file."""

from __future__ import annotations

from pathlib import Path

import typer

from wristmimic.cli.errors import user_errors
from wristmimic.convert.common import ConvertOptions, ConvertReport
from wristmimic.convert.hulls import HullParams
from wristmimic.safe_io import check_output_file

app = typer.Typer(help="Convert source datasets into the canonical HDF5 reference format.", no_args_is_help=True)

_OUT = typer.Option(..., "--out", "-o", help="Output .h5 file (written atomically).")
_CACHE = typer.Option(
    None, "--hull-cache", help="coacd cache folder [default: $WRISTMIMIC_CACHE_DIR/hulls or ~/.cache/wristmimic/hulls]."
)
_NOCACHE = typer.Option(False, "--no-hull-cache", help="Recompute every collision hull.")
_SEED = typer.Option(0, "--hull-seed", help="coacd seed (recorded in the file).")
_QUIET = typer.Option(False, "--quiet", "-q", help="No progress bars.")


def _options(cache: Path | None, no_cache: bool, seed: int, quiet: bool) -> ConvertOptions:
    return ConvertOptions(
        hull_cache_dir=cache, use_hull_cache=not no_cache, hull_params=HullParams(seed=seed), show_progress=not quiet
    )


def _summary(r: ConvertReport) -> None:
    hits = sum(r.hull_cache_hits.values())
    typer.echo(
        f"wrote {r.output}: {len(r.sequences)} sequence(s), {len(r.hull_cache_hits)} object(s) "
        f"({hits} hull cache hit(s))"
    )
    for sid, why in sorted(r.skipped.items()):
        typer.echo(f"skipped {sid}: {why}", err=True)


@app.command("intermimic")
def intermimic(
    src: Path = typer.Argument(
        ..., help="Folder with motions/*.pt, objects/ and the humanoid .xml (like ../shared/data/intermimic_omomo)."
    ),
    out: Path = _OUT,
    sequence: list[str] = typer.Option(
        None, "--sequence", "-s", help="Convert only these sequence ids (repeatable) [default: all]."
    ),
    humanoid: Path = typer.Option(None, "--humanoid", help="Humanoid MJCF [default: the one .xml in SRC]."),
    object_name: str = typer.Option(
        None, "--object", help="Object name for every sequence [default: from the name sub<N>_<object>_<NNN>]."
    ),
    generic_humanoid: bool = typer.Option(
        False,
        "--generic-humanoid",
        help="Use the humanoid .xml as shipped for every sequence. Default: one humanoid per subject "
        "(<xml stem>_<subject>) whose bone offsets are read from the stored body positions and whose feet reach "
        "the floor; the shipped omomo.xml floats sub2's feet 8-11 cm.",
    ),
    hull_cache: Path = _CACHE,
    no_hull_cache: bool = _NOCACHE,
    hull_seed: int = _SEED,
    quiet: bool = _QUIET,
) -> None:
    """InterMimic / InterAct OMOMO `.pt` files (T x 591, xyzw) -> canonical HDF5.

    Example: wristmimic convert intermimic ../shared/data/intermimic_omomo -o datasets/omomo.h5
    """
    from wristmimic.convert.intermimic import convert_intermimic

    with user_errors():
        check_output_file(out)
        r = convert_intermimic(
            src,
            out,
            sequences=sequence or None,
            humanoid=humanoid,
            object_name=object_name,
            options=_options(hull_cache, no_hull_cache, hull_seed, quiet),
            fit_subjects=not generic_humanoid,
        )
    _summary(r)


@app.command("skillmimic-parahome")
def skillmimic_parahome(
    src: Path = typer.Argument(
        ...,
        help="Folder with motions/**/NNN_sXX_<skill>[_<a>_<b>].pt, humanoids/sXX.xml "
        "and objects/ (like ../shared/data/skillmimic_parahome).",
    ),
    out: Path = _OUT,
    clip: list[str] = typer.Option(
        None, "--clip", "-c", help="Convert only these clips (sequence id or file stem, repeatable) [default: all]."
    ),
    subject: str = typer.Option(
        None, "--subject", help="Humanoid humanoids/<SUBJECT>.xml for every clip [default: sXX from the name]."
    ),
    objects: str = typer.Option(
        None,
        "--objects",
        help="Comma-separated object names for every clip "
        "[default: from the skill, e.g. pour_kettlecup -> kettle,cup].",
    ),
    skip_missing: bool = typer.Option(
        False, "--skip-missing", help="Skip (and report) clips whose humanoid or mesh is missing instead of failing."
    ),
    hull_cache: Path = _CACHE,
    no_hull_cache: bool = _NOCACHE,
    hull_seed: int = _SEED,
    quiet: bool = _QUIET,
) -> None:
    """SkillMimic(-V2) ParaHome clips (T x 409 / 415, rotation vectors) -> canonical HDF5, with contacts from
    geometry and inferred static supports.

    Example: wristmimic convert skillmimic-parahome ../shared/data/skillmimic_parahome -o datasets/parahome.h5
    """
    from wristmimic.convert.skillmimic_parahome import convert_skillmimic_parahome

    with user_errors():
        check_output_file(out)
        r = convert_skillmimic_parahome(
            src,
            out,
            clips=clip or None,
            subject=subject,
            objects=[o.strip() for o in objects.split(",")] if objects else None,
            skip_missing=skip_missing,
            options=_options(hull_cache, no_hull_cache, hull_seed, quiet),
        )
    _summary(r)


@app.command("parahome-raw")
def parahome_raw(
    root: Path = typer.Argument(
        ..., help="ParaHome data folder with seq/sN/*.pkl and scan/<obj>/simplified/*.obj (or sN/ beside scan/)."
    ),
    sequence: str = typer.Option(..., "--sequence", "-s", help="Sequence folder name, e.g. s110."),
    out: Path = _OUT,
    frames: list[str] = typer.Option(
        None, "--frames", help="Clip START:END (end exclusive, repeatable); id sN_<START>_<END>."
    ),
    annotation: list[int] = typer.Option(
        None, "--annotation", "-a", help="Clip = the N-th text annotation, sorted by start (repeatable)."
    ),
    skip_missing: bool = typer.Option(
        False, "--skip-missing", help="Skip (and report) object parts whose mesh is missing instead of failing."
    ),
    hull_cache: Path = _CACHE,
    no_hull_cache: bool = _NOCACHE,
    hull_seed: int = _SEED,
    quiet: bool = _QUIET,
) -> None:
    """Raw ParaHome sequence (6D orientations, bone vectors, object part transforms) -> canonical HDF5, with a
    humanoid generated from the sequence's bone vectors, every scene object part placed per frame, and contacts
    from geometry. Without --frames / --annotation the whole sequence is one clip.

    Example: wristmimic convert parahome-raw data/ -s s110 --frames 200:355 -o datasets/s110.h5
    """
    from wristmimic.convert.parahome_raw import convert_parahome_raw

    with user_errors():
        check_output_file(out)
        r = convert_parahome_raw(
            root,
            sequence,
            out,
            frames=frames or None,
            annotations=annotation or None,
            skip_missing=skip_missing,
            options=_options(hull_cache, no_hull_cache, hull_seed, quiet),
        )
    _summary(r)


@app.command("omomo-raw")
def omomo_raw(
    pickle_file: Path = typer.Argument(
        ..., help="OMOMO joblib file, e.g. train_diffusion_manip_seq_joints24.p (read without running code)."
    ),
    objects: Path = typer.Option(
        ..., "--objects", help="captured_objects/ folder with <obj>_cleaned_simplified[_top|_bottom].obj."
    ),
    out: Path = _OUT,
    smplx_models: Path = typer.Option(
        None,
        "--smplx-models",
        help="Folder with SMPLX_MALE.npz / SMPLX_FEMALE.npz (or smplx/SMPLX_*.npz) from "
        "https://smpl-x.is.tue.mpg.de (free registration); builds each subject's humanoid.",
    ),
    sequence: list[str] = typer.Option(
        None, "--sequence", "-s", help="Convert only these seq_name values (repeatable) [default: all]."
    ),
    hull_cache: Path = _CACHE,
    no_hull_cache: bool = _NOCACHE,
    hull_seed: int = _SEED,
    quiet: bool = _QUIET,
) -> None:
    """Raw OMOMO records (SMPL-X betas and pose, object pose and scale) -> canonical HDF5, with per-subject
    humanoids generated from the SMPL-X shape, mesh scale baked per sequence, Z-up kept, contacts from geometry.

    Example: wristmimic convert omomo-raw data/test_diffusion_manip_seq_joints24.p --objects
    data/captured_objects --smplx-models data/smpl_all_models -s sub16_suitcase_000 -o datasets/omomo_raw.h5
    """
    from wristmimic.convert.omomo_raw import convert_omomo_raw

    with user_errors():
        check_output_file(out)
        r = convert_omomo_raw(
            pickle_file,
            objects,
            out,
            smplx_models=smplx_models,
            sequences=sequence or None,
            options=_options(hull_cache, no_hull_cache, hull_seed, quiet),
        )
    _summary(r)
