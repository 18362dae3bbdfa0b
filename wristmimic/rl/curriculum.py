"""Training curricula: the virtual object controller's gain (DexMachina), lowered to exactly zero, and the root
assist's and the hands' adhesion gains (:func:`root_assist_gain`, :func:`hand_adhesion_gain`, linear ramps to zero).

The gain starts at ``initial_gain``. After every iteration whose episodes would survive a whole clip with
probability above ``survival`` (projected from the iteration's termination rate per step; with ``gate="completion"``
the share of its ended episodes that reached the clip's end), it is multiplied by
``decay``; with ``recover`` > 0, after every iteration whose statistic is below ``recover`` it is divided
by ``decay`` again (up to ``initial_gain``: DexMachina dials its gains back when episodes stay short); below
``min_gain`` it becomes 0, for good. A cap ``1 - frames / zero_by_frames`` makes it reach zero after that
many training frames whatever the episodes do, so the policy always trains its last part, and is always
evaluated, without help.
"""

from __future__ import annotations

import math
from typing import Any

from wristmimic.env.config import HandAdhesionConfig, ObjectControllerConfig, RootAssistConfig


def linear_ramp_gain(cfg: RootAssistConfig | HandAdhesionConfig, frames: int) -> float:
    """Gain of a training-only aid after ``frames`` training frames: ``initial_gain`` falling linearly to 0 at
    ``zero_by_frames``; exactly 0 below ``min_gain`` and when disabled (a pure function of frames: resumes and
    reproductions need no state)."""
    if not cfg.enabled:
        return 0.0
    gain = max(0.0, 1.0 - frames / cfg.zero_by_frames) * cfg.initial_gain
    return 0.0 if gain < cfg.min_gain else gain


def root_assist_gain(cfg: RootAssistConfig, frames: int) -> float:
    """The root assist's gain after ``frames`` training frames (:func:`linear_ramp_gain`)."""
    return linear_ramp_gain(cfg, frames)


def hand_adhesion_gain(cfg: HandAdhesionConfig, frames: int) -> float:
    """The hands' adhesion gain after ``frames`` training frames (:func:`linear_ramp_gain`)."""
    return linear_ramp_gain(cfg, frames)


class ObjectCurriculum:
    """The gain of the virtual object controller over training; its state goes into checkpoints."""

    def __init__(self, cfg: ObjectControllerConfig, num_frames: int):
        self.cfg = cfg
        self.num_frames = int(num_frames)
        self.gain = float(cfg.initial_gain) if cfg.enabled else 0.0
        self._adaptive = self.gain
        self.zero_frames: int | None = None if self.gain > 0 else 0
        """Training frames at which the gain first reached zero (None: not yet)."""

    def projected_survival(self, terminations: int, world_steps: int) -> float:
        """Probability of an episode surviving the whole clip at this iteration's termination rate per step."""
        hazard = terminations / max(world_steps, 1)
        return (1.0 - hazard) ** max(self.num_frames - 1, 1)

    def update(self, terminations: int, world_steps: int, frames: int, episodes: int | None = None) -> float:
        """Advance after an iteration (its terminations over ``world_steps`` world steps and ``episodes`` ended
        episodes; ``frames`` trained so far); returns the new gain. With ``gate="completion"`` an iteration in
        which no episode ended moves nothing but the frame cap."""
        if self.gain == 0.0:
            return 0.0
        c = self.cfg
        if c.gate == "completion":
            stat = (episodes - terminations) / episodes if episodes else None
        else:
            stat = self.projected_survival(terminations, world_steps)
        if stat is not None and stat > c.survival:
            self._adaptive *= c.decay
        elif stat is not None and stat < c.recover:
            self._adaptive = min(self._adaptive / c.decay, c.initial_gain)
        cap = 1.0 - frames / max(c.zero_by_frames, 1)
        gain = min(self._adaptive, cap * c.initial_gain)
        self.gain = 0.0 if gain < c.min_gain or math.isnan(gain) else gain
        if self.gain == 0.0:
            self.zero_frames = frames
        return self.gain

    def weight_gain(self, frames: int) -> float:
        """Gain of the weight support (``weight_zero_by_frames``; else the pose gain) after ``frames`` frames."""
        c = self.cfg
        if not c.enabled or c.weight_zero_by_frames <= 0:
            return self.gain
        ramp = max(0.0, 1.0 - frames / c.weight_zero_by_frames) * c.initial_gain
        gain = max(self.gain, ramp)
        return 0.0 if gain < c.min_gain else gain

    def state_dict(self) -> dict[str, Any]:
        return {"gain": self.gain, "adaptive": self._adaptive, "zero_frames": self.zero_frames}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        self.gain, self._adaptive = float(state["gain"]), float(state["adaptive"])
        self.zero_frames = None if state["zero_frames"] is None else int(state["zero_frames"])
