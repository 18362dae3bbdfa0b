"""``wristmimic demo``: the whole suite on the built-in synthetic default, with no dataset or licensed file.

synth (canonical HDF5) -> validate -> train (CPU preset, short) -> evaluate (quick protocol) -> report -> view.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING

from wristmimic.errors import InputError

if TYPE_CHECKING:
    from wristmimic.evaluate.policy import RunPolicy

SCENE = "synth_default"


@dataclass(frozen=True)
class DemoConfig:
    """Sizes of the demo. ``quick`` is for CI (under 3 minutes on 2 cores), the default 10-25 minutes (see README)."""

    out: Path = Path("outputs/demo")
    """Everything goes here: demo.h5, run/, eval/, report/, demo.rrd."""
    seed: int = 0
    train_frames: int = 400_000
    """Training budget in environment frames (CPU preset; 8-16 minutes on 2 cores, depending on the machine; see
    the README's status for what the recipe reaches at this budget)."""
    trials: int = 256
    """Evaluation trials (the paper uses 10,000; see ``wristmimic evaluate``)."""
    num_envs: int | None = None
    """Training worlds; None: the CPU recipe's (the preset keeps its number of minibatches for another count)."""
    eval_envs: int = 64
    """Evaluation worlds (trials run in batches of this many)."""


QUICK = DemoConfig(train_frames=8_192, trials=32, num_envs=32, eval_envs=32)


@dataclass
class DemoResult:
    """Where the demo put things, and how long each stage took (s)."""

    dataset: Path
    run_dir: Path
    eval_dir: Path
    report_dir: Path
    recording: Path
    seconds: dict[str, float]
    success_pct: float
    deployed: str = ""
    """Which weights were evaluated, e.g. "the best periodic evaluation's (iteration 100, 204,800 frames)"."""
    strict_pct: float = float("nan")
    """Trials that also kept the object within 10 cm of its reference in every frame (evaluate.metrics)."""


def run_demo(
    cfg: DemoConfig, nthread: int | None = None, progress: bool = True, echo: Callable[[str], None] = print
) -> DemoResult:
    """Run every stage; refuses an ``out`` folder that already holds a demo run."""
    from wristmimic.evaluate.policy import load_eval_policy
    from wristmimic.evaluate.protocol import load_protocol
    from wristmimic.evaluate.runner import evaluate_policy
    from wristmimic.format.validate import validate
    from wristmimic.report.summary import build_report
    from wristmimic.rl.config import preset
    from wristmimic.rl.train import TrainSpec, start_run
    from wristmimic.synth.generate import generate
    from wristmimic.view.run import RunViewOptions, record_run

    out = Path(cfg.out)
    run_dir = out / "run"
    if (run_dir / "config.json").exists():
        raise InputError(out, None, "already holds a demo run", "a new --out folder (or delete this one)")
    out.mkdir(parents=True, exist_ok=True)
    t: dict[str, float] = {}

    def stage(name: str) -> float:
        echo(f"[demo] {name}")
        return time.perf_counter()

    t0 = stage("synth: generating the built-in scene (humanoid from stature proportions, box on a table)")
    dataset = generate(out / "demo.h5", seed=cfg.seed, variants=("default",))
    problems = validate(dataset)
    if problems:
        raise InputError(dataset, None, f"generated file does not validate: {problems[0]}")
    t["synth"] = time.perf_counter() - t0

    t0 = stage(f"train: PPO, CPU preset, {cfg.train_frames:,} frames")
    ppo = replace(preset("cpu", num_envs=cfg.num_envs), max_frames=cfg.train_frames)
    start_run(
        TrainSpec(dataset, SCENE, "wristmimic", cfg.seed, "cpu", ppo), run_dir, nthread=nthread, progress=progress
    )
    t["train"] = time.perf_counter() - t0

    t0 = stage(f"evaluate: {cfg.trials} trials from frame 0 (quick protocol)")
    eval_dir = out / "eval"
    policy = load_eval_policy(run_dir)
    res = evaluate_policy(
        policy,
        load_protocol("quick"),
        eval_dir,
        trials=cfg.trials,
        num_envs=cfg.eval_envs,
        nthread=nthread,
        progress=progress,
    )
    t["evaluate"] = time.perf_counter() - t0

    t0 = stage("report: tables, plots, summary.md")
    report_dir = out / "report"
    build_report([eval_dir], report_dir, "wristmimic demo")
    t["report"] = time.perf_counter() - t0

    t0 = stage("view: rerun recording of one rollout beside the reference")
    recording = out / "demo.rrd"
    record_run(run_dir, recording, RunViewOptions())
    t["view"] = time.perf_counter() - t0
    return DemoResult(
        dataset, run_dir, eval_dir, report_dir, recording, t, _success_pct(res), deployed_text(policy),
        100.0 * float(res.summary["strict_success_rate"]),
    )  # fmt: skip


def deployed_text(policy: RunPolicy) -> str:
    """Which weights a loaded run deploys, in words."""
    p = policy.policy
    kind = {"best": "the best periodic evaluation's", "ema": "the moving average's", "latest": "the last update's"}
    return f"{kind.get(p.weights, p.weights)} weights (iteration {p.weights_iteration}, {p.weights_frames:,} frames)"


def _success_pct(res: object) -> float:
    return 100.0 * float(res.summary["success_rate"])  # type: ignore[attr-defined]
