"""Ablation of the CPU training recipe: one row per lever, every row at the same frame budget and seed.

Usage:  python scripts/ablation.py DATASET.h5 --scene synth_default --frames 400000 -o reports/ablation_synth_default
        [--rows recipe,white_noise,latest_weights,absolute,fixed_ppo,no_curriculum,uniform_starts,training_sigma,
        sigma_anneal,update_1204]
        [--trials 256]
        [--seed 0] [--nthread N]

Each row trains with ``wristmimic.rl.start_run`` (the ``cpu`` preset with one lever changed) and is evaluated
under the quick protocol with ``--trials`` frame-0 trials, as ``wristmimic evaluate`` does. Writes
``OUT/ablation.csv`` (success % by the strict and the paper's rule, Wilson 95 % intervals, median approx KL and
clip fraction, the periodic evaluations, frames completed, errors, termination counts, training
seconds) and ``OUT/ablation.md``, and keeps each row's ``config.json``, ``metrics.csv`` and evaluation
``summary.json`` under ``OUT/<row>/`` (checkpoints stay in ``--work``). A row already evaluated in ``--work`` is
not run again.
"""

from __future__ import annotations

import argparse
import json
import shutil
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

import pandas as pd

from wristmimic.env.config import ObjectControllerConfig, StartSamplingConfig
from wristmimic.evaluate.policy import load_eval_policy
from wristmimic.evaluate.protocol import load_protocol
from wristmimic.evaluate.runner import evaluate_policy
from wristmimic.rl import TrainSpec, preset, start_run
from wristmimic.rl.config import preset_env
from wristmimic.safe_io import atomic_output

ROWS: dict[str, tuple[str, dict[str, Any], dict[str, Any]]] = {
    # name: (what changes, EnvConfig fields, PPOConfig fields)
    "recipe": ("the CPU recipe (cpu preset)", {}, {}),
    "absolute": ("absolute PD targets (InterMimic) instead of residual", {"action_mode": "absolute"}, {}),
    "fixed_ppo": (
        "fixed lr (the recipe's starting rate) and fixed sigma 0.1 (no adaptive-KL schedule, no learned sigma)",
        {},
        {"schedule": "fixed", "learn_std": False},
    ),
    "no_curriculum": ("no virtual object controller", {"object_controller": ObjectControllerConfig(enabled=False)}, {}),
    "uniform_starts": (
        "uniform start frames (no failure weighting)",
        {"starts": StartSamplingConfig(adaptive=False)},
        {},
    ),
    "white_noise": (
        "white exploration noise (no AR(1) temporal correlation)",
        {},
        {"noise_correlation": 0.0},
    ),
    "latest_weights": ("the recipe's run, deploying its last update instead of the best periodic evaluation", {}, {}),
    "training_sigma": ("the recipe's run, deployed with the training sigma (~0.1) instead of 0.003", {}, {}),
    "update_1204": (
        "the update of 2026-12-04: 2 epochs x 2 minibatches of 256, the rate adapted per minibatch to the sampled"
        " approx KL (desired 0.008, from and floored at 1e-5)",
        {},
        {
            "epochs": 2,
            "minibatch_size": 256,
            "schedule": "adaptive",
            "kl_source": "approx",
            "learning_rate": 1e-5,
            "desired_kl": 0.008,
            "lr_min": 1e-5,
        },
    ),
    "sigma_anneal": (
        "training sigma annealed 0.1 -> 0.003 over the first 250k frames (not learned)",
        {},
        {"learn_std": False, "min_std": 0.0, "final_std": 0.003, "std_anneal_end": 250_000},
    ),
}


EVAL_ONLY: dict[str, tuple[str, str, float | None]] = {
    "latest_weights": ("recipe", "latest", None),
    "training_sigma": ("recipe", "deployed", 0.0),
}
"""Rows that train nothing: they evaluate another row's run with other weights (``load_eval_policy(weights=)``) or
another sigma of the sampled actions (0: the training sigma)."""


def run_row(
    name: str, dataset: Path, scene: str, frames: int, seed: int, trials: int, work: Path, nthread: int | None = None
) -> dict[str, Any]:
    what, env_kw, ppo_kw = ROWS[name]
    env = replace(preset_env("cpu", "wristmimic"), **env_kw)
    ppo = replace(preset("cpu"), max_frames=frames, **ppo_kw)
    source, weights, sigma = EVAL_ONLY.get(name, (name, "deployed", None))
    if source != name and not (work / source / "run" / "checkpoint.pt").is_file():
        run_row(source, dataset, scene, frames, seed, trials, work, nthread)
    run_dir, eval_dir = work / source / "run", work / name / "eval"
    t0 = time.perf_counter()
    if not (eval_dir / "summary.json").is_file():
        if source == name:
            if run_dir.exists():
                shutil.rmtree(run_dir)
            spec = TrainSpec(dataset, scene, "wristmimic", seed, "cpu", ppo, env=env)
            start_run(spec, run_dir, nthread=nthread, progress=False)
        policy = load_eval_policy(run_dir, weights)
        if sigma is not None:
            policy.policy.deploy_std = sigma
        evaluate_policy(policy, load_protocol("quick"), eval_dir, trials=trials, nthread=nthread, progress=False)
    s = json.loads((eval_dir / "summary.json").read_text())["scenes"][0]
    lo, hi = float(s["success_ci_low"]), float(s["success_ci_high"])
    m = pd.read_csv(run_dir / "metrics.csv")
    return {
        "row": name,
        "change": what,
        "frames": int(m["frames"].iloc[-1]),
        "train_s": round(float(m["seconds"].iloc[-1]), 1),
        "trials": int(s["trials"]),
        "success_pct": round(100 * float(s["success_rate"]), 1),
        "ci95_low_pct": round(100 * lo, 1),
        "ci95_high_pct": round(100 * hi, 1),
        "strict_success_pct": round(100 * float(s["strict_success_rate"]), 1),
        "strict_ci95_low_pct": round(100 * float(s["strict_success_ci_low"]), 1),
        "strict_ci95_high_pct": round(100 * float(s["strict_success_ci_high"]), 1),
        "frames_completed_mean": round(float(s["frames_completed_mean"]), 1),
        "frames_total": int(s["frames_total"]),
        "contact_ratio": round(float(s["contact_ratio"]), 3),
        "obj_pos_err_cm": round(float(s["obj_pos_err_cm"]), 2),
        "wrist_pos_err_cm": round(float(s["wrist_pos_err_cm"]), 2),
        **{k: int(v) for k, v in s.items() if k.startswith("terminated_")},
        **_training_signals(m),
        "seconds_wall": round(time.perf_counter() - t0, 1),
    }


def _training_signals(m: pd.DataFrame) -> dict[str, Any]:
    """Median approx KL, update KL (closed form; None for runs that predate it) and clip fraction over the run's
    updates, and its periodic frame-0 evaluations (%)."""
    periodic = m["eval/success_rate"].dropna() if "eval/success_rate" in m else pd.Series(dtype=float)
    kl_update = round(float(m["loss/kl_update"].median()), 4) if "loss/kl_update" in m else None
    return {
        "median_approx_kl": round(float(m["loss/approx_kl"].median()), 4),
        "median_kl_update": kl_update,
        "median_clip_fraction": round(float(m["loss/clip_fraction"].median()), 3),
        "periodic_success_pct": " ".join(f"{100 * v:.0f}" for v in periodic),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("dataset", type=Path)
    ap.add_argument("--scene", default="synth_default")
    ap.add_argument("--frames", type=int, default=400_000)
    ap.add_argument("--trials", type=int, default=256)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--nthread", type=int, default=None, help="physics threads per run (default: all cores)")
    ap.add_argument("--rows", default=",".join(ROWS))
    ap.add_argument("--work", type=Path, default=Path("runs/ablation"))
    ap.add_argument("-o", "--out", type=Path, default=Path("reports/ablation_synth_default"))
    args = ap.parse_args()
    rows = [r.strip() for r in args.rows.split(",") if r.strip()]
    unknown = [r for r in rows if r not in ROWS]
    if unknown:
        raise SystemExit(f"error: unknown row(s) {', '.join(unknown)}; expected some of {', '.join(ROWS)}")
    table = []
    for name in rows:
        print(f"[ablation] {name}: {ROWS[name][0]}", flush=True)
        table.append(
            run_row(name, args.dataset, args.scene, args.frames, args.seed, args.trials, args.work, args.nthread)
        )
        print(json.dumps(table[-1]), flush=True)
        keep = args.out / name
        keep.mkdir(parents=True, exist_ok=True)
        run_of = EVAL_ONLY.get(name, (name,))[0]
        for src in ("run/config.json", "run/metrics.csv", "eval/summary.json"):
            folder = run_of if src.startswith("run/") else name
            shutil.copyfile(args.work / folder / src, keep / Path(src).name)
    df = pd.DataFrame(table)
    args.out.mkdir(parents=True, exist_ok=True)
    with atomic_output(args.out / "ablation.csv") as tmp:
        df.to_csv(tmp, index=False)
    cols = ["row", "change", "strict_success_pct", "strict_ci95_low_pct", "strict_ci95_high_pct", "success_pct"]
    cols += ["frames_completed_mean", "median_kl_update", "median_approx_kl", "median_clip_fraction", "train_s"]
    md = (
        f"# Ablation on {args.scene}: {args.frames:,} frames, seed {args.seed}, {args.trials} quick-protocol trials\n\n"
    )
    md += "| " + " | ".join(cols) + " |\n|" + "---|" * len(cols) + "\n"
    md += "".join("| " + " | ".join(str(r[c]) for c in cols) + " |\n" for r in table)
    with atomic_output(args.out / "ablation.md") as tmp:
        tmp.write_text(md)
    print(f"wrote {args.out / 'ablation.csv'} and ablation.md")


if __name__ == "__main__":
    main()
