"""Early terminations (InterMimic's base resets + WristMimic's phase-specific wrist resets), batched.

Each ``term_*`` function returns an (N,) bool "this reason fires"; :func:`check_terminations` combines them
and reports the first reason in the order NONE < FALL < BODY_ERROR < OBJECT_ERROR < CONTACT_LOST < WRIST.
Thresholds come from :class:`wristmimic.env.config.TerminationConfig` and ``WristThresholds``; every
comparison is strict (an error exactly at a threshold does not terminate).
"""

from __future__ import annotations

from dataclasses import dataclass

import torch

from wristmimic.env.bodies import BodySets
from wristmimic.env.config import EnvConfig, WristThresholds
from wristmimic.env.torch_math import quat_angle
from wristmimic.env.window import APPROACH, GRASP, OUTSIDE, STABILIZE

NONE, FALL, BODY_ERROR, OBJECT_ERROR, CONTACT_LOST, WRIST = 0, 1, 2, 3, 4, 5
REASONS = {
    NONE: "none",
    FALL: "fall",
    BODY_ERROR: "body_error",
    OBJECT_ERROR: "object_error",
    CONTACT_LOST: "contact_lost",
    WRIST: "wrist",
}


@dataclass(frozen=True)
class TerminationConstants:
    """Fixed constants of the termination terms that are not thresholds (not in config.py)."""

    wrist_start_step: int = 1
    """Wrist resets apply from this step on: a window rule, not subject to TerminationConfig.grace_frames."""


CONSTANTS = TerminationConstants()


@dataclass
class TerminationInputs:
    """Everything the terminations read, torch float32 unless stated."""

    root_height: torch.Tensor  # (N,)
    body_pos: torch.Tensor  # (N, B, 3) simulated
    ref_body_pos: torch.Tensor  # (N, B, 3)
    obj_points: torch.Tensor  # (N, P, 3) dynamic objects' surface points in the world, simulated
    ref_obj_points: torch.Tensor  # (N, P, 3) reference
    contact_lost: torch.Tensor  # (N,) long: frames in a row with reference hand contact but none simulated
    wrist_pos: torch.Tensor  # (N, 2, 3) [left, right]
    ref_wrist_pos: torch.Tensor  # (N, 2, 3)
    wrist_quat: torch.Tensor  # (N, 2, 4) wxyz
    ref_wrist_quat: torch.Tensor  # (N, 2, 4)
    phase: torch.Tensor  # (N,) long from window.phase
    grasp_hands: torch.Tensor  # (N, 2) bool
    step: torch.Tensor  # (N,) long steps since the episode started


def term_fall(x: TerminationInputs, cfg: EnvConfig) -> torch.Tensor:
    """Root height below fall_height."""
    return x.root_height < cfg.termination.fall_height


def term_body_error(x: TerminationInputs, sets: BodySets, cfg: EnvConfig) -> torch.Tensor:
    """Mean key-body position error (m) above body_error."""
    diff = x.body_pos.index_select(1, sets.key) - x.ref_body_pos.index_select(1, sets.key)
    err = torch.linalg.vector_norm(diff, dim=-1).mean(-1)
    return err > cfg.termination.body_error


def term_object_error(x: TerminationInputs, cfg: EnvConfig) -> torch.Tensor:
    """Mean object surface-point position error (m) above object_error (never without points)."""
    if x.obj_points.shape[1] == 0:
        return torch.zeros_like(x.root_height, dtype=torch.bool)
    err = torch.linalg.vector_norm(x.obj_points - x.ref_obj_points, dim=-1).mean(-1)
    return err > cfg.termination.object_error


def term_contact_lost(x: TerminationInputs, cfg: EnvConfig) -> torch.Tensor:
    """Reference hand contact missing in simulation for more than contact_lost_frames frames in a row."""
    return x.contact_lost > cfg.termination.contact_lost_frames


_THRESHOLD_TABLES: dict[tuple[WristThresholds, torch.device], tuple[torch.Tensor, torch.Tensor]] = {}


def _threshold_tables(thr: WristThresholds, device: torch.device) -> tuple[torch.Tensor, torch.Tensor]:
    """(4,) position and rotation thresholds by phase code (+inf outside the window), made once per device."""
    key = (thr, device)
    if key not in _THRESHOLD_TABLES:
        inf = float("inf")
        pos = torch.full((4,), inf, dtype=torch.float32, device=device)
        rot = torch.full((4,), inf, dtype=torch.float32, device=device)
        for p, tp, tr in (
            (APPROACH, thr.approach_pos, thr.approach_rot),
            (GRASP, thr.grasp_pos, thr.grasp_rot),
            (STABILIZE, thr.stabilize_pos, thr.stabilize_rot),
        ):
            pos[p], rot[p] = tp, tr
        _THRESHOLD_TABLES[key] = (pos, rot)
    return _THRESHOLD_TABLES[key]


def phase_thresholds(ph: torch.Tensor, thr: WristThresholds) -> tuple[torch.Tensor, torch.Tensor]:
    """(N,) wrist position (m) and rotation (rad) thresholds of each phase; +inf outside the window."""
    pos, rot = _threshold_tables(thr, ph.device)
    return pos[ph], rot[ph]


def term_wrist(x: TerminationInputs, cfg: EnvConfig) -> torch.Tensor:
    """A grasping hand's wrist beyond its phase's position or rotation threshold inside the window."""
    pos_thr, rot_thr = phase_thresholds(x.phase, cfg.wrist)
    pos_err = torch.linalg.vector_norm(x.wrist_pos - x.ref_wrist_pos, dim=-1)  # (N, 2)
    rot_err = quat_angle(x.ref_wrist_quat, x.wrist_quat)  # (N, 2)
    beyond = (pos_err > pos_thr[:, None].to(pos_err.dtype)) | (rot_err > rot_thr[:, None].to(rot_err.dtype))
    return (beyond & x.grasp_hands).any(-1) & (x.phase != OUTSIDE)


def check_terminations(
    x: TerminationInputs, sets: BodySets, cfg: EnvConfig, consts: TerminationConstants = CONSTANTS
) -> tuple[torch.Tensor, torch.Tensor]:
    """(terminated (N,) bool, reason (N,) long); the first reason in the order FALL..WRIST wins.

    Fall, body, object and contact terminations apply only when step > grace_frames (InterMimic: after
    step 1); the wrist rule (cfg.wrist_resets) applies from step >= consts.wrist_start_step.
    """
    past_grace = x.step > cfg.termination.grace_frames
    terms = [
        (FALL, term_fall(x, cfg) & past_grace),
        (BODY_ERROR, term_body_error(x, sets, cfg) & past_grace),
        (OBJECT_ERROR, term_object_error(x, cfg) & past_grace),
        (CONTACT_LOST, term_contact_lost(x, cfg) & past_grace),
    ]
    if cfg.wrist_resets:
        terms.append((WRIST, term_wrist(x, cfg) & (x.step >= consts.wrist_start_step)))
    reason = torch.full_like(x.step, NONE, dtype=torch.long)
    for code, fired in reversed(terms):
        reason = torch.where(fired, code, reason)
    return reason != NONE, reason


class ContactLostCounter:
    """Per world and hand, consecutive frames in which the reference hand is in contact and the simulated
    hand is not (InterMimic's contact reset counter)."""

    def __init__(self, n: int, device: torch.device | str = "cpu") -> None:
        self.counts = torch.zeros(n, 2, dtype=torch.long, device=device)
        """(N, 2) current run length per hand [left, right]."""

    def update(self, ref_hand: torch.Tensor, sim_hand: torch.Tensor) -> torch.Tensor:
        """Advance one frame with (N, 2) bool contacts; returns (N,) long max over hands of the run length."""
        lost = ref_hand & ~sim_hand
        self.counts = torch.where(lost, self.counts + 1, torch.zeros_like(self.counts))
        return self.counts.max(-1).values

    __call__ = update

    def reset(self, ids: torch.Tensor) -> None:
        """Zero the counters of worlds ids (long indices)."""
        self.counts[ids] = 0
