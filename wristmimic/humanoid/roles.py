"""Body roles: which bodies are fingers, wrists, arm, key, contact and per-hand bodies.

Roles are data stored with each humanoid, so every later stage works for any hand. They are derived
from the body tree and a few anchor names per humanoid family:

- ``left_hand`` / ``right_hand``: the wrist body and its whole subtree;
- ``left_fingers`` / ``right_fingers``: the hand minus the wrist; ``fingers`` both;
- ``left_fingertips`` / ``right_fingertips``: leaves of the finger subtrees;
- ``left_arm`` / ``right_arm``: shoulder and elbow = grandparent and parent of the wrist;
- ``wrists``: [left wrist, right wrist];
- ``non_finger``: every body that is not a finger (root included); ``key_bodies``: non-finger minus the root
  (InterMimic's 21 key bodies for SMPL-X); ``contact_bodies``: key bodies + fingertips (InterMimic's 31);
- ``feet``: ankle and toe (ball-of-foot) bodies of both legs; ``root``, ``head``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from wristmimic.errors import InputError
from wristmimic.humanoid.skeleton import Skeleton


@dataclass(frozen=True)
class HumanoidProfile:
    """Anchor body names of a humanoid family."""

    family: str
    left_wrist: str
    right_wrist: str
    feet: tuple[str, ...]
    head: str


PROFILES: dict[str, HumanoidProfile] = {
    "smplx": HumanoidProfile("smplx", "L_Wrist", "R_Wrist", ("L_Ankle", "L_Toe", "R_Ankle", "R_Toe"), "Head"),
    "parahome": HumanoidProfile(
        "parahome",
        "jLeftWrist",
        "jRightWrist",
        ("jLeftAnkle", "jLeftBallFoot", "jRightAnkle", "jRightBallFoot"),
        "jC1Head",
    ),
}

ROLE_NAMES = (
    "root",
    "head",
    "wrists",
    "left_arm",
    "right_arm",
    "left_hand",
    "right_hand",
    "left_fingers",
    "right_fingers",
    "fingers",
    "left_fingertips",
    "right_fingertips",
    "non_finger",
    "key_bodies",
    "contact_bodies",
    "feet",
)
ROLE_DOCS = {
    "root": "the free-joint root body",
    "head": "the head body",
    "wrists": "[left wrist, right wrist]",
    "left_arm": "left shoulder and elbow (wrist grandparent, parent)",
    "right_arm": "right shoulder and elbow (wrist grandparent, parent)",
    "left_hand": "left wrist and its subtree",
    "right_hand": "right wrist and its subtree",
    "left_fingers": "left hand minus the wrist",
    "right_fingers": "right hand minus the wrist",
    "fingers": "both hands' finger bodies",
    "left_fingertips": "leaves of the left finger subtree",
    "right_fingertips": "leaves of the right finger subtree",
    "non_finger": "every body that is not a finger (root included)",
    "key_bodies": "non-finger bodies minus the root (tracked positions)",
    "contact_bodies": "key bodies + fingertips",
    "feet": "ankle and toe bodies",
}


def detect_profile(skel: Skeleton, source: str | None = None) -> HumanoidProfile:
    """The profile whose anchor names all exist in the skeleton."""
    names = set(skel.body_names)
    for p in PROFILES.values():
        if {p.left_wrist, p.right_wrist, p.head, *p.feet} <= names:
            return p
    raise InputError(
        source,
        "mjcf",
        "unknown humanoid family: no known wrist/foot/head body names",
        f"the body names of one of {sorted(PROFILES)}",
    )


def compute_roles(skel: Skeleton, profile: HumanoidProfile) -> dict[str, np.ndarray]:
    """Role name -> sorted int32 body indices (``wrists`` keeps left, right order)."""
    lw, rw = skel.index(profile.left_wrist), skel.index(profile.right_wrist)
    roles: dict[str, list[int]] = {"root": [0], "head": [skel.index(profile.head)], "wrists": [lw, rw]}
    for side, w in (("left", lw), ("right", rw)):
        hand = skel.subtree(w)
        fingers = [b for b in hand if b != w]
        elbow = int(skel.parents[w])
        shoulder = int(skel.parents[elbow])
        if elbow <= 0 or shoulder <= 0:
            raise InputError(None, f"body {skel.body_names[w]}", "wrist has no elbow and shoulder above it")
        roles[f"{side}_hand"] = hand
        roles[f"{side}_fingers"] = fingers
        roles[f"{side}_fingertips"] = [b for b in fingers if not skel.children(b)]
        roles[f"{side}_arm"] = sorted([shoulder, elbow])
    finger_set = set(roles["left_fingers"]) | set(roles["right_fingers"])
    roles["fingers"] = sorted(finger_set)
    roles["non_finger"] = [b for b in range(skel.num_bodies) if b not in finger_set]
    roles["key_bodies"] = [b for b in roles["non_finger"] if b != 0]
    roles["contact_bodies"] = sorted(roles["key_bodies"] + roles["left_fingertips"] + roles["right_fingertips"])
    roles["feet"] = sorted(skel.index(n) for n in profile.feet)
    return {k: np.asarray(roles[k], dtype=np.int32) for k in ROLE_NAMES}
