"""What evaluation needs from a policy, and the loader of trained runs behind one function.

:class:`EvalPolicy` is the small interface the trial runner programs against; :func:`load_eval_policy` wraps
``wristmimic.rl.load_policy`` (a run folder or ``checkpoint.pt``) into it. Tests build stand-in policies.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Protocol

import torch

from wristmimic.errors import InputError
from wristmimic.safe_io import first_sentence, sha256_file

POLICY_ROW_BLOCK = 64
"""Policy batches are padded to a multiple of this many rows. MKL's matrix product gives a row bits that depend
on the batch size and the row's position for small or ragged batches (measured: batches below 4 and the tail
rows of odd sizes differ by ~1e-7); with whole blocks of 64 rows each row's actions depend only on its own
observation, so a trial replays bit for bit in any world of any batch."""


class EvalPolicy(Protocol):
    """A policy as evaluation sees it."""

    metadata: dict[str, Any]
    """``scene``, ``variant``, ``dataset`` (path), ``dataset_sha256``, ``env`` (EnvConfig as a dict),
    ``scene_config``, ``ref_frames``, plus anything describing where it came from."""

    def act(self, obs: torch.Tensor, deterministic: bool = True) -> torch.Tensor:
        """(N, O) raw observations -> (N, A) mean actions (evaluation adds its own seeded noise)."""
        ...

    @property
    def sigma(self) -> torch.Tensor:
        """(A,) standard deviation of the policy's Gaussian."""
        ...


def act_rows(policy: EvalPolicy, obs: torch.Tensor) -> torch.Tensor:
    """Mean actions with the batch padded to whole :data:`POLICY_ROW_BLOCK` blocks (row-independent bits)."""
    n = obs.shape[0]
    pad = -n % POLICY_ROW_BLOCK
    if pad:
        obs = torch.cat([obs, obs.new_zeros(pad, obs.shape[1])])
    with torch.no_grad():
        return policy.act(obs, deterministic=True)[:n]


class RunPolicy:
    """A trained run's policy (``wristmimic.rl.Policy``) behind :class:`EvalPolicy`."""

    def __init__(self, policy: Any, metadata: dict[str, Any]):
        self.policy = policy
        self.metadata = metadata

    def act(self, obs: torch.Tensor, deterministic: bool = True) -> torch.Tensor:
        return self.policy.act(obs, deterministic=True)

    def to(self, device: torch.device | str) -> RunPolicy:
        """Move the network (and its normaliser) to ``device``, where the environment's observations are."""
        self.policy.to(device)
        return self

    @property
    def sigma(self) -> torch.Tensor:
        return self.policy.sigma.to(torch.float32)


def load_eval_policy(run_dir_or_checkpoint: str | Path, weights: str = "deployed") -> RunPolicy:
    """The policy of a training run folder or checkpoint file, with the run's config as metadata; ``weights``:
    ``deployed`` (what the run deploys) or ``latest`` (the last update's)."""
    from wristmimic.rl import load_policy
    from wristmimic.rl.checkpoint import checkpoint_path

    path = Path(run_dir_or_checkpoint)
    ckpt = checkpoint_path(path)
    try:
        p = load_policy(path, weights)  # load_checkpoint has checked the entries; this catches weights that do not fit
    except (KeyError, TypeError, ValueError, RuntimeError, AttributeError, IndexError) as exc:
        detail = first_sentence(str(exc), 240) or type(exc).__name__
        raise InputError(
            ckpt,
            "policy",
            f"cannot be rebuilt ({type(exc).__name__}: {detail})",
            "a checkpoint written by `wristmimic train`",
        ) from None
    cfg = p.config
    meta = {
        "scene": p.scene_id,
        "variant": p.variant,
        "dataset": cfg["dataset"]["path"],
        "dataset_sha256": p.dataset_sha256,
        "env": cfg["env"],
        "scene_config": cfg.get("scene_config"),
        "ref_frames": cfg.get("ref_frames"),
        "train_seed": p.seed,
        "iteration": p.iteration,
        "train_frames": p.frames,
        "run_dir": str(ckpt.parent.resolve()),
        "checkpoint": str(ckpt.resolve()),
        "checkpoint_sha256": sha256_file(ckpt),
        "preset": cfg.get("preset"),
        "feedforward": p.feedforward,
        "policy_weights": p.weights,
        "policy_weights_iteration": p.weights_iteration,
    }
    return RunPolicy(p, meta)
