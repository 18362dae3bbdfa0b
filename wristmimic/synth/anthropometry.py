"""Segment lengths and radii of the synthetic humanoid as fractions of stature H (metres out, H in).

Sources (published facts only; nothing is measured from any data set in this project):

- **Body** — Drillis, R. and Contini, R. (1966), *Body Segment Parameters*, Technical Report 1166-03, Office
  of Vocational Rehabilitation, New York University School of Engineering and Science; the segment lengths as
  fractions of body height reproduced in D. A. Winter, *Biomechanics and Motor Control of Human Movement*
  (4th ed., Wiley, 2009), Fig. 4.1. The fractions used here (heights above the floor unless stated):
  top of head 1.000, chin 0.870, shoulder (acromion) 0.818, hip (greater trochanter) 0.530, knee 0.285,
  ankle 0.039; shoulder width 0.259, hip width 0.191, upper arm 0.186, forearm 0.146, hand 0.108,
  thigh 0.245 (= 0.530 - 0.285), shank (leg) 0.246 (= 0.285 - 0.039), foot length 0.152, foot width 0.055.
- **Hand** — Buchholz, B., Armstrong, T. J. and Goldstein, S. A. (1992), "Anthropometric data for describing
  the kinematics of the human hand", *Ergonomics* 35(3), 261–273: kinematic segment lengths as fractions of
  hand length (wrist crease to the middle fingertip). Metacarpal / proximal / middle / distal:
  thumb 0.251 / 0.196 / – / 0.158 (metacarpal, proximal, distal phalanx), index 0.374 / 0.265 / 0.143 / 0.097,
  middle 0.373 / 0.277 / 0.170 / 0.108, ring 0.336 / 0.259 / 0.165 / 0.107, little 0.295 / 0.206 / 0.117 / 0.093.

Everything else is a **modelling choice** (stated where it is defined, never presented as a measurement):
where the SMPL-X joints sit between those landmarks (pelvis joint, spine split, neck, head joint, hip-joint
spacing, heel and ball of the foot, thumb base, metacarpal spread), and the capsule radii, which come from
plausible adult circumferences (r = C / 2 pi) expressed as fractions of stature.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

DEFAULT_HEIGHT_M = 1.70

DRILLIS_CONTINI = {
    "head_top": 1.000,  # height of the top of the head (stature)
    "chin": 0.870,  # height of the chin
    "shoulder": 0.818,  # height of the shoulder (acromion)
    "hip": 0.530,  # height of the hip (greater trochanter), taken as the hip joint centre height
    "knee": 0.285,  # height of the knee joint
    "ankle": 0.039,  # height of the ankle joint
    "shoulder_width": 0.259,  # biacromial width
    "hip_width": 0.191,  # bitrochanteric width
    "upper_arm": 0.186,  # shoulder to elbow
    "forearm": 0.146,  # elbow to wrist
    "hand": 0.108,  # wrist crease to the tip of the middle finger
    "foot_length": 0.152,  # heel to the tip of the longest toe
    "foot_width": 0.055,  # breadth of the foot
}
"""Drillis & Contini (1966) segment proportions (fractions of stature), as reproduced in Winter (2009) Fig. 4.1."""

BUCHHOLZ_1992 = {
    # finger: (metacarpal, proximal, middle, distal) kinematic segment lengths / hand length
    "Thumb": (0.251, 0.196, 0.158),  # metacarpal, proximal phalanx, distal phalanx (no middle phalanx)
    "Index": (0.374, 0.265, 0.143, 0.097),
    "Middle": (0.373, 0.277, 0.170, 0.108),
    "Ring": (0.336, 0.259, 0.165, 0.107),
    "Pinky": (0.295, 0.206, 0.117, 0.093),
}
"""Buchholz, Armstrong & Goldstein (1992): segment lengths as fractions of hand length."""


@dataclass(frozen=True)
class Choices:
    """Modelling choices (fractions of stature H unless stated); not from the sources above."""

    pelvis_above_hip: float = 0.050
    """SMPL-X's pelvis joint lies above the hip joint centres (about 8.5 cm at 1.70 m)."""
    hip_half_spacing: float = 0.0525
    """Hip joint centre to the midline: 0.55 of half the bitrochanteric width (0.191 H)."""
    spine_fractions: tuple[float, float, float, float] = (0.06, 0.075, 0.03, 0.09)
    """Pelvis -> Torso -> Spine -> Chest -> Neck joint steps (sum 0.255: neck joint at 0.835 H)."""
    head_joint: float = 0.900
    """Height of the head (atlanto-occipital) joint, between chin (0.870) and eyes (0.936)."""
    collar_half_spacing: float = 0.045
    """Thorax (sterno-clavicular) joint to the midline; the shoulder joint sits at half the shoulder width."""
    heel_behind_ankle: float = 0.22
    """Heel behind the ankle joint, fraction of foot length."""
    ball_ahead_of_ankle: float = 0.50
    """Ball of the foot (metatarso-phalangeal joint, SMPL-X toe joint) ahead of the ankle, fraction of foot length."""
    ball_height: float = 0.012
    """Height of the toe joint above the floor."""
    carpal: float = 0.072
    """Wrist crease to the finger carpo-metacarpal joints, fraction of hand length: 1 - the middle finger's sum."""
    hand_breadth: float = 0.45
    """Hand breadth at the metacarpal heads, fraction of hand length; the four MCPs are spread evenly over it."""
    thumb_base: tuple[float, float, float] = (0.13, 0.10, -0.04)
    """Thumb carpo-metacarpal joint from the wrist, fractions of hand length: (radial, distal, palmar=-)."""
    thumb_angle_deg: float = 40.0
    """Angle between the resting thumb and the middle finger, in the plane of the palm."""
    palm_half_thickness: float = 0.072
    """Half the thickness of the palm at the metacarpals, fraction of hand length (about 1.3 cm at 1.70 m)."""
    wrist_half_thickness: float = 0.080
    """Half the palmar-dorsal thickness of the distal forearm, fraction of hand length (about 1.5 cm at 1.70 m,
    a little more than the palm). The forearm tapers to it: its distal half is a capsule of this radius. A
    forearm of uniform (mid-forearm) radius would stand 2.7 cm proud of the palm, so a palm laid flat on a box
    face would put the forearm inside the box (the reference of generator version 1 did, by 2.7 cm)."""
    forearm_taper: float = 0.5
    """Where along the forearm (elbow 0, wrist 1) the distal, wrist-sized capsule takes over."""


@dataclass(frozen=True)
class Circumferences:
    """Plausible adult segment circumferences as fractions of stature (a 1.70 m adult in brackets).

    Capsule radius = circumference / 2 pi. Limb values are averages along the segment (the largest
    circumference, e.g. the thigh at the gluteal fold, would overfill the capsule); trunk capsules are laid
    across the body, so their radius is half the trunk depth."""

    upper_arm: float = 0.170  # (29 cm)
    forearm: float = 0.147  # (25 cm)
    thigh: float = 0.290  # (49 cm)
    shank: float = 0.200  # (34 cm)
    neck: float = 0.190  # (32 cm)
    head: float = 0.330  # (56 cm)
    thorax: float = 0.190  # collar region (32 cm)
    pelvis_depth: float = 0.120  # antero-posterior depth of the pelvis (20 cm) -> radius = depth / 2
    lumbar_depth: float = 0.100  # (17 cm)
    chest_depth: float = 0.125  # (21 cm)
    finger: tuple[float, float, float] = (0.050, 0.043, 0.037)
    """Finger radii (not circumferences) by phalanx, fractions of hand length (proximal 0.92 cm at 1.70 m:
    a 5.8 cm ring-size circumference)."""
    thumb: tuple[float, float, float] = (0.065, 0.055, 0.048)
    """Thumb radii (metacarpal, proximal, distal), fractions of hand length."""


@dataclass(frozen=True)
class Anthropometry:
    """All proportions of the synthetic humanoid; :meth:`scaled` gives metres for a stature."""

    height: float = DEFAULT_HEIGHT_M
    body: dict[str, float] = field(default_factory=lambda: dict(DRILLIS_CONTINI))
    hand: dict[str, tuple[float, ...]] = field(default_factory=lambda: dict(BUCHHOLZ_1992))
    choices: Choices = field(default_factory=Choices)
    circumferences: Circumferences = field(default_factory=Circumferences)

    def __post_init__(self) -> None:
        if not 1.0 <= self.height <= 2.3:
            raise ValueError(f"height {self.height} m outside [1.0, 2.3] m")

    def m(self, key: str) -> float:
        """A Drillis & Contini proportion in metres."""
        return self.body[key] * self.height

    @property
    def hand_length(self) -> float:
        return self.m("hand")

    def to_dict(self) -> dict:
        """JSON-friendly record of every number (stored with the generated file)."""
        return {
            "height_m": self.height,
            "body_fractions_of_height": dict(self.body),
            "body_source": "Drillis & Contini (1966), as reproduced in Winter (2009) Fig. 4.1",
            "hand_fractions_of_hand_length": {k: list(v) for k, v in self.hand.items()},
            "hand_source": "Buchholz, Armstrong & Goldstein (1992), Ergonomics 35(3)",
            "choices": asdict(self.choices),
            "circumferences": asdict(self.circumferences),
        }
