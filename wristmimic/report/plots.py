"""Report figures (matplotlib, Agg backend, PNG without a version stamp, so reruns give identical files)."""

from __future__ import annotations

import csv
import math
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from wristmimic.errors import InputError
from wristmimic.evaluate.runner import TERMINATION_NAMES
from wristmimic.report.tables import method_order
from wristmimic.safe_io import atomic_output

DPI = 110
REASON_COLORS = {"none": "#4c9a2a", "fall": "#7f7f7f", "body_error": "#1f77b4", "object_error": "#d62728",
                 "contact_lost": "#ff7f0e", "wrist": "#9467bd"}  # fmt: skip


def _plt() -> Any:
    try:
        import matplotlib
    except ImportError:
        raise InputError(
            None, "matplotlib", "not installed", "pip install matplotlib (needed for report plots)"
        ) from None
    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt

    plt.rcParams.update({"svg.hashsalt": "wristmimic", "font.size": 8})
    return plt


def _save(fig: Any, path: Path) -> None:
    with atomic_output(path, suffix=".png") as tmp:
        fig.savefig(tmp, format="png", dpi=DPI, metadata={"Software": None}, bbox_inches="tight")
    fig.clf()
    _plt().close(fig)


def success_per_scene(per_scene: pd.DataFrame, path: Path) -> None:
    """Horizontal bars: success % of every scene per method, Wilson 95 % interval as error bars."""
    plt = _plt()
    rows = per_scene.assign(label=per_scene["dataset_label"] + " / " + per_scene["scene"])
    labels = list(dict.fromkeys(rows["label"]))
    methods = method_order(rows["method"].tolist())
    h = 0.8 / max(len(methods), 1)
    fig, ax = plt.subplots(figsize=(7.0, 1.0 + 0.28 * len(labels) * max(1, len(methods)) ** 0.5))
    y = np.arange(len(labels))
    for i, m in enumerate(methods):
        r = rows[rows["method"] == m].set_index("label").reindex(labels)
        p = r["success_pct"].to_numpy(float)
        lo, hi = r["success_ci_low_pct"].to_numpy(float), r["success_ci_high_pct"].to_numpy(float)
        err = np.clip(np.vstack([p - lo, hi - p]), 0.0, None)
        ax.barh(y + (i - (len(methods) - 1) / 2) * h, p, height=h, xerr=err, capsize=2, label=m)
    ax.set_yticks(y, labels)
    ax.invert_yaxis()
    ax.set_xlim(0, 100)
    ax.set_xlabel("success rate (%) with Wilson 95 % interval")
    ax.legend(loc="lower left", bbox_to_anchor=(0.0, 1.01), fontsize=7, frameon=False, ncols=2)
    ax.grid(axis="x", alpha=0.3)
    fig.tight_layout()
    _save(fig, path)


def error_distributions(trials: pd.DataFrame, path: Path) -> None:
    """Histograms of per-trial object position (cm) and rotation (deg) errors per dataset and method."""
    plt = _plt()
    fig, axes = plt.subplots(1, 2, figsize=(9.0, 3.2))
    groups = sorted(trials.groupby(["dataset_label", "method"]).groups)
    for ax, col, unit in ((axes[0], "obj_pos_err_cm", "cm"), (axes[1], "obj_rot_err_deg", "deg")):
        vals = trials[col].to_numpy(float)
        finite = vals[np.isfinite(vals)]
        hi = float(np.percentile(finite, 99)) if finite.size else 1.0
        bins = np.linspace(0.0, max(hi, 1e-6), 41)
        for ds, m in groups:
            v = trials.loc[(trials["dataset_label"] == ds) & (trials["method"] == m), col].to_numpy(float)
            ax.hist(
                np.clip(v[np.isfinite(v)], 0, bins[-1]), bins=bins, histtype="step", density=True, label=f"{ds} / {m}"
            )
        if col == "obj_pos_err_cm":
            ax.axvline(10.0, color="k", ls="--", lw=0.8, label="10 cm success threshold")
        ax.set_xlabel(f"mean object {'position' if unit == 'cm' else 'rotation'} error per trial ({unit})")
        ax.set_ylabel("density")
    axes[0].legend(fontsize=6)
    fig.tight_layout()
    _save(fig, path)


def termination_reasons(term: pd.DataFrame, path: Path) -> None:
    """Stacked bars: share of trials per termination reason (``none`` = reached the end) for each scene."""
    plt = _plt()
    labels = (term["dataset_label"] + " / " + term["scene"] + " / " + term["method"]).tolist()
    fig, ax = plt.subplots(figsize=(7.0, 1.0 + 0.25 * len(labels)))
    left = np.zeros(len(term))
    n = term["trials"].to_numpy(float)
    for name in ["completed", *TERMINATION_NAMES]:
        share = 100.0 * term[name].to_numpy(float) / np.maximum(n, 1)
        color = REASON_COLORS["none" if name == "completed" else name]
        ax.barh(np.arange(len(labels)), share, left=left, color=color, label=name)
        left += share
    ax.set_yticks(np.arange(len(labels)), labels)
    ax.invert_yaxis()
    ax.set_xlim(0, 100)
    ax.set_xlabel("trials (%)")
    ax.legend(loc="lower left", bbox_to_anchor=(0.0, 1.01), fontsize=6, ncols=6, frameon=False)
    fig.tight_layout()
    _save(fig, path)


def read_metrics(run_dir: str | Path | None) -> pd.DataFrame | None:
    """A run's ``metrics.csv`` (frames, episode_length_mean, reward_mean), or None where absent or unreadable."""
    if not run_dir:
        return None
    f = Path(run_dir) / "metrics.csv"
    if not f.is_file():
        return None
    try:
        with open(f, newline="", encoding="utf-8") as fh:
            rows = list(csv.DictReader(fh))
    except (OSError, UnicodeDecodeError, csv.Error):
        return None

    def num(v: str | None) -> float:
        try:
            return float(v) if v not in (None, "") else math.nan
        except ValueError:
            return math.nan

    cols = ("frames", "episode_length_mean", "reward_mean")
    if not rows or any(c not in rows[0] for c in cols):
        return None
    return pd.DataFrame({c: [num(r[c]) for r in rows] for c in cols})


def training_curves(runs: list[tuple[str, pd.DataFrame]], path: Path) -> None:
    """Episode length and mean reward against training frames, one line per run."""
    plt = _plt()
    fig, axes = plt.subplots(1, 2, figsize=(9.0, 3.2))
    for label, m in runs:
        axes[0].plot(m["frames"], m["episode_length_mean"], lw=1, label=label)
        axes[1].plot(m["frames"], m["reward_mean"], lw=1, label=label)
    axes[0].set_ylabel("mean episode length (frames)")
    axes[1].set_ylabel("mean step reward")
    for ax in axes:
        ax.set_xlabel("environment frames")
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=6)
    fig.tight_layout()
    _save(fig, path)
