"""wristmimic: physics-based human-object-interaction retargeting (WristMimic) on MuJoCo."""

__version__ = "0.1.0"
