"""Pipelines: ``wristmimic run pipelines/NAME.toml`` runs convert -> hands -> train -> evaluate -> export ->
report.

Each stage is registered in :data:`STAGES` by name; a stage does its work in units (one converted file, one
trained scene) through :meth:`Context.cached`, which skips a unit whose input fingerprint (content hashes of its
input files, its parameters, the code version) and output hashes match the last run. The record lives in
``<work_dir>/pipeline_state.json``.

Training and evaluation are planned as per-scene :class:`Job` s (one (dataset, scene) run, then its evaluation).
By default they run here, stage by stage, as below; with ``wristmimic run --ray ADDRESS`` the train stage hands
them to :mod:`wristmimic.distributed`, which runs each job (train then evaluate) as a Ray task and records the
results here; the report is built from the same evaluation folders either way.

A pipeline file (paths relative to the current folder)::

    [pipeline]
    name = "omomo"                       # work_dir defaults to runs/pipelines/<name>
    ray_cpus_per_job = 2                 # with --ray: CPUs (and threads) per job; ray_gpus_per_job = 0
    [convert]
    format = "intermimic"                # or "skillmimic-parahome"
    source = "../shared/data/intermimic_omomo"
    output = "datasets/omomo.h5"
    [hands]                              # optional: one file per hand (pipelines/hands.toml)
    scene = "sub2_largetable_000"
    hands = ["smplx-intermimic", "smplx-free", "parahome-box"]
    [train]
    scenes = ["sub2_largetable_000"]     # or "all"
    variant = "wristmimic"
    preset = "cpu"
    seed = 0
    backend = "cpu"                      # or "warp" (MuJoCo Warp; device = "cuda" by default)
    [train.ppo]                          # optional overrides of the preset
    max_frames = 5_000_000
    [evaluate]
    protocol = "paper"                   # eval/protocols/<name>.toml; trials = ... overrides
    backend = "cpu"                      # or "warp", as [train]
    [export]                             # optional: rollouts of each scene -> <output>/<scene>.h5
    trials = 100                         # the evaluation's first rows (same protocol), else fresh trials
    successful_only = true
    output = "datasets/omomo_sim"        # default <work_dir>/export
    [report]                             # output = "reports/omomo" (default <work_dir>/report)
"""

from __future__ import annotations

import hashlib
import json
import tomllib
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

import wristmimic
from wristmimic.errors import InputError
from wristmimic.safe_io import atomic_output, sha256_file

if TYPE_CHECKING:
    from wristmimic.distributed import RayOptions
    from wristmimic.evaluate.protocol import Protocol as EvalProtocol
    from wristmimic.rl.train import TrainResult, TrainSpec

STATE_FILE = "pipeline_state.json"


def _read_state(state_file: Path) -> dict[str, Any]:
    """The recorded stage results of an earlier run ({} if none); one-line error for a damaged file."""
    if not state_file.exists():
        return {}
    expected = "the pipeline's state: a JSON object (delete the file to run every stage again)"
    try:
        state = json.loads(state_file.read_text(encoding="utf-8"))
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise InputError(state_file, None, f"not valid JSON ({str(exc).splitlines()[0][:120]})", expected) from None
    if not isinstance(state, dict):
        raise InputError(state_file, None, f"holds a JSON {type(state).__name__}", expected)
    return state


class Executor(Protocol):
    """Runs the planned jobs elsewhere (:class:`wristmimic.distributed.RayExecutor`): train each job, evaluate it
    when ``evaluate`` (the ``[evaluate]`` table) is given, record both units in ``ctx`` and set
    ``ctx.outputs["runs"]``, ``["evals"]``; raises :class:`~wristmimic.errors.WristmimicError` if a job failed."""

    def run(self, ctx: Context, jobs: list[Job], evaluate: dict[str, Any] | None) -> None: ...


@dataclass
class Context:
    """What stages share: the work folder, the cache record, outputs of earlier stages, the summary."""

    spec_path: Path
    work_dir: Path
    progress: bool = True
    nthread: int | None = None
    outputs: dict[str, Any] = field(default_factory=dict)
    """Values later stages read, e.g. ``outputs["dataset"]`` (the converted file)."""
    summary: list[tuple[str, str]] = field(default_factory=list)
    """(unit, status) with status ``ran``, ``up to date`` or ``not available yet`` (with ``--ray`` also ``failed``
    or ``skipped``)."""
    echo: Callable[[str], None] = print
    state: dict[str, Any] = field(default_factory=dict)
    spec: dict[str, Any] = field(default_factory=dict)
    """The whole pipeline file (tables by stage name)."""
    executor: Executor | None = None
    """None: jobs run here, in the train and evaluate stages; else the executor runs them (``--ray``)."""

    def cached(self, unit: str, inputs: dict[str, Any], outputs: list[Path], work: Callable[[], None]) -> bool:
        """Run ``work`` unless ``unit`` already ran with the same ``inputs`` and its ``outputs`` are unchanged.
        Returns True when work was done."""
        if self.up_to_date(unit, inputs, outputs):
            self.note(unit, "up to date")
            return False
        self.echo(f"{unit}: running")
        work()
        self.record(unit, inputs, outputs)
        self.note(unit, "ran")
        return True

    def up_to_date(self, unit: str, inputs: dict[str, Any], outputs: list[Path]) -> bool:
        """Whether ``unit`` is recorded with the same ``inputs`` and the current hashes of its ``outputs``."""
        rec = self.state.get(unit)
        return bool(rec) and rec["key"] == _inputs_key(inputs) and rec["outputs"] == _output_hashes(outputs)

    def record(self, unit: str, inputs: dict[str, Any], outputs: list[Path]) -> None:
        """Record that ``unit`` ran with ``inputs`` and made ``outputs`` (saved at once)."""
        self.state[unit] = {"key": _inputs_key(inputs), "outputs": _output_hashes(outputs)}
        self._save_state()

    def note(self, unit: str, status: str) -> None:
        """Add ``(unit, status)`` to the summary and say it."""
        self.summary.append((unit, status))
        self.echo(f"{unit}: {status}")

    _note = note  # the old private name, for stages written against it

    def _save_state(self) -> None:
        with atomic_output(self.work_dir / STATE_FILE) as tmp:
            tmp.write_text(json.dumps(self.state, indent=2, sort_keys=True) + "\n")


@dataclass(frozen=True)
class Stage:
    """A pipeline stage: ``run(ctx, params)`` with the TOML table's ``params``; ``run=None``: not available."""

    name: str
    run: Callable[[Context, dict[str, Any]], None] | None
    keys: frozenset[str] = frozenset()
    """Accepted keys of the stage's TOML table."""
    note: str = ""


STAGES: dict[str, Stage] = {}
"""Stage registry in execution order."""


def register(name: str, keys: set[str], note: str = "") -> Callable:
    """Decorator: register ``run(ctx, params)`` as stage ``name``."""

    def deco(fn: Callable[[Context, dict[str, Any]], None]) -> Callable:
        STAGES[name] = Stage(name, fn, frozenset(keys), note)
        return fn

    return deco


def _inputs_key(inputs: dict[str, Any]) -> str:
    return hashlib.sha256(json.dumps(inputs, sort_keys=True, default=str).encode()).hexdigest()


def _output_hashes(outputs: list[Path]) -> dict[str, str | None]:
    return {str(o): _hash_path(o) for o in outputs}


def _hash_path(p: Path) -> str | None:
    """sha256 of a file, of a folder's files (names and contents), None if absent."""
    p = Path(p)
    if p.is_file():
        return sha256_file(p)
    if not p.is_dir():
        return None
    h = hashlib.sha256()
    for f in sorted(q for q in p.rglob("*") if q.is_file()):
        h.update(f"{f.relative_to(p).as_posix()}\0{sha256_file(f)}\n".encode())
    return h.hexdigest()


# ----------------------------------------------------------------------------------------------- stages


@register("convert", {"format", "source", "output", "sequences", "hull_cache"})
def convert_stage(ctx: Context, p: dict[str, Any]) -> None:
    """Source folder -> canonical HDF5 (``outputs["dataset"]``)."""
    from wristmimic.convert.common import ConvertOptions
    from wristmimic.convert.intermimic import convert_intermimic
    from wristmimic.convert.skillmimic_parahome import convert_skillmimic_parahome

    converters = {"intermimic": convert_intermimic, "skillmimic-parahome": convert_skillmimic_parahome}
    fmt, src, out = p.get("format"), Path(_require(p, "convert", "source")), Path(_require(p, "convert", "output"))
    if fmt not in converters:
        raise InputError(ctx.spec_path, "convert.format", f"{fmt!r}", f"one of {', '.join(converters)}")
    if not src.is_dir():
        raise InputError(ctx.spec_path, "convert.source", f"folder {src} not found")
    sequences = p.get("sequences")
    cache = Path(p["hull_cache"]) if p.get("hull_cache") else None

    def work() -> None:
        out.parent.mkdir(parents=True, exist_ok=True)
        opts = ConvertOptions(hull_cache_dir=cache, show_progress=ctx.progress)
        pick = {"sequences": sequences} if fmt == "intermimic" else {"clips": sequences}
        converters[fmt](src, out, options=opts, **pick)

    inputs = {"format": fmt, "source": _hash_path(src), "sequences": sequences, "code": wristmimic.__version__}
    ctx.cached(f"convert {out}", inputs, [out], work)
    ctx.outputs["dataset"] = out


@register("hands", {"dataset", "scene", "hands", "output_dir", "palm", "ranges"})
def hands_stage(ctx: Context, p: dict[str, Any]) -> None:
    """The hand-morphology study: one file per hand with ``scene`` and that hand swapped onto both wrists
    (``<output_dir>/<scene>-<hand>.h5``, default ``<work_dir>/hands``); sets ``outputs["datasets"]`` (the files,
    in ``hands`` order) and ``outputs["scenes"]``. ``hands``: built-in names or MJCF paths (default: every
    built-in hand); ``palm`` and ``ranges`` apply to MJCF hands / override the range mode."""
    from wristmimic.humanoid.hands import BUILTIN_HANDS, swap_hands

    dataset = Path(p.get("dataset") or ctx.outputs.get("dataset") or _require(p, "hands", "dataset"))
    if not dataset.is_file():
        raise InputError(ctx.spec_path, "hands.dataset", f"file {dataset} not found")
    scene = str(_require(p, "hands", "scene"))
    hands = p.get("hands", list(BUILTIN_HANDS))
    if not isinstance(hands, list) or not hands or not all(isinstance(h, str) for h in hands):
        raise InputError(ctx.spec_path, "hands.hands", f"{hands!r}", "a non-empty list of hand names or MJCF paths")
    out_dir = Path(p.get("output_dir", ctx.work_dir / "hands"))
    sha, files = sha256_file(dataset), []
    for hand in hands:
        builtin = hand in BUILTIN_HANDS
        label = hand if builtin else Path(hand).stem
        if not builtin and not Path(hand).is_file():
            raise InputError(ctx.spec_path, "hands.hands", f"{hand!r} is no built-in hand nor a file",
                             f"one of {', '.join(BUILTIN_HANDS)} or an MJCF path")  # fmt: skip
        out = out_dir / f"{scene}-{label}{'-' + p['ranges'] if p.get('ranges') else ''}.h5"
        inputs = {"dataset_sha256": sha, "scene": scene, "hand": hand if builtin else _hash_path(Path(hand))}
        inputs |= {"palm": p.get("palm", "palm"), "ranges": p.get("ranges"), "code": wristmimic.__version__}

        def work(hand: str = hand, out: Path = out) -> None:
            out.parent.mkdir(parents=True, exist_ok=True)
            r = swap_hands(dataset, scene, hand, out, palm=p.get("palm", "palm"), ranges=p.get("ranges"))
            ctx.echo(f"{out}: hand {r.hand}, {r.num_fingers[1]} finger bodies, wrist deviation "
                     f"{r.wrist_deviation[0]:.1g} m / {r.wrist_deviation[1]:.1g} rad")  # fmt: skip

        ctx.cached(f"hands {scene} {label}", inputs, [out], work)
        files.append(out)
    ctx.outputs["datasets"] = files
    ctx.outputs["scenes"] = [scene]


@dataclass
class Job:
    """One (dataset, scene): train a run into ``run_dir``, then evaluate it (``run_dir/eval/<protocol>``)."""

    spec: TrainSpec
    run_dir: Path
    """``<work_dir>/runs/<scene>-<variant>-seed<seed>-<key>``; ``key`` hashes the cache inputs."""
    unit: str
    """Cache unit of the training: ``train <scene>`` (``train <dataset stem>/<scene>`` for several datasets)."""
    inputs: dict[str, Any]
    """Cache inputs of the training: dataset sha256, scene, variant, seed, PPO config, code version."""

    @property
    def checkpoint(self) -> Path:
        return self.run_dir / "checkpoint.pt"


def plan_jobs(ctx: Context, p: dict[str, Any]) -> list[Job]:
    """The jobs of the ``[train]`` table: its ``scenes`` (or all) of every dataset, in order.

    Datasets: ``outputs["datasets"]`` (set by a stage before train) when present, else ``[train].dataset`` or
    the converted ``outputs["dataset"]``."""
    from wristmimic.format.reader import open_dataset
    from wristmimic.rl.config import preset, to_jsonable
    from wristmimic.rl.train import TrainSpec
    from wristmimic.sim.backend import BACKENDS

    if ctx.outputs.get("datasets"):
        datasets = [Path(d) for d in ctx.outputs["datasets"]]
    else:
        datasets = [Path(p.get("dataset") or ctx.outputs.get("dataset") or _require(p, "train", "dataset"))]
    variant, seed, name = p.get("variant", "wristmimic"), int(p.get("seed", 0)), p.get("preset", "cpu")
    ppo = preset(name, **p.get("ppo", {}))
    backend, device = p.get("backend", "cpu"), p.get("device")
    if backend not in BACKENDS:
        raise InputError(ctx.spec_path, "train.backend", f"{backend!r}", f"one of {', '.join(BACKENDS)}")
    jobs = []
    for dataset in datasets:
        if not dataset.is_file():
            raise InputError(ctx.spec_path, "train.dataset", f"file {dataset} not found")
        scenes = p.get("scenes", "all")
        if scenes == "all":
            with open_dataset(dataset) as ds:
                scenes = list(ds.sequence_ids)
        sha = sha256_file(dataset)
        for scene in scenes:
            spec = TrainSpec(
                dataset, scene, variant, seed, name, ppo, ref_frames=p.get("ref_frames"), backend=backend, device=device
            )
            inputs = {"dataset_sha256": sha, "scene": scene, "variant": variant, "seed": seed}
            inputs |= {"ppo": to_jsonable(ppo), "ref_frames": spec.ref_frames, "code": wristmimic.__version__}
            if backend != "cpu":  # CPU runs keep the keys (and run folders) they had before backends existed
                inputs |= {"physics": {"backend": backend, "device": device}}
            key = hashlib.sha256(json.dumps(inputs, sort_keys=True).encode()).hexdigest()[:8]
            run_dir = ctx.work_dir / "runs" / f"{scene}-{variant}-seed{seed}-{key}"
            unit = f"train {scene}" if len(datasets) == 1 else f"train {dataset.stem}/{scene}"
            jobs.append(Job(spec, run_dir, unit, inputs))
    return jobs


def train_job(
    spec: TrainSpec,
    run_dir: Path,
    nthread: int | None,
    progress: bool,
    dataset_file: Path | None = None,
    should_stop: Callable[[], bool] | None = None,
) -> TrainResult:
    """Start the run in ``run_dir``, or resume it from its checkpoint (``should_stop``: stop after an iteration,
    checkpoint saved). ``nthread`` sets the physics and the torch threads (as a Ray job's CPUs do), so a serial
    and a distributed run of the same job compute the same bits."""
    from wristmimic.rl.train import resume_run, start_run
    from wristmimic.threads import torch_threads

    kw: dict[str, Any] = {"nthread": nthread, "progress": progress, "dataset_file": dataset_file}
    kw["should_stop"] = should_stop
    with torch_threads(nthread):
        if (Path(run_dir) / "checkpoint.pt").exists():
            return resume_run(run_dir, **kw)
        return start_run(spec, run_dir, **kw)


def evaluate_job(
    run_dir: Path,
    protocol: EvalProtocol,
    p: dict[str, Any],
    nthread: int | None,
    progress: bool,
    dataset_file: Path | None = None,
    recorded_run_dir: Path | None = None,
    should_stop: Callable[[], bool] | None = None,
) -> Path:
    """Evaluate the run in ``run_dir`` under ``protocol`` with the ``[evaluate]`` table ``p``; returns
    ``run_dir/eval/<protocol>``. ``recorded_run_dir``: the run's path to record (when evaluated in a copy)."""
    from wristmimic.evaluate.policy import load_eval_policy
    from wristmimic.evaluate.runner import evaluate_policy

    out = Path(run_dir) / "eval" / protocol.name
    policy = load_eval_policy(run_dir)
    if recorded_run_dir is not None:
        rec = Path(recorded_run_dir)
        policy.metadata |= {"run_dir": str(rec), "checkpoint": str(rec / "checkpoint.pt")}
    evaluate_policy(
        policy,
        protocol,
        out,
        trials=p.get("trials"),
        noise=p.get("noise"),
        seed=p.get("seed"),
        num_envs=int(p.get("num_envs", 256)),
        nthread=nthread,
        dataset=dataset_file,
        progress=progress,
        backend=p.get("backend", "cpu"),
        backend_options={"device": p["device"]} if p.get("device") else None,
        should_stop=should_stop,
    )
    return out


def eval_unit(run_dir: Path) -> str:
    return f"evaluate {Path(run_dir).name}"


def eval_inputs(run_dir: Path, p: dict[str, Any]) -> dict[str, Any]:
    """Cache inputs of a run's evaluation: its checkpoint's hash, the ``[evaluate]`` table, the code version."""
    return {"checkpoint": _hash_path(Path(run_dir) / "checkpoint.pt"), "params": p, "code": wristmimic.__version__}


@register("train", {"dataset", "scenes", "variant", "preset", "seed", "ref_frames", "ppo", "backend", "device"})
def train_stage(ctx: Context, p: dict[str, Any]) -> None:
    """One PPO run per job (dataset, scene) in ``<work_dir>/runs/<scene>-<variant>-seed<seed>-<key>``; an
    interrupted run resumes. With an executor (``--ray``) each job also runs its evaluation there."""
    jobs = plan_jobs(ctx, p)
    ctx.outputs["jobs"] = jobs
    if ctx.executor is not None:
        ctx.executor.run(ctx, jobs, ctx.spec.get("evaluate"))
        return
    for job in jobs:

        def work(job: Job = job) -> None:
            r = train_job(job.spec, job.run_dir, ctx.nthread, ctx.progress)
            if r.status == "interrupted":
                ctx.echo(f"{job.run_dir}: interrupted, checkpoint saved; run the pipeline again to resume")
                raise KeyboardInterrupt
            ctx.echo(f"{job.run_dir}: {r.status} at iteration {r.iteration} ({r.frames:,} frames)")

        ctx.cached(job.unit, job.inputs, [job.checkpoint], work)
        ctx.outputs.setdefault("runs", []).append(job.run_dir)


@register("evaluate", {"protocol", "trials", "noise", "seed", "num_envs", "backend", "device"})
def evaluate_stage(ctx: Context, p: dict[str, Any]) -> None:
    """Evaluate every trained run (``outputs["runs"]``) under a protocol into ``<run>/eval/<protocol>``."""
    from wristmimic.evaluate.protocol import load_protocol

    if ctx.outputs.get("jobs_evaluated"):
        return  # the executor evaluated each job after training it
    protocol = load_protocol(p.get("protocol", "paper"))
    runs = ctx.outputs.get("runs") or []
    if not runs:
        raise InputError(ctx.spec_path, "[evaluate]", "no trained run to evaluate", "a [train] stage before it")
    for run_dir in runs:
        out = Path(run_dir) / "eval" / protocol.name

        def work(run_dir: Path = Path(run_dir)) -> None:
            evaluate_job(run_dir, protocol, p, ctx.nthread, ctx.progress)

        ctx.cached(eval_unit(run_dir), eval_inputs(run_dir, p), [out], work)
        ctx.outputs.setdefault("evals", []).append(out)


EXPORT_KEYS = {"trials", "successful_only", "protocol", "output", "noise", "seed", "num_envs", "backend", "device"}


def export_file(out_dir: Path, job: Job, several_datasets: bool) -> Path:
    """``<out_dir>/<scene>.h5`` (``<dataset stem>-<scene>.h5`` when the pipeline trains several datasets)."""
    scene = job.spec.scene
    return Path(out_dir) / (f"{Path(job.spec.dataset).stem}-{scene}.h5" if several_datasets else f"{scene}.h5")


@register("export", EXPORT_KEYS)
def export_stage(ctx: Context, p: dict[str, Any]) -> None:
    """Rollouts of every trained scene written as a canonical file ``<output>/<scene>.h5`` (default output
    ``<work_dir>/export``), one file per scene: each holds one run's humanoid, objects and provenance (the root
    ``export`` attribute names one checkpoint), and a scene re-exports alone when its checkpoint changes.

    With the ``[evaluate]`` stage under the same protocol, the export re-runs the first ``trials`` rows of that
    evaluation's table by their seeds (``successful_only``: of its successful rows; default: every row); else
    ``trials`` fresh trials as ``evaluate`` would run them (``noise``, ``seed``; default: the policy mean).
    Cached on the checkpoint's hash, the evaluation's files, the protocol, the table and the code version."""
    from wristmimic.evaluate.export import export_rollouts
    from wristmimic.evaluate.policy import load_eval_policy
    from wristmimic.evaluate.protocol import load_protocol

    jobs: list[Job] = ctx.outputs.get("jobs") or []
    if not jobs:
        raise InputError(ctx.spec_path, "[export]", "no trained run to export", "a [train] stage before it")
    evaluate = ctx.spec.get("evaluate")
    protocol = load_protocol(p.get("protocol", (evaluate or {}).get("protocol", "paper")))
    trials = p.get("trials")
    if trials is not None and (isinstance(trials, bool) or not isinstance(trials, int) or trials < 1):
        raise InputError(ctx.spec_path, "export.trials", f"{trials!r}", "an integer >= 1")
    if not isinstance(p.get("successful_only", False), bool):
        raise InputError(ctx.spec_path, "export.successful_only", f"{p['successful_only']!r}", "true or false")
    replay = evaluate is not None and load_protocol(evaluate.get("protocol", "paper")).name == protocol.name
    if replay and ("noise" in p or "seed" in p):
        raise InputError(ctx.spec_path, "export.noise/seed", "given with an evaluation to replay",
                         "the evaluation's own (leave them out, or export under another protocol)")  # fmt: skip
    out_dir = Path(p.get("output", ctx.work_dir / "export"))
    several = len({str(j.spec.dataset) for j in jobs}) > 1
    for job in jobs:
        out = export_file(out_dir, job, several)
        eval_dir = job.run_dir / "eval" / protocol.name if replay else None
        inputs = {"checkpoint": _hash_path(job.checkpoint), "params": p, "protocol": protocol.to_dict()}
        inputs |= {"evaluation": _hash_path(eval_dir) if eval_dir else None, "code": wristmimic.__version__}

        def work(job: Job = job, out: Path = out, eval_dir: Path | None = eval_dir) -> None:
            out.parent.mkdir(parents=True, exist_ok=True)
            ok_only = bool(p.get("successful_only", False))
            try:
                r = export_rollouts(
                    load_eval_policy(job.run_dir),
                    out,
                    trials=trials,
                    successful_only=ok_only,
                    from_eval=eval_dir,
                    protocol=protocol,
                    noise=p.get("noise"),
                    seed=p.get("seed"),
                    num_envs=int(p.get("num_envs", 256)),
                    nthread=ctx.nthread,
                    backend=p.get("backend"),
                    backend_options={"device": p["device"]} if p.get("device") else None,
                    force=True,
                    progress=ctx.progress,
                )
            except InputError as exc:
                if not (ok_only and "succeeded" in str(exc)):
                    raise
                ctx.echo(f"{out}: not written, no successful trial ({exc})")
                out.unlink(missing_ok=True)
                return
            ctx.echo(f"{out}: {len(r.sequences)} sequence(s) of {r.trials_run} trial(s), {r.successes} successful")

        unit = "export " + (f"{Path(job.spec.dataset).stem}/{job.spec.scene}" if several else job.spec.scene)
        ctx.cached(unit, inputs, [out], work)
        if out.is_file():
            ctx.outputs.setdefault("exports", []).append(out)


@register("report", {"output", "title", "splits"})
def report_stage(ctx: Context, p: dict[str, Any]) -> None:
    """Tables, plots and summary.md of every evaluation of this pipeline (``output``, default ``<work_dir>/report``)."""
    from wristmimic.report.summary import build_report

    evals = ctx.outputs.get("evals") or []
    if not evals:
        raise InputError(ctx.spec_path, "[report]", "no evaluation to report", "an [evaluate] stage before it")
    out = Path(p.get("output", ctx.work_dir / "report"))
    exports = [Path(e) for e in ctx.outputs.get("exports") or []]  # the [export] stage's files, if it ran
    inputs = {"evals": {str(e): _hash_path(e) for e in evals}, "params": p, "code": wristmimic.__version__}
    if exports:
        inputs["exports"] = {str(e): _hash_path(e) for e in exports}

    def work() -> None:
        build_report(list(evals), out, p.get("title"), p.get("splits"), exports or None)

    ctx.cached("report", inputs, [out], work)


# ---------------------------------------------------------------------------------------------- running


def _require(p: dict[str, Any], stage: str, key: str) -> Any:
    if key not in p:
        raise InputError(None, f"[{stage}]", f"missing key {key!r}")
    return p[key]


def load_spec(path: Path) -> dict[str, Any]:
    """Read and check a pipeline TOML: known tables only, known keys per stage."""
    try:
        spec = tomllib.loads(Path(path).read_text())
    except FileNotFoundError:
        raise InputError(path, None, "file not found") from None
    except tomllib.TOMLDecodeError as exc:
        raise InputError(path, None, f"not valid TOML ({exc})") from None
    for table, params in spec.items():
        if table == "pipeline":
            continue
        if table not in STAGES:
            raise InputError(path, f"[{table}]", "unknown stage", f"one of pipeline, {', '.join(STAGES)}")
        stage = STAGES[table]
        unknown = sorted(set(params) - stage.keys) if stage.run else []
        if unknown:
            raise InputError(path, f"[{table}]", f"unknown key(s) {', '.join(unknown)}", ", ".join(sorted(stage.keys)))
    return spec


def run_pipeline(
    path: Path,
    progress: bool = True,
    nthread: int | None = None,
    echo: Callable[[str], None] = print,
    ray: RayOptions | None = None,
) -> Context:
    """Run every stage named in the pipeline file, in registry order; returns the context with the summary.

    ``ray``: run the train/evaluate jobs as Ray tasks (:mod:`wristmimic.distributed`); None: here, in order."""
    spec = load_spec(path)
    meta = spec.get("pipeline", {})
    executor = None
    if ray is not None:
        from wristmimic.distributed import RayExecutor

        executor = RayExecutor(ray.resolved(meta, nthread, Path(path)))
    work_dir = Path(meta.get("work_dir", Path("runs") / "pipelines" / meta.get("name", Path(path).stem)))
    work_dir.mkdir(parents=True, exist_ok=True)
    state_file = work_dir / STATE_FILE
    state = _read_state(state_file)
    ctx = Context(Path(path), work_dir, progress, nthread, echo=echo, state=state, spec=spec, executor=executor)
    for name, stage in STAGES.items():
        if name not in spec:
            continue
        if stage.run is None:
            ctx.note(name, "not available yet")
            echo(f"  ({stage.note}; skipped)")
            continue
        stage.run(ctx, spec[name])
    return ctx
