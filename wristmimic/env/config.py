"""Every constant of the WristMimic environment in one place (paper supplement, InterMimic defaults).

Variants for the paper's tables are built by :func:`variant_config` from a name.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

VARIANTS = ("wristmimic", "decoupled", "reward-modulation-only", "reset-only", "finger-guidance", "intermimic")


@dataclass(frozen=True)
class RewardWeights:
    """lambda of each multiplicative factor exp(-lambda * E) (paper supplement, Table 'Reward weights')."""

    p: float = 30.0
    """Body position outside the contact window."""
    r: float = 2.5
    """Body rotation outside the contact window."""
    gbp: float = 10.0
    """Body position inside the contact window (reduced from p)."""
    gbr: float = 1.0
    """Body rotation inside the contact window (reduced from r)."""
    gwp: float = 10.0
    """Wrist position, every phase."""
    gwr: float = 1.0
    """Wrist rotation, every phase."""
    fp: float = 30.0
    """Finger position (finger-guidance and intermimic variants only)."""
    fr: float = 2.5
    """Finger rotation (finger-guidance and intermimic variants only)."""
    op: float = 5.0
    """Object position."""
    orot: float = 0.1
    """Object rotation (paper 'or')."""
    ig: float = 5.0
    """Interaction graph."""
    cg_hand: float = 10.0
    """Hand contact."""
    cg_other: float = 5.0
    """Other (non-finger) body contact."""
    eg1: float = 2e-5
    """Joint energy (joint acceleration)."""
    eg2: float = 2e-5
    """Object energy (object acceleration)."""
    eg3: float = 1e-9
    """Contact energy (humanoid contact forces)."""
    near_far: float = 5.0
    """InterMimic's w = exp(-near_far * d): position error weighted near the object, rotation error far."""


@dataclass(frozen=True)
class WindowConfig:
    """Contact window [t_c - t_b, t_c + t_a] and its phases (paper: tau1 = -2, tau2 = 12)."""

    t_b: int = 10
    t_a: int = 15
    tau1: int = -2
    """Approach ends / grasping starts at t_c + tau1."""
    tau2: int = 12
    """Grasping ends / stabilisation starts at t_c + tau2."""


@dataclass(frozen=True)
class WristThresholds:
    """Wrist reset thresholds per phase (position m, rotation rad); grasping is the tight one."""

    approach_pos: float = 0.15
    approach_rot: float = 0.5
    grasp_pos: float = 0.07
    grasp_rot: float = 0.2
    stabilize_pos: float = 0.15
    stabilize_rot: float = 0.5


@dataclass(frozen=True)
class TerminationConfig:
    """Base terminations (InterMimic): fall, body error, object error, contact lost."""

    fall_height: float = 0.3
    """Root height below this (m) ends the episode."""
    body_error: float = 0.5
    """Mean key-body position error above this (m) ends the episode."""
    object_error: float = 0.5
    """Mean object surface-point error above this (m) ends the episode."""
    contact_lost_frames: int = 10
    """Reference hand in contact but no simulated hand-object contact for more than this many frames."""
    grace_frames: int = 1
    """Kinematic terminations start after this many steps of an episode."""


@dataclass(frozen=True)
class EnvConfig:
    """The WristMimic environment. Defaults = the paper's method (variant 'wristmimic')."""

    variant: str = "wristmimic"
    goal_horizons: tuple[int, ...] = (1, 16)
    """Future reference frames in the goal observation (InterMimic: t+1 and t+16)."""
    window_modulation: bool = True
    """Inside the contact window: arm weights 0, wrist terms kept, body weights reduced (gbp, gbr)."""
    wrist_resets: bool = True
    """Phase-specific wrist thresholds inside the contact window."""
    wrist_terms: bool = True
    """Separate wrist position/rotation reward factors (gwp, gwr); else wrists count as body joints."""
    finger_targets: bool = False
    """Finger pose targets in the goal observation and finger pose rewards."""
    weights: RewardWeights = field(default_factory=RewardWeights)
    window: WindowConfig = field(default_factory=WindowConfig)
    wrist: WristThresholds = field(default_factory=WristThresholds)
    termination: TerminationConfig = field(default_factory=TerminationConfig)
    ig_points: int = 128
    """Object surface points (a seeded subset of the 1,024 stored) for the interaction graph, nearest-point
    features and object error. InterMimic uses all 1,024; on CPU the all-pairs graph then costs as much as
    the physics (benchmarks/env_step.py), 128 keeps the environment >= 80 % inside MuJoCo."""
    math_threads: int = 1
    """torch threads for observation/reward math inside ``step``; 1 avoids OpenMP contention with the
    physics threads on small machines (restored afterwards)."""
    contact_force_threshold: float = 0.1
    """A body counts as in contact when its net contact force exceeds this (N)."""
    max_episode_frames: int = 300
    """Training episodes are truncated after this many frames (InterMimic rolloutLength 300)."""
    reset_frame0_prob: float = 0.1
    """Reference state initialisation: probability of starting at frame 0 (else a uniform frame)."""
    action_scale: float = 1.0
    """Actions in [-1, 1] map to PD targets offset + action_scale * scale * a (InterMimic's mapping)."""


def variant_config(name: str, **overrides: object) -> EnvConfig:
    """The paper's variants by name; ``overrides`` replace fields (e.g. ``wrist=WristThresholds(...)``)."""
    flags = {
        "wristmimic": dict(window_modulation=True, wrist_resets=True, wrist_terms=True, finger_targets=False),
        "decoupled": dict(window_modulation=False, wrist_resets=False, wrist_terms=False, finger_targets=False),
        "reward-modulation-only": dict(
            window_modulation=True, wrist_resets=False, wrist_terms=True, finger_targets=False
        ),
        "reset-only": dict(window_modulation=False, wrist_resets=True, wrist_terms=True, finger_targets=False),
        "finger-guidance": dict(window_modulation=True, wrist_resets=True, wrist_terms=True, finger_targets=True),
        "intermimic": dict(window_modulation=False, wrist_resets=False, wrist_terms=False, finger_targets=True),
    }
    if name not in flags:
        raise ValueError(f"unknown variant {name!r}; expected one of {', '.join(VARIANTS)}")
    return replace(EnvConfig(variant=name, **flags[name]), **overrides)  # type: ignore[arg-type]
