"""Per-trial metrics, the success rule and the Wilson score interval.

A trial's errors are means over the frames it completed (frames 1..n after its start at frame 0); its peak object
position error is the largest over those frames. Its contact
ratio counts hand-frames: (frames where a reference hand touches the object and the simulated hand does too) /
(frames where the reference hand touches it over the whole sequence), so a trial that ends early keeps only
what it held. A sequence whose reference hands never touch the object has ratio 1.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch

TRIAL_COLUMNS: dict[str, str] = {
    "scene": "str",
    "trial": "int64",
    "seed": "int64",
    "noise": "str",
    "success": "bool",
    "terminated": "bool",
    "termination_reason": "str",
    "frames_completed": "int64",
    "frames_total": "int64",
    "obj_pos_err_cm": "float64",
    "obj_rot_err_deg": "float64",
    "wrist_pos_err_cm": "float64",
    "wrist_rot_err_deg": "float64",
    "contact_ratio": "float64",
    "obj_pos_err_peak_cm": "float64",
    "strict_success": "bool",
}
"""Columns of the per-trial table, in order, with their pandas dtypes."""


def wilson_interval(successes: int, n: int, z: float = 1.959963984540054) -> tuple[float, float]:
    """Wilson score interval (default 95 %) of a binomial proportion; (nan, nan) for n = 0."""
    if n <= 0:
        return math.nan, math.nan
    p = successes / n
    denom = 1.0 + z * z / n
    centre = (p + z * z / (2 * n)) / denom
    half = z * math.sqrt(p * (1.0 - p) / n + z * z / (4 * n * n)) / denom
    lo = 0.0 if successes <= 0 else max(0.0, centre - half)
    return lo, 1.0 if successes >= n else min(1.0, centre + half)


def is_success(
    terminated: torch.Tensor,
    completed: torch.Tensor,
    obj_pos_err_m: torch.Tensor,
    contact_ratio: torch.Tensor,
    max_obj_pos_err_m: float,
    min_contact_ratio: float,
) -> torch.Tensor:
    """The paper's rule: reached the end without early termination, mean object position error below the
    threshold, contact kept at least ``min_contact_ratio`` of the reference contact duration."""
    return ~terminated & completed & (obj_pos_err_m < max_obj_pos_err_m) & (contact_ratio >= min_contact_ratio)


def is_strict_success(
    success: torch.Tensor, obj_pos_err_peak_m: torch.Tensor, max_obj_pos_err_m: float
) -> torch.Tensor:
    """The paper's success and the object within the threshold of its reference in every completed frame."""
    return success & (obj_pos_err_peak_m < max_obj_pos_err_m)


@dataclass
class TrialSums:
    """Running per-world sums over the current trial's frames (N worlds)."""

    frames: torch.Tensor  # (N,) long
    obj_pos: torch.Tensor  # (N,) float64, m
    obj_rot: torch.Tensor  # (N,) float64, rad
    wrist_pos: torch.Tensor  # (N,) float64, m
    wrist_rot: torch.Tensor  # (N,) float64, rad
    contact_kept: torch.Tensor  # (N,) long hand-frames
    obj_pos_peak: torch.Tensor  # (N,) float64, m: the largest object position error so far

    @classmethod
    def zeros(cls, n: int) -> TrialSums:
        f = torch.zeros(n, dtype=torch.float64)
        i = torch.zeros(n, dtype=torch.long)
        return cls(i.clone(), f.clone(), f.clone(), f.clone(), f.clone(), i.clone(), f.clone())

    def add(self, e: dict[str, torch.Tensor]) -> None:
        """Fold one step of ``info["eval"]`` (WristMimicEnv) into the sums."""
        self.frames += 1
        self.obj_pos += e["obj_pos"].to(torch.float64)
        self.obj_rot += e["obj_rot"].to(torch.float64)
        self.wrist_pos += e["wrist_pos"].to(torch.float64)
        self.wrist_rot += e["wrist_rot"].to(torch.float64)
        self.contact_kept += (e["ref_hand"] & e["sim_hand"]).sum(-1)
        torch.maximum(self.obj_pos_peak, e["obj_pos"].to(torch.float64), out=self.obj_pos_peak)

    def clear(self, ids: torch.Tensor) -> None:
        for v in self.__dict__.values():
            v[ids] = 0

    def means(self, ids: torch.Tensor, ref_contact: int) -> dict[str, torch.Tensor]:
        """Per-trial means of worlds ``ids`` in report units (cm, degrees) and the contact ratio."""
        n = self.frames[ids].clamp_min(1).to(torch.float64)
        deg = 180.0 / math.pi
        ratio = (
            self.contact_kept[ids].to(torch.float64) / ref_contact
            if ref_contact
            else torch.ones(len(ids), dtype=torch.float64)
        )
        return {
            "obj_pos_err_cm": 100.0 * self.obj_pos[ids] / n,
            "obj_rot_err_deg": deg * self.obj_rot[ids] / n,
            "wrist_pos_err_cm": 100.0 * self.wrist_pos[ids] / n,
            "wrist_rot_err_deg": deg * self.wrist_rot[ids] / n,
            "contact_ratio": ratio,
            "obj_pos_err_peak_cm": 100.0 * self.obj_pos_peak[ids],
        }
