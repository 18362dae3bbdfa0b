"""Counter-based random numbers: every value is a pure function of (trial seed, step, index).

A trial can then be replayed alone, in any world of any batch, and a resumed evaluation draws exactly the
numbers the interrupted one would have drawn. The generator is splitmix64 integer mixing in torch int64
(wrapping multiplication; logical shifts emulated on the signed type), top 53 bits -> uniform in (0, 1),
Box-Muller -> standard normal.
"""

from __future__ import annotations

import math

import torch


def _signed(x: int) -> int:
    """A 64-bit unsigned constant as the int64 with the same bits."""
    return x - (1 << 64) if x >= 1 << 63 else x


_GOLDEN = _signed(0x9E3779B97F4A7C15)
_M1 = _signed(0xBF58476D1CE4E5B9)
_M2 = _signed(0x94D049BB133111EB)
_MASK63 = (1 << 63) - 1


def _lsr(x: torch.Tensor, k: int) -> torch.Tensor:
    """Logical right shift of int64 bits."""
    return (x >> k) & ((1 << (64 - k)) - 1)


def splitmix64(x: torch.Tensor) -> torch.Tensor:
    """The splitmix64 finaliser of ``x + golden`` (int64 in, int64 out, element-wise)."""
    z = x.to(torch.int64) + _GOLDEN
    z = (z ^ _lsr(z, 30)) * _M1
    z = (z ^ _lsr(z, 27)) * _M2
    return z ^ _lsr(z, 31)


def trial_seeds(base_seed: int, trials: torch.Tensor) -> torch.Tensor:
    """(n,) int64 seeds in [0, 2^63) of trial indices ``trials`` under ``base_seed``."""
    return (
        splitmix64(splitmix64(torch.full_like(trials, base_seed, dtype=torch.int64)) ^ trials.to(torch.int64)) & _MASK63
    )


def trial_seed(base_seed: int, trial: int) -> int:
    """The seed of one trial (see :func:`trial_seeds`)."""
    return int(trial_seeds(base_seed, torch.tensor([trial]))[0])


def uniform(seeds: torch.Tensor, steps: torch.Tensor, size: int, stream: int = 0) -> torch.Tensor:
    """(N, size) float64 uniforms in (0, 1) for rows (seed, step); ``stream`` separates independent uses."""
    key = splitmix64(splitmix64(seeds.to(torch.int64) ^ _signed(0xA0761D6478BD642F * (stream + 1) % (1 << 64))))
    key = splitmix64(key ^ steps.to(torch.int64))
    h = splitmix64(key[:, None] ^ torch.arange(size, dtype=torch.int64)[None])
    return (_lsr(h, 11).to(torch.float64) + 0.5) * 2.0**-53


def normal(seeds: torch.Tensor, steps: torch.Tensor, size: int, stream: int = 0) -> torch.Tensor:
    """(N, size) float32 standard normals for rows (seed, step), by Box-Muller on two uniform columns."""
    u = uniform(seeds, steps, 2 * size, stream)
    r = torch.sqrt(-2.0 * torch.log(u[:, :size]))
    return (r * torch.cos(2.0 * math.pi * u[:, size:])).to(torch.float32)
