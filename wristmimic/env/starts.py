"""Start frames where rollouts fail (BeyondMimic's adaptive sampling), batched on the environment's device.

The clip is cut into bins of ``bin_frames`` frames. Every step, each bin's failure rate is an exponential moving
average (rate ``alpha``) of the terminations that happened in it. Start bins are drawn with probability
proportional to that rate smoothed toward earlier bins (a bin also gets ``kernel_lambda^k`` of the failures
``k`` bins later, so episodes start shortly before where rollouts die), mixed with a ``uniform`` share.
"""

from __future__ import annotations

import math

import torch

from wristmimic.env.config import StartSamplingConfig


class AdaptiveStarts:
    """Failure-weighted start-frame sampler over ``num_frames - 1`` possible starts."""

    def __init__(self, cfg: StartSamplingConfig, num_frames: int, device: torch.device | str = "cpu"):
        self.cfg = cfg
        self.num_starts = max(int(num_frames) - 1, 1)
        self.num_bins = math.ceil(self.num_starts / cfg.bin_frames)
        self.failures = torch.zeros(self.num_bins, dtype=torch.float32, device=device)
        """(bins,) moving average of terminations per step in each bin."""
        k = torch.arange(cfg.kernel, dtype=torch.float32, device=device)
        self._kernel = cfg.kernel_lambda**k  # weight of the failures k bins later

    def record(self, frames: torch.Tensor, terminated: torch.Tensor) -> None:
        """One step: worlds that ``terminated`` (N,) at ``frames`` (N,) count as failures of their bins."""
        bins = (frames.clamp(0, self.num_starts - 1) // self.cfg.bin_frames).clamp_max(self.num_bins - 1)
        now = torch.zeros_like(self.failures).index_add_(0, bins, terminated.to(self.failures.dtype))
        self.failures.mul_(1.0 - self.cfg.alpha).add_(self.cfg.alpha * now)

    def probabilities(self) -> torch.Tensor:
        """(bins,) start-bin probabilities: smoothed failures mixed with the uniform share."""
        padded = torch.cat([self.failures, self.failures.new_zeros(len(self._kernel) - 1)])
        smooth = padded.unfold(0, len(self._kernel), 1) @ self._kernel  # sum_k lambda^k f[b + k]
        total = smooth.sum()
        uniform = torch.full_like(smooth, 1.0 / self.num_bins)
        p = torch.where(total > 0, smooth / total.clamp_min(1e-12), uniform)
        return (1.0 - self.cfg.uniform) * p + self.cfg.uniform * uniform

    def sample(self, n: int, generator: torch.Generator) -> torch.Tensor:
        """(n,) long start frames in [0, num_frames - 2]."""
        dev = self.failures.device
        b = torch.multinomial(self.probabilities(), n, replacement=True, generator=generator)
        offset = torch.randint(0, self.cfg.bin_frames, (n,), generator=generator, device=dev)
        return (b * self.cfg.bin_frames + offset).clamp_max(self.num_starts - 1)


class StateBank:
    """Physics states (qpos, qvel) the policy itself reached, ``size`` per reference frame (a ring per frame).

    Training episodes that start at frame ``f`` > 0 restore one of the states banked at ``f`` (with probability
    ``StartSamplingConfig.bank``) instead of the reference's: mocap references are not physically consistent
    (sub2_largetable_000's reference thumbs lie 4 cm inside the table during the carry), so a reference-state
    start mid-carry sheds its grasp within frames and teaches nothing about the carry. Only worlds whose episode
    began at frame 0 or from a banked state record (their states were reached by simulation from a frame-0
    start, however many restarts back).
    """

    def __init__(self, num_frames: int, size: int, nq: int, nv: int, device: torch.device | str = "cpu"):
        self.size = int(size)
        self.qpos = torch.zeros(num_frames, self.size, nq, dtype=torch.float64, device=device)
        self.qvel = torch.zeros(num_frames, self.size, nv, dtype=torch.float64, device=device)
        self.filled = torch.zeros(num_frames, self.size, dtype=torch.bool, device=device)
        """(T, size) which slots hold a state."""

    def record(
        self, frames: torch.Tensor, ok: torch.Tensor, qpos: torch.Tensor, qvel: torch.Tensor, gen: torch.Generator
    ) -> None:
        """Bank the states of worlds ``ok`` (N,) at ``frames`` (N,) into random slots of their frames."""
        slot = torch.randint(0, self.size, frames.shape, generator=gen, device=frames.device)
        ids = ok.nonzero().flatten()
        if ids.numel():
            f, k = frames[ids], slot[ids]
            self.qpos[f, k], self.qvel[f, k] = qpos[ids].to(self.qpos.dtype), qvel[ids].to(self.qvel.dtype)
            self.filled[f, k] = True

    def draw(self, frames: torch.Tensor, gen: torch.Generator) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """(have (N,) bool, qpos (N, nq), qvel (N, nv)): a random banked state at each of ``frames`` (N,);
        ``have`` is false where that frame's bank is empty."""
        u = torch.rand(frames.shape[0], self.size, generator=gen, device=frames.device)
        score = torch.where(self.filled[frames], u, -1.0)  # a uniform choice among the filled slots
        k = score.argmax(-1)
        return score.max(-1).values >= 0, self.qpos[frames, k], self.qvel[frames, k]

    def state_dict(self) -> dict[str, torch.Tensor]:
        return {"bank_qpos": self.qpos.clone(), "bank_qvel": self.qvel.clone(), "bank_filled": self.filled.clone()}

    def load_state_dict(self, state: dict[str, torch.Tensor]) -> None:
        self.qpos[:], self.qvel[:], self.filled[:] = state["bank_qpos"], state["bank_qvel"], state["bank_filled"]
