"""Record what ``wristmimic view`` is pointed at: a canonical file's sequence, or a trained run's policy.

A trained run (a run folder or its ``checkpoint.pt``) is loaded with ``wristmimic.evaluate.load_eval_policy``
(which wraps :func:`wristmimic.rl.load_policy`); the run's config says which dataset, scene, variant and
reference frames it was trained on, and the rollout runs in a one-world environment built as evaluation
builds it (reset at frame 0, no truncation before the end of the reference).

Sampled-action trials: ``trial_seed`` is a trial's ``seed`` in an evaluation's per-trial table; the actions are
the policy mean plus ``sigma * normal(seed, step, index)`` from ``wristmimic.evaluate.noise``, so the recording
replays that trial (noise mode ``actions``; initial-state trials are not replayed).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from wristmimic.errors import InputError
from wristmimic.view.record import RecordingSummary, record_reference, record_rollout
from wristmimic.view.rollout import env_for_policy, evaluation_actor, run_dataset


@dataclass(frozen=True)
class RunViewOptions:
    """How to record a trained run."""

    reference_only: bool = False
    """Record the run's reference (its dataset and scene) without running the policy."""
    trial_seed: int | None = None
    """Replay the sampled-action trial with this seed (an evaluation table's ``seed``); None: mean actions."""
    start_frame: int = 0
    """Reference frame the rollout starts from."""
    hulls: bool = False
    """Add the objects' collision hulls (hidden in the default layout)."""
    dataset: Path | None = None
    """The run's dataset when it moved since training (must be the same file)."""
    nthread: int = 1
    """Physics threads."""


def record_run(run_dir_or_checkpoint: str | Path, out: str | Path, options: RunViewOptions) -> RecordingSummary:
    """One rollout of a trained policy from ``options.start_frame``, recorded beside its reference."""
    from wristmimic.env.config import env_config_from_dict
    from wristmimic.evaluate.policy import load_eval_policy

    policy = load_eval_policy(run_dir_or_checkpoint)
    meta = policy.metadata
    if options.reference_only:
        window = env_config_from_dict(meta["env"]).window
        path = run_dataset(meta, options.dataset)
        return record_reference(
            path, meta["scene"], out, hulls=options.hulls, window=window, max_frames=meta.get("ref_frames")
        )
    env = env_for_policy(policy, options.dataset, options.nthread)
    try:
        env.reset()  # the observation size is known after the first observation
        net = policy.policy.net
        if env.observation_size != net.obs_size or env.action_size != net.action_size:
            raise InputError(
                run_dir_or_checkpoint,
                "policy",
                f"observations/actions {net.obs_size}/{net.action_size}",
                f"{env.observation_size}/{env.action_size} (the scene's); was the dataset converted again?",
            )
        seed = options.trial_seed
        info = {
            "run": str(meta.get("run_dir", run_dir_or_checkpoint)),
            "variant": str(meta["variant"]),
            "training seed": str(meta.get("train_seed")),
            "trained": f"{meta.get('iteration')} iterations, {meta.get('train_frames', 0):,} frames",
            "actions": "policy mean" if seed is None else f"mean + sigma * noise of trial seed {seed}",
        }
        actor = evaluation_actor(policy, seed)
        return record_rollout(env, actor, out, start_frame=options.start_frame, hulls=options.hulls, info=info)
    finally:
        env.close()


def source_kind(source: str | Path) -> str:
    """``dataset`` for an HDF5 file, ``run`` for a folder or any other file (a checkpoint)."""
    import h5py

    p = Path(source)
    if not p.exists():
        raise InputError(p, None, "not found", "a canonical .h5 file, a run folder or a checkpoint.pt")
    if p.is_file() and h5py.is_hdf5(p):
        return "dataset"
    return "run"
