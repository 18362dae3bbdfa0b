"""Report tables from evaluation folders: per scene, per dataset, the paper's method x dataset layout, ablations.

Every table has a fixed column order and sorted rows (dataset in the order OMOMO, ParaHome, others; methods in
the paper's variant order; scenes by name) and is written with ``%.4f`` floats and ``\\n`` line ends, so the
same inputs give byte-identical files. Success rates come with a Wilson score 95 % interval; dataset rows pool
the trials of their scenes (equal trials per scene make that the mean over scenes).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pandas as pd

from wristmimic.errors import InputError
from wristmimic.evaluate.metrics import TRIAL_COLUMNS, wilson_interval
from wristmimic.evaluate.protocol import Split, load_split
from wristmimic.evaluate.runner import DATASET_LABELS, EVAL_FORMAT, METHOD_LABELS, TERMINATION_NAMES
from wristmimic.safe_io import atomic_output, first_sentence

FLOAT_FORMAT = "%.4f"
LABEL_COLUMNS = ["dataset_label", "dataset", "split", "method", "variant", "protocol", "hand"]
ERROR_COLUMNS = ["obj_pos_err_cm", "obj_rot_err_deg", "wrist_pos_err_cm", "wrist_rot_err_deg", "contact_ratio"]
RATE_COLUMNS = ["trials", "successes", "success_pct", "success_ci_low_pct", "success_ci_high_pct"]
STRICT_COLUMNS = ["strict_pct", "strict_ci_low_pct", "strict_ci_high_pct", "obj_pos_err_peak_cm"]
"""Success with the object never beyond the threshold in any frame (:mod:`wristmimic.evaluate.metrics`); NaN for
trial tables written before it existed."""
LATER_TRIAL_COLUMNS = {"obj_pos_err_peak_cm": math.nan, "strict_success": False}
"""Trial columns added after the first table format, and their fill for older tables (whose strict rates are NaN)."""
PER_SCENE_COLUMNS = [
    "dataset_label",
    "method",
    "scene",
    *RATE_COLUMNS,
    *ERROR_COLUMNS,
    *STRICT_COLUMNS,
    "completion_pct",
    "frames_completed_mean",
    "frames_total",
]
PER_DATASET_COLUMNS = [
    "dataset_label", "method", "scenes", *RATE_COLUMNS, *ERROR_COLUMNS, *STRICT_COLUMNS, "completion_pct"
]  # fmt: skip
ABLATION_COLUMNS = ["method", "variant", "scenes", *RATE_COLUMNS, "obj_pos_err_cm", "obj_rot_err_deg"]
HAND_COLUMNS = ["hand", "method", "dataset_label", "scenes", *RATE_COLUMNS, "obj_pos_err_cm", "obj_rot_err_deg", "cell"]
SOURCE_HAND = "(source hand)"
"""Hand label of evaluations without a swapped hand, in the hands table."""
TERMINATION_COLUMNS = ["dataset_label", "method", "scene", "trials", "completed", *TERMINATION_NAMES]
PAPER_REFERENCE = {
    ("WristMimic (Ours)", "OMOMO"): (98.9, 7.3, 12.2),
    ("WristMimic (Ours)", "ParaHome"): (83.3, 15.3, 33.9),
    ("InterMimic", "OMOMO"): (86.6, 14.2, 22.2),
    ("InterMimic", "ParaHome"): (0.1, 83.5, 73.3),
}
"""The paper's Table 1 (success % / object position cm / rotation deg), for comparison in summary.md."""


@dataclass
class EvalSet:
    """All trials of the evaluation folders of one report."""

    trials: pd.DataFrame
    """One row per trial: TRIAL_COLUMNS plus LABEL_COLUMNS."""
    sources: list[dict[str, Any]]
    """Per folder: path, scene, method, run_dir (for training curves), dataset and checkpoint_sha256 (the
    policy's, if recorded)."""


def find_eval_dirs(paths: list[Path]) -> list[Path]:
    """Folders holding ``summary.json``: each path itself, or every one below it (sorted)."""
    found: list[Path] = []
    for p in paths:
        p = Path(p)
        if (p / "summary.json").is_file():
            found.append(p)
        elif p.is_dir():
            below = sorted(q.parent for q in p.rglob("summary.json"))
            if not below:
                raise InputError(
                    p,
                    None,
                    "no evaluation found (no summary.json in or below it)",
                    "output folders of `wristmimic evaluate`",
                )
            found += below
        else:
            raise InputError(p, None, "not a folder")
    return sorted(dict.fromkeys(found))


def _json_kind(value: object) -> str:
    return {dict: "object", list: "list", str: "string", bool: "boolean"}.get(type(value), type(value).__name__)


def read_summary(path: Path) -> tuple[dict[str, Any], dict[str, Any]]:
    """An evaluation's ``summary.json`` and its first scene row; one-line :class:`InputError` when it is not one."""
    expected = "the summary.json `wristmimic evaluate` writes"
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except OSError as exc:
        raise InputError(path, None, f"cannot be read ({exc.strerror or type(exc).__name__})") from None
    except UnicodeDecodeError:
        raise InputError(path, "<file>", "not UTF-8 text", expected) from None
    except json.JSONDecodeError as exc:
        raise InputError(path, None, f"not valid JSON ({exc.msg})") from None
    if not isinstance(doc, dict):
        raise InputError(path, "<root>", f"holds a JSON {_json_kind(doc)}", "a JSON object: " + expected)
    if doc.get("format") != EVAL_FORMAT:
        raise InputError(path, "format", "not a wristmimic evaluation summary")
    scenes = doc.get("scenes")
    if not isinstance(scenes, list) or not scenes or not isinstance(scenes[0], dict):
        got = (
            "missing"
            if scenes is None
            else f"holds {'an empty list' if scenes == [] else 'a JSON ' + _json_kind(scenes)}"
        )
        raise InputError(path, "scenes", got, "a list of scene summaries (objects)")
    row = scenes[0]
    for key in ("scene", "method"):
        value = row.get(key)
        if not isinstance(value, str) or not value:
            raise InputError(path, f"scenes[0].{key}", "missing" if value is None else f"holds {value!r}", "a name")
    if "/" in row["scene"] or "\\" in row["scene"] or row["scene"] in (".", ".."):
        raise InputError(path, "scenes[0].scene", f"{row['scene']!r} is not a plain name", "a sequence id")
    policy = doc.get("policy", {})
    if not isinstance(policy, dict) or not isinstance(policy.get("run_dir", ""), str | None):
        raise InputError(path, "policy", "not an object with a run_dir string", expected)
    return doc, row


def read_trials(path: Path) -> pd.DataFrame:
    """An evaluation's per-trial table with :data:`TRIAL_COLUMNS` in their types; one-line errors otherwise."""
    try:
        df = pd.read_parquet(path)
    except (OSError, ValueError) as exc:  # pyarrow's ArrowInvalid is a ValueError; I/O errors are OSErrors
        reason = first_sentence(str(exc).split("': ", 1)[-1]) or type(exc).__name__
        raise InputError(
            path, "<file>", f"not a readable parquet file ({reason})", "the trial table `wristmimic evaluate` wrote"
        ) from None
    for col, fill in LATER_TRIAL_COLUMNS.items():
        if col not in df.columns:
            df[col] = fill
    missing = [c for c in TRIAL_COLUMNS if c not in df.columns]
    if missing:
        raise InputError(path, missing[0], "column missing", "a wristmimic trial table")
    df = df[list(TRIAL_COLUMNS)].copy()
    for col, dtype in TRIAL_COLUMNS.items():
        try:
            df[col] = df[col].astype(dtype)
        except (TypeError, ValueError):
            raise InputError(path, col, f"values of type {df[col].dtype}", f"{dtype} values") from None
    return df


def load_evals(paths: list[Path]) -> EvalSet:
    """Read the trial tables and labels of evaluation folders; one-line errors for mixed or duplicate inputs."""
    frames, sources = [], []
    seen: dict[tuple[str, str], Path] = {}
    for d in find_eval_dirs(paths):
        doc, row = read_summary(d / "summary.json")
        scene = row["scene"]
        key = (row["method"], scene)
        if key in seen:
            raise InputError(
                d, None, f"{row['method']} on {scene} is also in {seen[key]}", "one evaluation per method and scene"
            )
        seen[key] = d
        pq = d / f"{scene}.parquet"
        if not pq.is_file():
            raise InputError(pq, None, "trial table missing", "the folder as `wristmimic evaluate` wrote it")
        df = read_trials(pq)
        for c in LABEL_COLUMNS:
            df[c] = str(row.get(c, ""))
        frames.append(df)
        run_dir = doc.get("policy", {}).get("run_dir")
        dataset = doc.get("policy", {}).get("dataset")
        sha = doc.get("policy", {}).get("checkpoint_sha256")
        sources.append(
            {"path": str(d), "scene": scene, "method": row["method"], "run_dir": run_dir, "dataset": dataset,
             "checkpoint_sha256": sha if isinstance(sha, str) else None}
        )  # fmt: skip
    protocols = sorted({f["protocol"].iloc[0] for f in frames if len(f)})
    if len(protocols) > 1:
        raise InputError(
            None, "EVAL_DIRS", f"evaluations of different protocols ({', '.join(protocols)})", "one protocol per report"
        )
    trials = pd.concat(frames, ignore_index=True) if frames else pd.DataFrame(columns=[*TRIAL_COLUMNS, *LABEL_COLUMNS])
    return EvalSet(trials, sources)


# --------------------------------------------------------------------------------------------------- ordering


def dataset_order(labels: list[str]) -> list[str]:
    known = list(DATASET_LABELS.values())
    return sorted(set(labels), key=lambda x: (known.index(x) if x in known else len(known), x))


def method_order(methods: list[str]) -> list[str]:
    known = list(METHOD_LABELS.values())
    # the paper lists baselines first: InterMimic, then the ablations, then ours
    paper = [known[5], known[1], known[2], known[3], known[0], known[4]]

    def key(m: str) -> tuple[int, str]:
        base = next((i for i, k in enumerate(paper) if m == k or m.startswith(k + " [")), len(paper))
        return base, m

    return sorted(set(methods), key=key)


def _sort(df: pd.DataFrame, by: list[str]) -> pd.DataFrame:
    if df.empty:
        return df
    keys = {
        "dataset_label": {v: i for i, v in enumerate(dataset_order(df["dataset_label"].tolist()))}
        if "dataset_label" in df
        else {},
        "method": {v: i for i, v in enumerate(method_order(df["method"].tolist()))} if "method" in df else {},
    }

    def sort_key(col: pd.Series) -> pd.Series:
        return col.map(keys[col.name]) if keys.get(col.name) else col

    return df.sort_values(by, key=sort_key, kind="stable").reset_index(drop=True)


# ------------------------------------------------------------------------------------------------------ tables


def _rates(g: pd.DataFrame) -> dict[str, Any]:
    n, s = len(g), int(g["success"].sum())
    lo, hi = wilson_interval(s, n)
    out: dict[str, Any] = {
        "trials": n,
        "successes": s,
        "success_pct": 100.0 * s / n if n else math.nan,
        "success_ci_low_pct": 100.0 * lo,
        "success_ci_high_pct": 100.0 * hi,
    }
    out |= {c: float(g[c].mean()) if n else math.nan for c in ERROR_COLUMNS}
    judged = g[g["obj_pos_err_peak_cm"].notna()]  # older tables have no peak error: NaN, not 0 %
    m, k = len(judged), int(judged["strict_success"].sum())
    lo, hi = wilson_interval(k, m)
    out |= {"strict_pct": 100.0 * k / m if m else math.nan, "strict_ci_low_pct": 100.0 * lo}
    out |= {"strict_ci_high_pct": 100.0 * hi, "obj_pos_err_peak_cm": float(judged["obj_pos_err_peak_cm"].mean())}
    out["completion_pct"] = 100.0 * float((~g["terminated"]).mean()) if n else math.nan
    return out


def per_scene(t: pd.DataFrame) -> pd.DataFrame:
    """One row per (dataset, method, scene)."""
    rows = []
    for (ds, method, scene), g in t.groupby(["dataset_label", "method", "scene"], sort=True):
        r = {"dataset_label": ds, "method": method, "scene": scene, **_rates(g)}
        r["frames_completed_mean"] = float(g["frames_completed"].mean())
        r["frames_total"] = int(g["frames_total"].iloc[0])
        rows.append(r)
    return _sort(pd.DataFrame(rows, columns=PER_SCENE_COLUMNS), ["dataset_label", "method", "scene"])


def per_dataset(t: pd.DataFrame) -> pd.DataFrame:
    """One row per (dataset, method), trials pooled over its scenes."""
    rows = [
        {"dataset_label": ds, "method": m, "scenes": g["scene"].nunique(), **_rates(g)}
        for (ds, m), g in t.groupby(["dataset_label", "method"], sort=True)
    ]
    return _sort(pd.DataFrame(rows, columns=PER_DATASET_COLUMNS), ["dataset_label", "method"])


def cell(success_pct: float, pos_cm: float, rot_deg: float) -> str:
    """The paper's cell: ``success / object position / rotation`` with one decimal each."""
    return f"{success_pct:.1f} / {pos_cm:.1f} / {rot_deg:.1f}"


def paper_table(t: pd.DataFrame) -> pd.DataFrame:
    """Method x dataset cells ``success % / obj pos cm / obj rot deg`` and their average over the method's
    datasets (the paper's Table 1 layout; ``-`` where a method has no evaluation of a dataset)."""
    d = per_dataset(t)
    labels = dataset_order(d["dataset_label"].tolist())
    rows = []
    for m in method_order(d["method"].tolist()):
        sub = d[d["method"] == m].set_index("dataset_label")
        r = {"method": m}
        for ds in labels:
            r[ds] = cell(*sub.loc[ds, ["success_pct", "obj_pos_err_cm", "obj_rot_err_deg"]]) if ds in sub.index else "-"
        mean = sub[["success_pct", "obj_pos_err_cm", "obj_rot_err_deg"]].mean()
        r["Avg."] = cell(*mean) if len(labels) > 1 else r[labels[0]]
        rows.append(r)
    return pd.DataFrame(rows, columns=["method", *labels, "Avg."])


def ablations(t: pd.DataFrame) -> dict[str, pd.DataFrame]:
    """Per dataset with more than one method: one row per method on the scenes every method was evaluated on."""
    out = {}
    for ds in dataset_order(t["dataset_label"].tolist()):
        sub = t[t["dataset_label"] == ds]
        methods = method_order(sub["method"].tolist())
        if len(methods) < 2:
            continue
        common = set.intersection(*(set(sub.loc[sub["method"] == m, "scene"]) for m in methods))
        sub = sub[sub["scene"].isin(common)]
        rows = []
        for m in methods:
            g = sub[sub["method"] == m]
            r = _rates(g)
            rows.append({"method": m, "variant": g["variant"].iloc[0] if len(g) else "", "scenes": len(common), **r})
        out[ds] = pd.DataFrame(rows, columns=ABLATION_COLUMNS)
    return out


def hand_order(hands: list[str]) -> list[str]:
    """Built-in hands in their library order, then the source hand, then other hands by name."""
    from wristmimic.humanoid.hands import BUILTIN_HANDS

    known = [*BUILTIN_HANDS, SOURCE_HAND]
    return sorted(set(hands), key=lambda h: (known.index(h) if h in known else len(known), h))


def hands(t: pd.DataFrame) -> pd.DataFrame:
    """The paper's Table 4 (hand morphology) in long form: one row per (hand, method, dataset), trials pooled over
    scenes, with the ``success / obj pos / obj rot`` cell. Empty when no evaluation has a swapped hand."""
    if "hand" not in t or not (t["hand"] != "").any():
        return pd.DataFrame(columns=HAND_COLUMNS)
    t = t.assign(hand=t["hand"].where(t["hand"] != "", SOURCE_HAND), method=t["variant"].map(METHOD_LABELS))
    t["method"] = t["method"].fillna(t["variant"])
    rows = []
    for (h, m, ds), g in t.groupby(["hand", "method", "dataset_label"], sort=True):
        r = {"hand": h, "method": m, "dataset_label": ds, "scenes": g["scene"].nunique(), **_rates(g)}
        r["cell"] = cell(r["success_pct"], r["obj_pos_err_cm"], r["obj_rot_err_deg"])
        rows.append(r)
    df = pd.DataFrame(rows, columns=HAND_COLUMNS)
    order = {h: i for i, h in enumerate(hand_order(df["hand"].tolist()))}
    df = _sort(df, ["dataset_label", "method"])
    return df.sort_values("hand", key=lambda c: c.map(order), kind="stable").reset_index(drop=True)


def hands_layout(hand_t: pd.DataFrame) -> pd.DataFrame:
    """Hand x dataset cells as the paper's Table 4 (a method column only when several methods were run)."""
    labels = dataset_order(hand_t["dataset_label"].tolist())
    several = hand_t["method"].nunique() > 1
    rows = []
    for (h, m), g in hand_t.groupby(["hand", "method"], sort=False):
        sub = g.set_index("dataset_label")
        r = {"hand": h, **({"method": m} if several else {})}
        r |= {ds: sub.loc[ds, "cell"] if ds in sub.index else "-" for ds in labels}
        rows.append(r)
    return pd.DataFrame(rows, columns=["hand", *(["method"] if several else []), *labels])


def terminations(t: pd.DataFrame) -> pd.DataFrame:
    """Trials per termination reason for each (dataset, method, scene); ``completed`` = no early termination."""
    rows = []
    for (ds, m, scene), g in t.groupby(["dataset_label", "method", "scene"], sort=True):
        counts = g["termination_reason"].value_counts()
        r = {
            "dataset_label": ds,
            "method": m,
            "scene": scene,
            "trials": len(g),
            "completed": int((~g["terminated"]).sum()),
        }
        r |= {name: int(counts.get(name, 0)) for name in TERMINATION_NAMES}
        rows.append(r)
    return _sort(pd.DataFrame(rows, columns=TERMINATION_COLUMNS), ["dataset_label", "method", "scene"])


def write_csv(df: pd.DataFrame, path: Path) -> None:
    """Deterministic CSV: no index, ``%.4f`` floats, ``\\n`` line ends (atomic)."""
    with atomic_output(path, suffix=".csv") as tmp:
        df.to_csv(tmp, index=False, float_format=FLOAT_FORMAT, lineterminator="\n")


def select_splits(t: pd.DataFrame, names: list[str]) -> tuple[pd.DataFrame, list[Split]]:
    """Keep the trials of the scenes listed in the splits ``names``, labelled with each split's dataset label."""
    splits = [load_split(n) for n in names]
    label = {sid: sp.label for sp in splits for sid in sp.ids}
    name = {sid: sp.name for sp in splits for sid in sp.ids}
    keep = t[t["scene"].isin(list(label))].copy()
    keep["dataset_label"] = keep["scene"].map(label).astype("str")
    keep["split"] = keep["scene"].map(name).astype("str")
    return keep.reset_index(drop=True), splits


def coverage(t: pd.DataFrame, splits: list[Split]) -> pd.DataFrame:
    """Per split and method: scenes listed, scenes evaluated, and the missing ids."""
    rows = []
    for sp in splits:
        sub = t[t["scene"].isin(sp.ids)]
        for m in method_order(sub["method"].tolist()) or ["-"]:
            have = set(sub.loc[sub["method"] == m, "scene"])
            missing = [i for i in sp.ids if i not in have]
            rows.append({"split": sp.name, "method": m, "listed": len(sp.ids), "evaluated": len(have),
                         "missing": " ".join(missing)})  # fmt: skip
    return pd.DataFrame(rows, columns=["split", "method", "listed", "evaluated", "missing"])
