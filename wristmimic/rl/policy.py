"""A trained policy for evaluation: ``load_policy(run_dir_or_checkpoint).act(obs)``."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import torch

from wristmimic.errors import InputError
from wristmimic.rl.checkpoint import load_checkpoint
from wristmimic.rl.config import PPOConfig, from_jsonable
from wristmimic.rl.networks import ActorCritic


@dataclass
class Policy:
    """A finished policy with its observation normaliser inside, and where it came from.

    >>> policy = load_policy("runs/sub2_largetable_000-wristmimic-seed0-20261123-120000")
    >>> actions = policy.act(obs)  # raw observations (N, O) from WristMimicEnv -> actions (N, A)
    """

    net: ActorCritic
    scene_id: str
    variant: str
    dataset_sha256: str
    seed: int
    iteration: int
    frames: int
    config: dict
    feedforward: torch.Tensor | None = None
    """(T, D) the run's open-loop PD-target offsets (``WristMimicEnv.feedforward``), if it optimised them."""
    deploy_std: float = 0.0
    """``PPOConfig.deploy_std``: the sigma of sampled actions once deployed (0: the training sigma)."""
    weights: str = "latest"
    """Which weights ``net`` holds: ``latest`` (the last update's), ``ema`` (``PPOConfig.deploy_ema``'s average)
    or ``best`` (``PPOConfig.deploy_best``: the best periodically evaluated policy)."""
    weights_iteration: int = 0
    """The training iteration of those weights (``iteration`` for the latest or the average)."""
    weights_frames: int = 0
    """The training frames of those weights."""

    @property
    def sigma(self) -> torch.Tensor:
        """(A,) sigma of the deployed policy's sampled actions."""
        if self.deploy_std > 0.0:
            return torch.full_like(self.net.log_std.detach(), self.deploy_std)
        return torch.exp(self.net.log_std.detach())

    @property
    def observation_size(self) -> int:
        return self.net.obs_size

    @property
    def action_size(self) -> int:
        return self.net.action_size

    @torch.no_grad()
    def act(
        self, obs: torch.Tensor, deterministic: bool = True, generator: torch.Generator | None = None
    ) -> torch.Tensor:
        """Actions for raw observations: the mean, or a sample with the policy's sigma."""
        if obs.shape[-1] != self.net.obs_size:
            raise InputError(None, "obs", f"{obs.shape[-1]} features", f"{self.net.obs_size} (the training scene's)")
        mu = self.net.mean(self.net.normalizer(obs))
        if deterministic:
            return mu
        return mu + self.sigma * self.net.active * torch.randn(mu.shape, generator=generator, device=mu.device)

    def to(self, device: torch.device | str) -> Policy:
        """Move the network to ``device`` (observations must be there too)."""
        self.net.to(device)
        return self


WEIGHTS = ("deployed", "latest")
"""Which weights :func:`load_policy` loads: the ones the run deploys (``deploy_policy`` where it has one: the best
periodic evaluation's or a moving average) or the last update's."""


def load_policy(run_dir_or_checkpoint: str | Path, weights: str = "deployed") -> Policy:
    """The policy of a run folder (its ``checkpoint.pt``) or of a checkpoint file, on the CPU, in eval mode;
    ``weights``: one of :data:`WEIGHTS`."""
    if weights not in WEIGHTS:
        raise InputError(None, "weights", f"{weights!r}", f"one of {', '.join(WEIGHTS)}")
    state = load_checkpoint(run_dir_or_checkpoint)
    if weights == "latest":
        state = {k: v for k, v in state.items() if k not in ("deploy_policy", "deploy")}
    config = json.loads(state["config"])
    ppo = from_jsonable(PPOConfig, config["ppo"])
    params = state.get("deploy_policy", state["policy"])  # the deployed weights, where the run keeps its own
    std_key = "log_std_param" if "log_std_param" in params else "log_std"  # older checkpoints: 'log_std'
    obs_size, action_size = params["normalizer.mean"].shape[0], params[std_key].shape[0]
    net = ActorCritic(
        obs_size,
        action_size,
        ppo.actor_hidden,
        ppo.critic_hidden,
        ppo.log_std,
        ppo.obs_clip,
        ppo.learn_std,
        ppo.min_log_std,
    )
    net.load_state_dict(params)
    net.eval()
    meta = state["metadata"]
    deploy = state.get("deploy") or {}
    return Policy(
        net=net,
        scene_id=meta["scene"],
        variant=meta["variant"],
        dataset_sha256=meta["dataset_sha256"],
        seed=int(meta["seed"]),
        iteration=int(state["iteration"]),
        frames=int(state["frames"]),
        config=config,
        feedforward=state.get("feedforward"),
        deploy_std=ppo.deploy_std,
        weights=deploy.get("weights", "latest"),
        weights_iteration=int(deploy.get("iteration", state["iteration"])),
        weights_frames=int(deploy.get("frames", state["frames"])),
    )
