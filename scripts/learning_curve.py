"""Plot a training run's learning curves (episode length and reward vs frames) from its metrics.csv.

Usage:  python scripts/learning_curve.py RUN_DIR -o reports/learning_curve_<scene>.png [--smooth 10]

Panels: mean episode length, mean per-step reward and success rate against environment frames; faint lines are
per-iteration values, bold lines a moving average. The episode-length panel also shows, as points, how many frames
the periodic evaluation's frame-0 trials last, and (dotted, right axis) the training-only object controller's gain. The success panel shows the training success rate (episodes
that started at frame 0 and reached the last frame) and, as points, the periodic evaluation's
``eval/success_rate`` (frame-0 trials of the quick protocol, as ``wristmimic evaluate`` runs them) and, where logged,
``eval/strict_success_rate`` (the object within 10 cm of its reference in every frame).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import pandas as pd  # noqa: E402
from matplotlib.ticker import EngFormatter  # noqa: E402

from wristmimic.safe_io import atomic_output  # noqa: E402

PANELS = (("episode_length_mean", "mean episode length (frames)"), ("reward_mean", "mean reward per step"))
PANELS += (("success_rate", "success rate"),)


def plot(run_dir: Path, out: Path, smooth: int) -> Path:
    metrics = run_dir / "metrics.csv"
    if not metrics.is_file():
        sys.exit(f"error: {metrics}: not found (expected a run folder from `wristmimic train`)")
    m = pd.read_csv(metrics)
    if m.empty:
        sys.exit(f"error: {metrics}: no iterations yet")
    cfg = json.loads((run_dir / "config.json").read_text()) if (run_dir / "config.json").is_file() else {}
    title = f"{cfg.get('scene', run_dir.name)} [{cfg.get('variant', '?')}] seed {cfg.get('seed', '?')}"
    fig, axes = plt.subplots(1, len(PANELS), figsize=(5 * len(PANELS), 3.6), constrained_layout=True)
    for ax, (col, label) in zip(axes, PANELS, strict=True):
        y = m[col].astype(float)
        ax.plot(m["frames"], y, alpha=0.3, lw=0.8)
        ax.plot(m["frames"], y.rolling(smooth, min_periods=1).mean(), lw=2)
        if col == "success_rate" and "eval/success_rate" in m:
            ev = m[m["eval/success_rate"].notna()]
            ax.plot(ev["frames"], ev["eval/success_rate"], "o-", ms=4, label="evaluation (frame-0 trials)")
            if "eval/strict_success_rate" in m and ev["eval/strict_success_rate"].notna().any():
                ax.plot(ev["frames"], ev["eval/strict_success_rate"], "s--", ms=3, label="strict (object within 10 cm)")
            ax.legend(loc="upper left", fontsize=8)
        if col == "episode_length_mean":
            _episode_extras(ax, m)
        ax.set_xlabel("environment frames")
        ax.xaxis.set_major_formatter(EngFormatter(sep=""))  # 200k, 1M: no overlapping tick labels
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
    fig.suptitle(title)
    out.parent.mkdir(parents=True, exist_ok=True)
    with atomic_output(out, suffix=".png") as tmp:
        fig.savefig(tmp, dpi=120, format="png")
    plt.close(fig)
    return out


def _episode_extras(ax: plt.Axes, m: pd.DataFrame) -> None:
    """The periodic evaluation's frames completed per frame-0 trial (points) and, on a right-hand axis, the
    training-only object controller's gain where the run logs a nonzero one: where a scene's frame-0 trials end
    says more than a success rate of 0, and the gain says how much of the object's motion the policy was given."""
    if "eval/frames_completed" in m and m["eval/frames_completed"].notna().any():
        ev = m[m["eval/frames_completed"].notna()]
        ax.plot(ev["frames"], ev["eval/frames_completed"], "o-", ms=3, label="evaluation: frames per frame-0 trial")
        ax.legend(loc="upper left", fontsize=8)
    if "curriculum/object_gain" in m and (m["curriculum/object_gain"].astype(float) > 0).any():
        right = ax.twinx()
        right.plot(m["frames"], m["curriculum/object_gain"].astype(float), color="grey", ls=":", lw=1.5)
        right.set_ylim(0.0, 1.05)
        right.set_ylabel("object controller gain (dotted)", fontsize=8)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("run_dir", type=Path)
    ap.add_argument("-o", "--out", type=Path, help="PNG [default: reports/learning_curve_<scene>.png]")
    ap.add_argument("--smooth", type=int, default=10, help="moving-average window in iterations")
    args = ap.parse_args()
    scene = args.run_dir.name.split("-")[0]
    out = args.out or Path("reports") / f"learning_curve_{scene}.png"
    print(f"wrote {plot(args.run_dir, out, max(1, args.smooth))}")


if __name__ == "__main__":
    main()
