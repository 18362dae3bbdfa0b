"""Policy networks: running observation normalisation, separate actor and critic MLPs (SiLU), fixed sigma."""

from __future__ import annotations

import math
from collections.abc import Sequence

import torch
from torch import nn

from wristmimic.threads import torch_threads


class ObsNormalizer(nn.Module):
    """Running mean / variance of observations (Chan et al. parallel update); its state is in buffers, so it is
    saved and restored with the policy's ``state_dict``. ``forward`` standardises and clips."""

    def __init__(self, size: int, clip: float = 5.0, eps: float = 1e-8):
        super().__init__()
        self.clip, self.eps = float(clip), float(eps)
        self.register_buffer("mean", torch.zeros(size, dtype=torch.float64))
        self.register_buffer("var", torch.ones(size, dtype=torch.float64))
        self.register_buffer("count", torch.zeros((), dtype=torch.float64))

    @torch.no_grad()
    def update(self, x: torch.Tensor) -> None:
        """Fold a batch ``(N, size)`` into the running statistics."""
        x = x.to(torch.float64)
        n = x.shape[0]
        b_mean, b_var = x.mean(0), x.var(0, unbiased=False)
        total = self.count + n
        delta = b_mean - self.mean
        self.mean += delta * n / total  # mean' = mean + delta n_b / n
        m2 = self.var * self.count + b_var * n + delta.square() * self.count * n / total  # combined M2
        self.var.copy_(m2 / total)
        self.count.fill_(total)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        z = (x.to(torch.float64) - self.mean) / torch.sqrt(self.var + self.eps)
        return z.clamp(-self.clip, self.clip).to(torch.float32)


def mlp(in_size: int, hidden: Sequence[int], out_size: int, out_gain: float) -> nn.Sequential:
    """Linear + SiLU layers; orthogonal init (gain sqrt 2), last layer gain ``out_gain``, zero biases."""
    sizes = [in_size, *hidden]
    layers: list[nn.Module] = []
    for a, b in zip(sizes[:-1], sizes[1:], strict=True):
        layers += [_init(nn.Linear(a, b), math.sqrt(2.0)), nn.SiLU()]
    layers.append(_init(nn.Linear(sizes[-1], out_size), out_gain))
    return nn.Sequential(*layers)


def _init(layer: nn.Linear, gain: float) -> nn.Linear:
    with torch_threads(1):  # LAPACK's QR rounds differently on more threads: the same seed, the same weights
        nn.init.orthogonal_(layer.weight, gain)
    nn.init.zeros_(layer.bias)
    return layer


class ActorCritic(nn.Module):
    """Gaussian policy pi(a | s) = N(actor(s), sigma^2), sigma fixed or learned (state-independent), and a
    separate critic V(s).

    Both networks read normalised observations; :attr:`normalizer` does that and is updated by the runner.
    """

    def __init__(
        self,
        obs_size: int,
        action_size: int,
        actor_hidden: Sequence[int],
        critic_hidden: Sequence[int],
        log_std: float,
        obs_clip: float = 5.0,
        learn_std: bool = False,
        min_log_std: float = -20.0,
    ):
        super().__init__()
        self.obs_size, self.action_size = int(obs_size), int(action_size)
        self.normalizer = ObsNormalizer(obs_size, obs_clip)
        self.actor = mlp(obs_size, actor_hidden, action_size, out_gain=0.01)  # mu ~ 0 at the start
        self.critic = mlp(obs_size, critic_hidden, 1, out_gain=1.0)
        self.min_log_std = float(min_log_std)
        self.register_buffer("active", torch.ones(action_size))
        """(A,) 1 for the dimensions the policy acts on, 0 for held ones (:attr:`PPOConfig.held_actions`): their
        mean and noise are 0 (a = 0) and they add nothing to log-probabilities, entropy or KL."""
        init = torch.full((action_size,), float(log_std))
        if learn_std:  # state-independent, learned (rsl_rl); floored by min_log_std when used
            self.log_std_param = nn.Parameter(init)
        else:  # fixed (InterMimic): a buffer, not learned
            self.register_buffer("log_std_param", init)

    @property
    def log_std(self) -> torch.Tensor:
        """(A,) log sigma in use: the stored value, floored at ``min_log_std``."""
        return self.log_std_param.clamp_min(self.min_log_std)

    def _load_from_state_dict(self, state_dict, prefix, *args, **kwargs):  # type: ignore[no-untyped-def]
        upgrade_state_dict(state_dict, self.active.numel(), prefix)
        super()._load_from_state_dict(state_dict, prefix, *args, **kwargs)

    def mean(self, obs_n: torch.Tensor) -> torch.Tensor:
        """mu(s) of normalised observations ``(N, O)`` -> ``(N, A)``, 0 on held dimensions."""
        return self.actor(obs_n) * self.active

    def entropy(self) -> torch.Tensor:
        """Entropy of the Gaussian per sample (sum over the active action dimensions)."""
        return ((self.log_std + 0.5 * math.log(2 * math.pi * math.e)) * self.active).sum()

    def value(self, obs_n: torch.Tensor) -> torch.Tensor:
        """V(s) of normalised observations ``(N, O)`` -> ``(N,)``."""
        return self.critic(obs_n).squeeze(-1)

    def log_prob(self, mu: torch.Tensor, actions: torch.Tensor) -> torch.Tensor:
        """log N(a; mu, sigma^2) summed over the active action dimensions -> ``(N,)``."""
        z = (actions - mu) * torch.exp(-self.log_std)
        return ((-0.5 * z.square() - self.log_std - 0.5 * math.log(2 * math.pi)) * self.active).sum(-1)

    @torch.no_grad()
    def act(
        self, obs_n: torch.Tensor, generator: torch.Generator | None = None, noise: torch.Tensor | None = None
    ) -> tuple[torch.Tensor, ...]:
        """Sample actions for normalised observations: ``(actions, log_probs, mu, values)``; ``noise`` (N, A),
        standard normal per step (e.g. temporally correlated), replaces fresh draws from ``generator``."""
        mu = self.mean(obs_n)
        if noise is None:
            noise = torch.randn(mu.shape, generator=generator, device=mu.device)
        actions = mu + torch.exp(self.log_std) * self.active * noise
        return actions, self.log_prob(mu, actions), mu, self.value(obs_n)


def upgrade_state_dict(state: dict[str, torch.Tensor], action_size: int, prefix: str = "") -> dict[str, torch.Tensor]:
    """Bring an :class:`ActorCritic` state dict saved by an earlier version to today's names, in place: the
    fixed sigma's buffer ``log_std`` (before the learned sigma) becomes ``log_std_param``, and a missing ``active``
    mask (before held dimensions) is all ones. Returns ``state``."""
    if prefix + "log_std" in state:
        state[prefix + "log_std_param"] = state.pop(prefix + "log_std")
    if prefix + "active" not in state:
        state[prefix + "active"] = torch.ones(action_size)
    return state
