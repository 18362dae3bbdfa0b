"""Start or resume a training run of one scene: run folder, ``config.json``, environment, :class:`Runner`.

A run folder holds ``config.json`` (everything that defines the run), ``metrics.csv`` and ``checkpoint.pt``.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import wristmimic
from wristmimic.env.config import VARIANTS, EnvConfig, env_config_from_dict
from wristmimic.env.vec_env import WristMimicEnv
from wristmimic.errors import InputError
from wristmimic.format.reader import open_dataset
from wristmimic.format.validate import check_sequence
from wristmimic.rl.checkpoint import (
    CHECKPOINT_NAME,
    INIT_NAME,
    RUN_FILES,
    checkpoint_path,
    load_checkpoint,
    remove_stale_temporaries,
)
from wristmimic.rl.config import PPOConfig, dumps, from_jsonable, preset, preset_env, to_jsonable
from wristmimic.rl.runner import Runner, TrainingError
from wristmimic.safe_io import OutputError, atomic_output, sha256_file
from wristmimic.scene import SceneConfig, scene_config_from_dict
from wristmimic.sim.backend import BACKENDS


@dataclass
class TrainSpec:
    """What defines a run (written to ``config.json``)."""

    dataset: Path
    """Canonical HDF5 file."""
    scene: str
    """Sequence id to imitate."""
    variant: str = "wristmimic"
    """Environment variant (``wristmimic.env.config.VARIANTS``)."""
    seed: int = 0
    """Seeds the networks, action noise, minibatch order and the environment's start frames."""
    preset: str = "cpu"
    """Name of the PPO preset the config started from."""
    ppo: PPOConfig = field(default_factory=lambda: preset("cpu"))
    env: EnvConfig | None = None
    """Environment config; None: the variant's under the preset (:func:`wristmimic.rl.config.preset_env`)."""
    scene_config: SceneConfig = field(default_factory=SceneConfig)
    ref_frames: int | None = None
    """Keep only the first frames of the reference (a short task); None: the whole sequence."""
    backend: str = "cpu"
    """Physics backend: ``cpu`` (MuJoCo threads) or ``warp`` (MuJoCo Warp; policy and math on its device)."""
    device: str | None = None
    """Warp device (``cuda``, ``cuda:1``, ``cpu``); None: a GPU if there is one."""
    overrides: tuple[str, ...] = ()
    """``--set`` strings already applied to ``env``, ``ppo`` and ``scene_config`` (recorded in ``config.json``)."""
    init_from: Path | None = None
    """Start from the policy of this run folder or checkpoint (a warm start, e.g. from a body-only stage) instead
    of fresh networks; ``config.json`` records its path, sha256, weights and frames."""
    init_weights: str = "deployed"
    """Which of its weights: ``deployed`` (what ``wristmimic evaluate`` loads) or ``latest`` (the last update's)."""
    init_normalizer: str = "reset"
    """The observation statistics of a warm start: ``reset`` (re-estimated from this run's observations: the source
    scene placed objects elsewhere, e.g. a body-only copy parks them 20 m away) or ``source`` (kept and updated on:
    the same scene with other starts or terms, whose first batches would otherwise set statistics the policy never
    saw)."""


@dataclass
class TrainResult:
    run_dir: Path
    status: str
    """``finished``, ``interrupted`` or ``up to date`` (nothing left to train)."""
    iteration: int
    frames: int


def default_run_dir(out: Path, scene: str, variant: str, seed: int) -> Path:
    """``OUT/<scene>-<variant>-seed<seed>-<YYYYmmdd-HHMMSS>``."""
    return Path(out) / f"{scene}-{variant}-seed{seed}-{time.strftime('%Y%m%d-%H%M%S')}"


def git_commit(start: Path | None = None) -> str | None:
    """The checked-out commit, read from ``.git`` files (no git process); None outside a checkout."""
    here = (start or Path(wristmimic.__file__)).resolve()
    for d in [here, *here.parents]:
        head = d / ".git" / "HEAD"
        if head.is_file():
            ref = head.read_text().strip()
            if not ref.startswith("ref: "):
                return ref
            name = ref[5:]
            loose = d / ".git" / name
            if loose.is_file():
                return loose.read_text().strip()
            packed = d / ".git" / "packed-refs"
            for line in packed.read_text().splitlines() if packed.is_file() else []:
                if line.endswith(" " + name):
                    return line.split()[0]
            return None
    return None


def _config_dict(spec: TrainSpec, env_cfg: EnvConfig, sha: str, init: dict[str, Any] | None = None) -> dict[str, Any]:
    return {
        "dataset": {"path": str(Path(spec.dataset).resolve()), "sha256": sha},
        "scene": spec.scene,
        "variant": spec.variant,
        "seed": spec.seed,
        "preset": spec.preset,
        "ref_frames": spec.ref_frames,
        "ppo": to_jsonable(spec.ppo),
        "env": to_jsonable(env_cfg),
        "scene_config": to_jsonable(spec.scene_config),
        "physics": {"backend": spec.backend, "device": spec.device},
        "overrides": list(spec.overrides),
        "init": init,
        "code": {"version": wristmimic.__version__, "git_commit": git_commit()},
        "created": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
    }


def _build(config: dict[str, Any], run_dir: Path, nthread: int | None, dataset_file: Path | None = None) -> Runner:
    ppo = from_jsonable(PPOConfig, config["ppo"])
    env_cfg = env_config_from_dict(config["env"])
    scene_cfg = scene_config_from_dict(config["scene_config"])
    # the training scene alone carries the virtual object controller's motors (config.json records the user's)
    scene_cfg = replace(
        scene_cfg,
        object_actuators=env_cfg.object_controller.enabled,
        root_actuators=env_cfg.root_assist.enabled,
        hand_adhesion=env_cfg.hand_adhesion.enabled,
    )
    physics = config.get("physics") or {"backend": "cpu"}  # runs from before backends existed: CPU
    options = {"device": physics["device"]} if physics["backend"] == "warp" and physics.get("device") else None
    env = WristMimicEnv.from_file(
        dataset_file or config["dataset"]["path"],
        config["scene"],
        num_worlds=ppo.num_envs,
        config=env_cfg,
        scene_config=scene_cfg,
        seed=config["seed"],
        nthread=nthread,
        max_frames=config["ref_frames"],
        backend=physics["backend"],
        backend_options=options,
    )
    meta = {
        "scene": config["scene"],
        "variant": config["variant"],
        "dataset_sha256": config["dataset"]["sha256"],
        "seed": config["seed"],
    }
    return Runner(
        env, ppo, config["seed"], run_dir, dumps(config), meta, Path(dataset_file or config["dataset"]["path"])
    )


def _check_scene(dataset: Path, scene: str) -> None:
    with open_dataset(dataset) as ds:
        check_sequence(ds, scene)  # InputError naming the known ids, or the first problem of the scene's data


def start_run(
    spec: TrainSpec,
    run_dir: Path,
    nthread: int | None = None,
    progress: bool = True,
    dataset_file: Path | None = None,
    should_stop: Callable[[], bool] | None = None,
) -> TrainResult:
    """Create ``run_dir`` (must not hold a checkpoint yet), write ``config.json`` and train to
    ``spec.ppo.max_frames`` (or until ``should_stop()`` turns true after an iteration: status ``interrupted``,
    checkpoint saved).

    Nothing is written before the environment is built. A failure (or Ctrl-C twice) before the first checkpoint
    removes what was written, and the folders created; after it, the folder keeps the last good checkpoint and
    ``metrics.csv`` up to it (see :meth:`Runner.learn`). A folder with ``config.json`` but no checkpoint (a start
    killed in its first iteration) is started afresh.

    ``dataset_file``: read the data from this copy of ``spec.dataset`` (e.g. a Ray worker's local copy);
    ``config.json`` still records ``spec.dataset`` and the sha256 of the bytes read."""
    run_dir = Path(run_dir)
    data = Path(dataset_file or spec.dataset)
    _check_budget("ppo.max_frames", spec.ppo.max_frames)
    if (run_dir / CHECKPOINT_NAME).exists():
        raise InputError(run_dir, None, "already holds a run", "a new folder (or use --resume)")
    _check_scene(data, spec.scene)
    if spec.variant not in VARIANTS:
        raise InputError(None, "variant", f"unknown variant {spec.variant!r}", f"one of {', '.join(VARIANTS)}")
    if spec.backend not in BACKENDS:
        raise InputError(None, "backend", f"unknown backend {spec.backend!r}", f"one of {', '.join(BACKENDS)}")
    spec = _for_backend(spec)
    env_cfg = spec.env or preset_env(spec.preset, spec.variant)
    blob = _read_init(spec)
    source = _init_source(spec, blob)
    config = _config_dict(spec, env_cfg, sha256_file(data), None if source is None else source[2])
    runner = _build(config, run_dir, nthread, data)  # before the folder exists: a scene that fails leaves none
    # the physics and update threads: the update's float reductions can depend on them (last bits, on some CPUs),
    # so a run repeats bit for bit with the same commit, seed and thread count
    config["nthread"] = getattr(runner.env.backend, "nthread", None)
    if source is not None:
        path, entry, _, weights = source
        try:
            runner.warm_start(path, entry, weights, reset_normalizer=spec.init_normalizer == "reset")
        except BaseException:
            runner.env.close()
            raise
    made = [d for d in (run_dir, *run_dir.parents) if not d.exists()]
    try:
        _write_config(run_dir, config)
        if blob is not None:
            _keep_init_copy(blob, source[0], run_dir)
        runner.optimise_feedforward(progress)
        status = runner.learn(spec.ppo.max_frames, progress, should_stop)
    except BaseException as exc:
        if runner.saved_iteration is None:  # nothing trained was saved: leave nothing behind
            kept = _remove_unsaved_run(run_dir, made)
            if isinstance(exc, TrainingError):
                raise TrainingError(run_dir, exc.iteration, exc.problem, None, f"no checkpoint yet: {kept}") from None
        raise
    finally:
        runner.env.close()
    return TrainResult(run_dir, status, runner.iteration, runner.frames)


def _for_backend(spec: TrainSpec) -> TrainSpec:
    """MuJoCo Warp has no PGS solver: a ``warp`` run of a PGS scene uses Newton with 100 iterations (MuJoCo's
    defaults); ``config.json`` records what ran."""
    sc = spec.scene_config
    if spec.backend == "warp" and sc.solver == "pgs":
        return replace(spec, scene_config=replace(sc, solver="newton", iterations=100))
    return spec


INIT_WEIGHTS = ("deployed", "latest")
INIT_NORMALIZER = ("reset", "source")


def _read_init(spec: TrainSpec) -> bytes | None:
    """The ``--init-from`` checkpoint's bytes, read once (None without a warm start): the hash, the weights and the
    run's kept copy (:data:`INIT_NAME`) all come from them, even while the source run trains on and replaces its
    checkpoint."""
    if spec.init_from is None:
        return None
    path = checkpoint_path(spec.init_from)
    try:
        return path.read_bytes()
    except OSError as exc:
        raise InputError(path, None, f"cannot be read ({exc.strerror})") from None


def _keep_init_copy(blob: bytes, source: Path, run_dir: Path) -> None:
    """Write the warm start's checkpoint bytes into the new run folder (atomically) as :data:`INIT_NAME`."""
    try:
        with atomic_output(run_dir / INIT_NAME, suffix=".pt") as tmp:
            tmp.write_bytes(blob)
    except (OSError, OutputError) as exc:  # a full disk: OutputError from atomic_output
        reason = exc.reason if isinstance(exc, OutputError) else exc.strerror
        raise InputError(run_dir / INIT_NAME, None, f"copy of {source} not written ({reason})") from None


def _init_source(spec: TrainSpec, blob: bytes | None = None) -> tuple[Path, str, dict[str, Any], dict[str, Any]] | None:
    """The warm start's checkpoint path, weights entry, ``config.json`` record and weights; None: no warm start.
    ``blob``: the checkpoint's bytes as :func:`_read_init` read them (None: read the file here)."""
    if spec.init_from is None:
        return None
    if spec.init_weights not in INIT_WEIGHTS:
        raise InputError(None, "init_weights", f"unknown weights {spec.init_weights!r}", " or ".join(INIT_WEIGHTS))
    if spec.init_normalizer not in INIT_NORMALIZER:
        raise InputError(
            None, "init_normalizer", f"unknown choice {spec.init_normalizer!r}", " or ".join(INIT_NORMALIZER)
        )
    path = checkpoint_path(spec.init_from)
    state = load_checkpoint(path, blob)
    entry = "deploy_policy" if spec.init_weights == "deployed" and "deploy_policy" in state else "policy"
    source = json.loads(state["config"])
    record = {
        "path": str(path.resolve()),
        "sha256": sha256_file(path) if blob is None else hashlib.sha256(blob).hexdigest(),
        "copy": None if blob is None else INIT_NAME,
        "weights": spec.init_weights,
        "normalizer": spec.init_normalizer,
        "entry": entry,
        "scene": source.get("scene"),
        "dataset_sha256": source["dataset"]["sha256"],
        "iteration": int(state["iteration"]),
        "frames": int(state["frames"]),
    }
    return path, entry, record, state[entry]


def _check_budget(key: str, frames: int) -> None:
    if frames < 1:
        raise InputError(None, key, f"{frames} frames", "a positive training budget")


def _write_config(run_dir: Path, config: dict[str, Any]) -> None:
    """Create the run folder and write ``config.json``; files of a start that never saved a checkpoint (a run
    killed in its first iteration) are replaced."""
    try:
        run_dir.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(run_dir, None, f"cannot be created ({exc.strerror})") from None
    remove_stale_temporaries(run_dir)
    (run_dir / "metrics.csv").unlink(missing_ok=True)
    try:
        with atomic_output(run_dir / "config.json") as tmp:
            tmp.write_text(dumps(config) + "\n")
    except OSError as exc:
        raise InputError(run_dir / "config.json", None, f"not written ({exc.strerror})") from None


def _remove_unsaved_run(run_dir: Path, made: list[Path]) -> str:
    """Delete what a start wrote before its first checkpoint (and the folders it created); says what is left."""
    with contextlib.suppress(OSError):
        for name in RUN_FILES:
            (run_dir / name).unlink(missing_ok=True)
        remove_stale_temporaries(run_dir)
    for d in made:  # deepest first
        with contextlib.suppress(OSError):
            d.rmdir()
    return "run folder removed" if not run_dir.exists() else "its files removed"


def resume_run(
    run_dir: Path,
    max_frames: int | None = None,
    nthread: int | None = None,
    progress: bool = True,
    dataset_file: Path | None = None,
    should_stop: Callable[[], bool] | None = None,
) -> TrainResult:
    """Continue a run from its ``checkpoint.pt`` exactly where it stopped (to ``max_frames`` if given;
    ``should_stop`` as in :func:`start_run`).

    ``dataset_file``: read the data from this copy of the recorded dataset (its sha256 must match)."""
    run_dir = Path(run_dir)
    if max_frames is not None:
        _check_budget("max_frames", max_frames)
    if (run_dir / "config.json").is_file() and not (run_dir / CHECKPOINT_NAME).exists():
        raise InputError(
            run_dir,
            None,
            "no checkpoint: the run stopped in its first iteration",
            "a run with checkpoint.pt (start it again)",
        )
    state = load_checkpoint(run_dir)
    config = json.loads(state["config"])
    dataset = Path(dataset_file or config["dataset"]["path"])
    if not dataset.is_file():
        raise InputError(dataset, None, "dataset of the run not found", "the file recorded in config.json")
    if sha256_file(dataset) != config["dataset"]["sha256"]:
        raise InputError(dataset, None, "changed since the run started (sha256 differs)", "the same file")
    _check_scene(dataset, config["scene"])
    runner = _build(config, run_dir, nthread, dataset)
    try:
        if run_dir.is_dir():
            remove_stale_temporaries(run_dir)  # left by a kill during a write
        runner.load_state_dict(state)
        budget = max_frames if max_frames is not None else config["ppo"]["max_frames"]
        status = runner.learn(budget, progress, should_stop) if runner.frames < budget else "up to date"
    finally:
        runner.env.close()
    return TrainResult(run_dir, status, runner.iteration, runner.frames)
