"""PPO: generalised advantage estimation and the clipped-surrogate update (CleanRL's order, rsl_rl's split)."""

from __future__ import annotations

import torch
from torch import nn

from wristmimic.rl.config import PPOConfig
from wristmimic.rl.networks import ActorCritic
from wristmimic.rl.storage import RolloutStorage


def compute_gae(
    rewards: torch.Tensor,
    values: torch.Tensor,
    terminated: torch.Tensor,
    time_outs: torch.Tensor,
    last_values: torch.Tensor,
    gamma: float,
    lam: float,
) -> tuple[torch.Tensor, torch.Tensor]:
    """Advantages and returns of one rollout; all ``(H, N)`` except ``last_values`` ``(N,)`` = V(s_H).

    Auto-reset replaces the last observation of an ended episode, so on a time-out the value of the state
    before the last step stands in for the lost final state (rsl_rl's approximation); terminations get none.
    """
    H = rewards.shape[0]
    rewards = rewards + gamma * values * time_outs  # r~_t = r_t + gamma V(s_t) on time-outs, else r_t
    not_done = 1.0 - torch.maximum(terminated, time_outs)  # (1 - d_t): the episode continues into s_{t+1}
    advantages = torch.zeros_like(rewards)
    gae = torch.zeros_like(last_values)  # A_H = 0
    for t in reversed(range(H)):
        next_values = last_values if t == H - 1 else values[t + 1]  # V(s_{t+1})
        delta = rewards[t] + gamma * next_values * not_done[t] - values[t]  # d_t = r~_t + g V(s_t+1)(1-d_t) - V(s_t)
        gae = delta + gamma * lam * not_done[t] * gae  # A_t = d_t + gamma lambda (1 - d_t) A_{t+1}
        advantages[t] = gae
    returns = advantages + values  # R_t = A_t + V(s_t)
    return advantages, returns


def bounds_loss(mu: torch.Tensor, bound: float) -> torch.Tensor:
    """Soft action bound: mean over samples of sum_i max(|mu_i| - bound, 0)^2."""
    return (mu.abs() - bound).clamp_min(0.0).square().sum(-1).mean()


class PPO:
    """Owns the policy's optimiser; :meth:`update` runs the epochs x minibatches of one rollout."""

    def __init__(self, policy: ActorCritic, cfg: PPOConfig):
        self.policy, self.cfg = policy, cfg
        actor = [*policy.actor.parameters()]
        log_std = [policy.log_std_param] if isinstance(policy.log_std_param, nn.Parameter) else []
        if cfg.log_std_learning_rate is None:
            actor, log_std = actor + log_std, []
        critic = [*policy.critic.parameters()]
        if cfg.critic_learning_rate is None:
            groups = [{"params": actor + critic}]
        else:  # the critic keeps its own fixed rate; the schedule moves the actor's group only
            groups = [{"params": actor}, {"params": critic, "lr": cfg.critic_learning_rate}]
        if log_std:  # a fixed rate of its own, outside the schedule
            groups.append({"params": log_std, "lr": cfg.log_std_learning_rate})
        # fused: one kernel over all parameters (on 2 CPU threads 4x faster than the per-tensor loop for the CPU
        # preset's 2.1 M parameters); needs float32 parameters on a CPU or CUDA device
        every = actor + critic + log_std
        fused = all(p.dtype == torch.float32 and p.device.type in ("cpu", "cuda") for p in every)
        self.optimizer = torch.optim.Adam(groups, lr=cfg.learning_rate, fused=fused or None)

    @property
    def learning_rate(self) -> float:
        return float(self.optimizer.param_groups[0]["lr"])

    def _adapt_learning_rate(self, kl: float) -> None:
        """rsl_rl's adaptive schedule: lr / 1.5 above 2 x desired KL, x 1.5 below half of it, clamped."""
        c, lr = self.cfg, self.learning_rate
        if kl > 2.0 * c.desired_kl:
            lr = max(c.lr_min, lr / 1.5)
        elif kl < 0.5 * c.desired_kl:
            lr = min(c.lr_max, lr * 1.5)
        self.optimizer.param_groups[0]["lr"] = lr  # the actor's group (and the critic's, when it shares the rate)

    @torch.no_grad()
    def update_kl(self, storage: RolloutStorage, log_std_old: torch.Tensor) -> float:
        """Mean over the rollout's states of the closed-form KL(old || new) between the Gaussian policy that
        collected it (the stored means, sigma ``exp(log_std_old)``) and the updated one (rsl_rl's formula)."""
        pi = self.policy
        mu_old = storage.mu.flatten(0, 1)
        mu = pi.mean(storage.observations.flatten(0, 1))
        log_std = pi.log_std
        var, var_old = torch.exp(2.0 * log_std), torch.exp(2.0 * log_std_old)
        kl = ((log_std - log_std_old + (var_old + (mu_old - mu).square()) / (2.0 * var) - 0.5) * pi.active).sum(-1)
        return float(kl.double().mean())

    def compute_returns(self, storage: RolloutStorage, last_values: torch.Tensor) -> None:
        adv, ret = compute_gae(
            storage.rewards,
            storage.values,
            storage.terminated,
            storage.time_outs,
            last_values,
            self.cfg.gamma,
            self.cfg.lam,
        )
        storage.set_returns(adv, ret)

    def update(self, storage: RolloutStorage, generator: torch.Generator) -> dict[str, float]:
        """Minibatch epochs over the rollout; returns mean losses and diagnostics under ``loss/...``."""
        c, pi = self.cfg, self.policy
        sums: dict[str, torch.Tensor] = {}
        n = 0
        log_std_old = pi.log_std.detach().clone()
        for mb in storage.minibatches(c.minibatch_size, c.epochs, generator):
            adv = mb["advantages"]
            if c.normalize_advantage:
                adv = (adv - adv.mean()) / (adv.std() + 1e-8)
            mu = pi.mean(mb["observations"])
            log_ratio = pi.log_prob(mu, mb["actions"]) - mb["log_probs"]
            ratio = log_ratio.exp()
            kl = ((ratio - 1) - log_ratio).mean()  # k3 estimator of KL(old || new)
            if c.schedule == "adaptive":  # one host sync per minibatch: the step size depends on it
                self._adapt_learning_rate(float(kl.detach()))
            policy_loss = torch.max(-adv * ratio, -adv * ratio.clamp(1 - c.clip, 1 + c.clip)).mean()
            v = pi.value(mb["observations"])
            value_loss = 0.5 * (v - mb["returns"]).square()
            if c.clip_value_loss:
                v_clipped = mb["values"] + (v - mb["values"]).clamp(-c.clip, c.clip)
                value_loss = torch.max(value_loss, 0.5 * (v_clipped - mb["returns"]).square())
            value_loss = value_loss.mean()
            b_loss = bounds_loss(mu, c.action_bound)
            entropy = pi.entropy()
            loss = policy_loss + c.value_coef * value_loss + c.bounds_loss_coef * b_loss - c.entropy_coef * entropy
            self.optimizer.zero_grad()
            loss.backward()
            actor_norm = nn.utils.clip_grad_norm_(pi.actor.parameters(), c.max_grad_norm)
            critic_norm = nn.utils.clip_grad_norm_(pi.critic.parameters(), c.max_grad_norm)
            self.optimizer.step()
            with torch.no_grad():
                stats = {
                    "loss/policy": policy_loss,
                    "loss/value": value_loss,
                    "loss/bounds": b_loss,
                    "loss/total": loss,
                    "loss/approx_kl": kl,
                    "loss/clip_fraction": ((ratio - 1).abs() > c.clip).float().mean(),
                    "loss/grad_norm_actor": actor_norm,
                    "loss/grad_norm_critic": critic_norm,
                }
            for k, v in stats.items():
                sums[k] = sums[k] + v.detach() if k in sums else v.detach()
            n += 1
        values = torch.stack([v.double() for v in sums.values()]).cpu().tolist()  # one host sync per update
        out = {k: v / n for k, v in zip(sums, values, strict=True)}
        out["loss/kl_update"] = self.update_kl(storage, log_std_old)
        out["loss/learning_rate"] = self.learning_rate
        if c.schedule == "adaptive_update":  # the next update's rate, from this one's KL
            self._adapt_learning_rate(out["loss/approx_kl" if c.kl_source == "approx" else "loss/kl_update"])
        out["loss/sigma"] = float(torch.exp(pi.log_std.detach()).mean())
        return out
