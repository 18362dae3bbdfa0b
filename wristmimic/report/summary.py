"""``report``: CSV tables, PNG plots and a ``summary.md`` that embeds them, from evaluation folders.

Output folder::

    summary.md                 the tables below as Markdown, the plots embedded, the paper's numbers beside ours
    paper_table.csv            method x dataset: success % / object position cm / rotation deg (paper Table 1)
    per_dataset.csv            per dataset and method (trials pooled), Wilson 95 % interval
    per_scene.csv              per scene and method
    coverage.csv               per split and method: scenes listed, evaluated, missing (when splits are known)
    ablation_<dataset>.csv     per method on the scenes every method of that dataset was evaluated on
    terminations.csv           trials per termination reason
    hands.csv                  per hand, method and dataset (paper Table 4), only when a hand was swapped
    plausibility.csv           per scene: plausibility metrics of the reference and of its exported rollouts
                               (with ``plausibility=[EXPORT.h5, ...]`` or an export found beside an evaluation,
                               see :func:`wristmimic.report.plausibility.exports_beside`; docs/plausibility.md)
    success_per_scene.png, error_distributions.png, termination_reasons.png, training_curves.png (if logs exist)
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import pandas as pd

from wristmimic.errors import InputError
from wristmimic.report import plots
from wristmimic.report import tables as T
from wristmimic.safe_io import atomic_output, check_output_folder


@dataclass
class ReportResult:
    out: Path
    files: list[str] = field(default_factory=list)
    trials: int = 0
    scenes: int = 0
    exports: list[Path] = field(default_factory=list)
    """Export files whose rollouts are in plausibility.csv (given and found)."""


STRICT_NOTE = (
    "`strict_pct`: trials that succeed by the paper's rule and whose object never leaves the same 10 cm of its "
    "reference in any frame (`obj_pos_err_peak_cm`: the mean over trials of that largest error); the paper's mean "
    "over the clip lets a short lift that never happens pass. NaN: evaluations written before it was recorded."
)


def markdown_table(df: pd.DataFrame, digits: dict[str, int] | None = None) -> str:
    """A GitHub Markdown table (floats with ``digits[col]`` decimals, default 2)."""
    digits = digits or {}

    def f(c: str, v: object) -> str:
        if isinstance(v, float):
            return "" if math.isnan(v) else f"{v:.{digits.get(c, 2)}f}"
        return str(v).replace("|", "\\|")

    head = "| " + " | ".join(df.columns) + " |"
    sep = "|" + "|".join("---" for _ in df.columns) + "|"
    body = [
        "| " + " | ".join(f(c, v) for c, v in zip(df.columns, row, strict=True)) + " |"
        for row in df.itertuples(index=False)
    ]
    return "\n".join([head, sep, *body])


def build_report(
    eval_dirs: list[Path],
    out: Path,
    title: str | None = None,
    splits: list[str] | None = None,
    plausibility: list[Path] | None = None,
    find_exports: bool = True,
) -> ReportResult:
    """Read evaluation folders and write every table, plot and ``summary.md`` into ``out``.

    ``splits`` (names in ``eval/splits`` or paths): keep only their scenes, label datasets by split, and report
    which listed scenes have no evaluation. Without it, the splits the evaluations recorded are used for that.
    ``plausibility``: files of ``wristmimic export``; adds ``plausibility.csv``, reference against simulation
    for every evaluated scene. ``find_exports``: also use the exports of the evaluated policies found beside
    their evaluations (:func:`~wristmimic.report.plausibility.exports_beside`).
    """
    check_output_folder(out, None)
    ev = T.load_evals(eval_dirs)
    t = ev.trials
    if splits:
        t, used = T.select_splits(t, splits)
        if t.empty:
            raise InputError(None, "--split", f"no evaluated scene is in {', '.join(splits)}")
    else:
        used = [T.load_split(n) for n in sorted(set(t["split"]) - {""})]
    cover = T.coverage(t, used)
    out = Path(out)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(out, None, f"cannot make the report folder ({exc.strerror or type(exc).__name__})") from None
    res = ReportResult(out, trials=len(t), scenes=t["scene"].nunique())
    scene_t, dataset_t, paper_t = T.per_scene(t), T.per_dataset(t), T.paper_table(t)
    term_t = T.terminations(t)
    written = {
        "paper_table.csv": paper_t,
        "per_dataset.csv": dataset_t,
        "per_scene.csv": scene_t,
        "terminations.csv": term_t,
    }
    if len(cover):
        written["coverage.csv"] = cover
    abl = T.ablations(t)
    for ds, df in abl.items():
        written[f"ablation_{ds.lower()}.csv"] = df
    hand_t = T.hands(t)
    if len(hand_t):
        written["hands.csv"] = hand_t
    plaus_t = None
    exports = list(plausibility or [])
    if find_exports:
        from wristmimic.report.plausibility import exports_beside

        given = {Path(p).resolve() for p in exports}
        exports += [p for p in exports_beside(ev.sources) if p not in given]
    if exports:
        from wristmimic.report.plausibility import plausibility_table

        datasets = {s["scene"]: s["dataset"] for s in ev.sources if s.get("dataset")}
        plaus_t = plausibility_table(sorted(set(t["scene"])), exports, datasets)
        written["plausibility.csv"] = plaus_t
        res.exports = [Path(p) for p in exports]
    for name, df in written.items():
        T.write_csv(df, out / name)
    res.files += list(written)
    plots.success_per_scene(scene_t, out / "success_per_scene.png")
    plots.error_distributions(t, out / "error_distributions.png")
    plots.termination_reasons(term_t, out / "termination_reasons.png")
    res.files += ["success_per_scene.png", "error_distributions.png", "termination_reasons.png"]
    runs = []
    for s in sorted(ev.sources, key=lambda s: (s["method"], s["scene"])):
        m = plots.read_metrics(s["run_dir"])
        if m is not None:
            runs.append((f"{s['scene']} / {s['method']}", m))
    if runs:
        plots.training_curves(runs, out / "training_curves.png")
        res.files.append("training_curves.png")
    md = _markdown(title or out.name, t, paper_t, dataset_t, scene_t, abl, ev, bool(runs), cover, hand_t, plaus_t)
    with atomic_output(out / "summary.md") as tmp:
        tmp.write_text(md)
    res.files.append("summary.md")
    return res


def _markdown(
    title: str,
    t: pd.DataFrame,
    paper_t: pd.DataFrame,
    dataset_t: pd.DataFrame,
    scene_t: pd.DataFrame,
    abl: dict[str, pd.DataFrame],
    ev: T.EvalSet,
    curves: bool,
    cover: pd.DataFrame,
    hand_t: pd.DataFrame | None = None,
    plaus_t: pd.DataFrame | None = None,
) -> str:
    protocol = t["protocol"].iloc[0] if len(t) else ""
    noise = ", ".join(sorted(set(t["noise"]))) if len(t) else ""
    per = t.groupby(["method", "scene"]).size()
    trials = f"{int(per.min()):,}" if len(per) and per.min() == per.max() else "varying"
    lines = [
        f"# {title}",
        "",
        f"Protocol `{protocol}`: {trials} trials per scene from frame 0, trials differ by {noise or '-'}; "
        f"{t['scene'].nunique()} scene(s), {len(t):,} trials, {len(ev.sources)} evaluation folder(s). A trial "
        "succeeds when it reaches the end without early termination, its mean object position error is below the "
        "protocol's threshold (paper: 10 cm) and it keeps hand contact for at least the protocol's share (paper: "
        "80 %) of the reference contact duration. Intervals are Wilson score 95 % intervals; dataset rows pool "
        "the trials of their scenes.",
        "",
        "## Method x dataset (success % / object position cm / object rotation deg)",
        "",
        markdown_table(paper_t),
        "",
    ]
    ref = [
        {"method": m, "dataset": ds, "paper": T.cell(*v)}
        for (m, ds), v in T.PAPER_REFERENCE.items()
        if m in set(paper_t["method"])
    ]
    if ref:
        lines += ["The paper's Table 1 for the same methods (its 20 + 20 scenes, not necessarily ours):", "",
                  markdown_table(pd.DataFrame(ref)), ""]  # fmt: skip
    if hand_t is not None and len(hand_t):
        lines += ["## Hand morphology (success % / object position cm / object rotation deg)", "",
                  "Each hand was swapped onto the humanoid at the wrists (`wristmimic humanoid swap-hands`) and "
                  "trained and evaluated on its own, as the paper's Table 4.", "",
                  markdown_table(T.hands_layout(hand_t)), ""]  # fmt: skip
    if len(cover):
        lines += ["## Coverage of the splits", "", markdown_table(cover), ""]
    cols = ["dataset_label", "method", "scenes", "trials", "success_pct", "success_ci_low_pct", "success_ci_high_pct",
            "obj_pos_err_cm", "obj_rot_err_deg", "wrist_pos_err_cm", "wrist_rot_err_deg", "contact_ratio",
            "strict_pct", "obj_pos_err_peak_cm"]  # fmt: skip
    lines += ["## Per dataset", "", STRICT_NOTE, "", markdown_table(dataset_t[cols]), ""]
    for ds, df in abl.items():
        lines += [f"## Ablation: {ds} (scenes every method was evaluated on)", "",
                  markdown_table(df.drop(columns=["variant"])), ""]  # fmt: skip
    cols = ["dataset_label", "method", "scene", "trials", "success_pct", "success_ci_low_pct", "success_ci_high_pct",
            "obj_pos_err_cm", "obj_rot_err_deg", "contact_ratio", "strict_pct", "obj_pos_err_peak_cm", "completion_pct",
            "frames_completed_mean"]  # fmt: skip
    lines += ["## Per scene", "", markdown_table(scene_t[cols]), ""]
    if plaus_t is not None:
        from wristmimic.report.plausibility import markdown_layout

        lines += ["## Physical plausibility: reference / simulation", "",
                  "Each cell is the reference's value / the mean over the scene's exported rollouts (`-`: none); "
                  "definitions and thresholds in `docs/plausibility.md`, every metric in `plausibility.csv`. "
                  "Penetrations are the deepest over the sequence; the simulation's labelled gap is small by "
                  "construction (an export labels contact where the simulation touches).", "",
                  markdown_table(markdown_layout(plaus_t)), ""]  # fmt: skip
    lines += ["## Plots", "", "![success per scene](success_per_scene.png)", "",
              "![object error distributions](error_distributions.png)", "",
              "![termination reasons](termination_reasons.png)", ""]  # fmt: skip
    if curves:
        lines += ["![training curves](training_curves.png)", ""]
    else:
        lines += ["No training logs (`metrics.csv` in the run folders) were found: no training curves.", ""]
    lines += ["## Inputs", "", *(f"- `{s['path']}` ({s['scene']}, {s['method']})" for s in ev.sources), ""]
    return "\n".join(lines)
