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
