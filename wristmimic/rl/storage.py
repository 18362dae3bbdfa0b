"""Rollout storage: preallocated ``(horizon, num_envs, ...)`` tensors filled one environment step at a time."""

from __future__ import annotations

from collections.abc import Iterator

import torch


class RolloutStorage:
    """One rollout of ``horizon`` steps of ``num_envs`` worlds.

    Attributes (H = horizon, N = num_envs, O = observation size, A = action size; float32 unless stated):
        observations: (H, N, O) normalised observations, exactly as the policy saw them when it acted.
        actions:      (H, N, A) sampled actions (before the environment clips them to [-1, 1]).
        rewards:      (H, N) rewards r_t in [0, 1].
        terminated:   (H, N) 1.0 where the episode ended early (fall, tracking error, ...): no bootstrap.
        time_outs:    (H, N) 1.0 where the episode was truncated (sequence end, episode cap): bootstrap.
        values:       (H, N) critic values V(s_t) at collection time.
        log_probs:    (H, N) log pi_old(a_t | s_t) at collection time.
        mu:           (H, N, A) action means at collection time.
        advantages:   (H, N) GAE advantages A_t, filled by :meth:`set_returns`.
        returns:      (H, N) value targets R_t = A_t + V(s_t), filled by :meth:`set_returns`.
        step:         int, the next row to write (0 .. H); H means full.
    """

    def __init__(
        self, horizon: int, num_envs: int, obs_size: int, action_size: int, device: torch.device | str = "cpu"
    ):
        self.horizon, self.num_envs = int(horizon), int(num_envs)
        H, N = self.horizon, self.num_envs

        def z(*shape: int) -> torch.Tensor:
            return torch.zeros(*shape, device=device)

        self.observations = z(H, N, obs_size)
        self.actions = z(H, N, action_size)
        self.rewards = z(H, N)
        self.terminated = z(H, N)
        self.time_outs = z(H, N)
        self.values = z(H, N)
        self.log_probs = z(H, N)
        self.mu = z(H, N, action_size)
        self.advantages = z(H, N)
        self.returns = z(H, N)
        self.step = 0

    def add(
        self,
        obs: torch.Tensor,
        actions: torch.Tensor,
        log_probs: torch.Tensor,
        mu: torch.Tensor,
        values: torch.Tensor,
        rewards: torch.Tensor,
        terminated: torch.Tensor,
        time_outs: torch.Tensor,
    ) -> None:
        """Write one step of every world (all tensors have leading dimension N)."""
        if self.step >= self.horizon:
            raise RuntimeError("rollout storage is full: call clear() after the update")
        t = self.step
        self.observations[t] = obs
        self.actions[t] = actions
        self.log_probs[t] = log_probs
        self.mu[t] = mu
        self.values[t] = values
        self.rewards[t] = rewards
        self.terminated[t] = terminated.float()
        self.time_outs[t] = time_outs.float()
        self.step += 1

    def set_returns(self, advantages: torch.Tensor, returns: torch.Tensor) -> None:
        self.advantages[:] = advantages
        self.returns[:] = returns

    def clear(self) -> None:
        self.step = 0

    def minibatches(self, minibatch_size: int, epochs: int, generator: torch.Generator) -> Iterator[dict]:
        """``epochs`` passes over the flattened rollout in shuffled minibatches of ``minibatch_size`` samples."""
        flat = {
            "observations": self.observations.flatten(0, 1),
            "actions": self.actions.flatten(0, 1),
            "log_probs": self.log_probs.flatten(0, 1),
            "mu": self.mu.flatten(0, 1),
            "values": self.values.flatten(0, 1),
            "advantages": self.advantages.flatten(0, 1),
            "returns": self.returns.flatten(0, 1),
        }
        n = self.horizon * self.num_envs
        for _ in range(epochs):
            order = torch.randperm(n, generator=generator, device=generator.device)
            for start in range(0, n, minibatch_size):
                idx = order[start : start + minibatch_size]
                yield {k: v[idx] for k, v in flat.items()}
