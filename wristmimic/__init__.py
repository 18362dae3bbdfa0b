"""wristmimic: physics-based human-object-interaction retargeting (WristMimic) on MuJoCo."""

__version__ = "0.2.0"
