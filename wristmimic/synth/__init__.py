"""Synthetic scenes: a humanoid with the SMPL-X body structure sized from published proportions of stature,
a box on a table, and box-lifting references made by inverse kinematics (``wristmimic synth``).

- :mod:`~wristmimic.synth.anthropometry`: segment proportions (Drillis & Contini 1966; Buchholz et al. 1992);
- :mod:`~wristmimic.synth.humanoid`: the 52-body MJCF in a T-pose;
- :mod:`~wristmimic.synth.ik`: whole-body damped least-squares IK with MuJoCo Jacobians;
- :mod:`~wristmimic.synth.motion`: the phases (stand, reach, grasp, lift, hold / turn, put down, release,
  retract, rest) and their minimum-jerk targets;
- :mod:`~wristmimic.synth.generate`: variants, objects, contact labels and the canonical file.
"""

from wristmimic.synth.generate import VARIANTS, generate

__all__ = ["VARIANTS", "generate"]
