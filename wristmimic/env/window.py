"""Contact window around the first contact frame t_c and its three phases (paper: Learning Wrist-Guided
Manipulation), batched over worlds.

The window is the inclusive frame range [t_c - t_b, t_c + t_a]. The paper writes the phases as closed
intervals that share their endpoints; here every frame belongs to exactly one phase and the tight grasping
phase takes both shared endpoints::

    approach     [t_c - t_b,  t_c + tau1)     defaults: t_c - 10 .. t_c - 3
    grasp        [t_c + tau1, t_c + tau2]     defaults: t_c - 2  .. t_c + 12
    stabilize    (t_c + tau2, t_c + t_a]      defaults: t_c + 13 .. t_c + 15
    outside      elsewhere, and wherever t_c < 0 (no contact in the sequence)

All functions are elementwise, so ``frame`` and ``t_c`` may have any (broadcastable) shape, e.g. (N,).
"""

from __future__ import annotations

import torch

from wristmimic.env.config import WindowConfig

OUTSIDE, APPROACH, GRASP, STABILIZE = 0, 1, 2, 3
PHASE_NAMES = {OUTSIDE: "outside", APPROACH: "approach", GRASP: "grasp", STABILIZE: "stabilize"}


def window_bounds(t_c: torch.Tensor, cfg: WindowConfig) -> tuple[torch.Tensor, torch.Tensor]:
    """Inclusive window (lo, hi) = (t_c - t_b, t_c + t_a); where t_c < 0 an empty range (hi = lo - 1)."""
    lo = t_c - cfg.t_b
    hi = torch.where(t_c >= 0, t_c + cfg.t_a, lo - 1)
    return lo, hi


def in_window(frame: torch.Tensor, t_c: torch.Tensor, cfg: WindowConfig) -> torch.Tensor:
    """Bool: frame lies in the contact window [t_c - t_b, t_c + t_a] (never where t_c < 0)."""
    lo, hi = window_bounds(t_c, cfg)
    return (frame >= lo) & (frame <= hi)


def phase(frame: torch.Tensor, t_c: torch.Tensor, cfg: WindowConfig) -> torch.Tensor:
    """Long phase id (OUTSIDE, APPROACH, GRASP, STABILIZE) of each frame; the boundaries are in the module doc."""
    rel = frame - t_c
    inside = in_window(frame, t_c, cfg)
    out = torch.full_like(rel, STABILIZE)
    out = torch.where(rel <= cfg.tau2, torch.full_like(rel, GRASP), out)
    out = torch.where(rel < cfg.tau1, torch.full_like(rel, APPROACH), out)
    return torch.where(inside, out, torch.full_like(rel, OUTSIDE)).long()
