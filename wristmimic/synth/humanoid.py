"""A 52-body humanoid with the SMPL-X body structure, sized from published proportions of stature.

Body names, order and tree are InterMimic's ``omomo.xml`` (:data:`wristmimic.humanoid.smplx_body.BODY_NAMES`):
a free-joint Pelvis and 51 bodies with three hinges x, y, z each (30 of them finger bodies). The rest pose is a
T-pose in the humanoid's own axes (x forward, y left, z up): legs straight down, arms along +y (left) and -y
(right), fingers extending along the arm, palms facing down (-z), thumbs pointing forward. Bodies carry no rest
rotation, so hinge angles are joint rotations in the world-aligned rest frame. The root body sits at the pelvis
joint, ``hip + pelvis_above_hip`` above the floor, so the rest pose stands on z = 0 with the top of the head at
z = height.

Geoms: capsules on limbs, fingers, neck and across the trunk (radii from circumferences,
:mod:`wristmimic.synth.anthropometry`), a sphere for the head, boxes for feet, toes and palms; every geom
collides (``contype=conaffinity=1``, the scene turns self-collision off), density 1000 kg/m^3. Joint ranges
and PD gains follow InterMimic's (body joints +-180 deg; finger ranges as the scene applies them).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from wristmimic.humanoid.smplx_body import BODY_NAMES, FINGERS, PARENTS
from wristmimic.synth.anthropometry import Anthropometry

SIDES = (("L", 1.0), ("R", -1.0))
_GAINS = {"Hip": 800, "Knee": 800, "Ankle": 800, "Toe": 500, "Torso": 1000, "Spine": 1000, "Chest": 1000}
_GAINS.update({"Wrist": 300})


@dataclass(frozen=True)
class SynthHumanoid:
    """The generated MJCF and the hand geometry the motion generator needs (wrist frames, metres)."""

    mjcf: str
    anthropometry: Anthropometry
    offsets: dict[str, np.ndarray]
    """Body name -> offset from its parent (rest pose)."""
    palm_point: dict[str, np.ndarray]
    """'L' / 'R' -> centre of the palmar surface of the palm box, in the wrist frame."""
    palm_half_thickness: float
    fingertip_ahead: float
    """How far the longest fingertip reaches beyond the palm point along the fingers."""
    hand_points: dict[str, tuple[np.ndarray, np.ndarray]]
    """'L' / 'R' -> ((N, 3) points in the wrist frame, (N,) radii): capsule end centres and palm box corners of
    the hand in the rest pose; the hand's volume is their union of spheres (boxes: radius 0)."""

    @property
    def height(self) -> float:
        return self.anthropometry.height


def _f(v) -> str:
    return " ".join(f"{float(x):.6g}" for x in np.atleast_1d(v))


def _offsets(a: Anthropometry) -> dict[str, np.ndarray]:
    """Rest-pose offset of every body from its parent (metres)."""
    H, HL, c = a.height, a.hand_length, a.choices
    b = a.body
    pelvis_z = (b["hip"] + c.pelvis_above_hip) * H
    off: dict[str, np.ndarray] = {"Pelvis": np.array([0.0, 0.0, pelvis_z])}
    fl = b["foot_length"] * H
    for s, y in SIDES:
        off[f"{s}_Hip"] = np.array([0.0, y * c.hip_half_spacing * H, -c.pelvis_above_hip * H])
        off[f"{s}_Knee"] = np.array([0.0, 0.0, -(b["hip"] - b["knee"]) * H])
        off[f"{s}_Ankle"] = np.array([0.0, 0.0, -(b["knee"] - b["ankle"]) * H])
        off[f"{s}_Toe"] = np.array([c.ball_ahead_of_ankle * fl, 0.0, -(b["ankle"] - c.ball_height) * H])
    for name, step in zip(("Torso", "Spine", "Chest", "Neck"), c.spine_fractions, strict=True):
        off[name] = np.array([0.0, 0.0, step * H])
    neck_z = b["hip"] + c.pelvis_above_hip + sum(c.spine_fractions)
    chest_z = neck_z - c.spine_fractions[-1]
    off["Head"] = np.array([0.0, 0.0, (c.head_joint - neck_z) * H])
    spread = c.hand_breadth * HL / 4.0
    radial = {"Index": 1.5, "Middle": 0.5, "Ring": -0.5, "Pinky": -1.5}
    th = np.deg2rad(c.thumb_angle_deg)
    for s, y in SIDES:
        off[f"{s}_Thorax"] = np.array([0.0, y * c.collar_half_spacing * H, (b["shoulder"] - chest_z) * H])
        off[f"{s}_Shoulder"] = np.array([0.0, y * (b["shoulder_width"] / 2 - c.collar_half_spacing) * H, 0.0])
        off[f"{s}_Elbow"] = np.array([0.0, y * b["upper_arm"] * H, 0.0])
        off[f"{s}_Wrist"] = np.array([0.0, y * b["forearm"] * H, 0.0])
        for f in FINGERS:
            seg = a.hand[f]
            if f == "Thumb":
                d = np.array([np.sin(th), y * np.cos(th), 0.0])
                off[f"{s}_Thumb1"] = np.array([c.thumb_base[0], y * c.thumb_base[1], c.thumb_base[2]]) * HL
                off[f"{s}_Thumb2"] = seg[0] * HL * d
                off[f"{s}_Thumb3"] = seg[1] * HL * d
            else:
                off[f"{s}_{f}1"] = np.array([radial[f] * spread, y * (c.carpal + seg[0]) * HL, 0.0])
                off[f"{s}_{f}2"] = np.array([0.0, y * seg[1] * HL, 0.0])
                off[f"{s}_{f}3"] = np.array([0.0, y * seg[2] * HL, 0.0])
    return off


def _capsule(p0, p1, r: float) -> str:
    return f'<geom type="capsule" fromto="{_f(np.concatenate([p0, p1]))}" size="{r:.6g}"/>'


def _box(center, half) -> str:
    return f'<geom type="box" pos="{_f(center)}" size="{_f(half)}"/>'


def _geoms(a: Anthropometry, off: dict[str, np.ndarray]) -> dict[str, str]:
    """The collision geoms of each body (one, two for the tapered forearm), in the body frame."""
    H, HL, c, circ = a.height, a.hand_length, a.choices, a.circumferences
    b = a.body
    r_of = lambda frac: frac * H / (2 * np.pi)  # noqa: E731  circumference -> radius
    z0 = np.zeros(3)
    g: dict[str, str] = {}
    rp = circ.pelvis_depth / 2 * H
    ap = max(b["hip_width"] / 2 * H - rp, 0.01)
    g["Pelvis"] = _capsule([0, -ap, 0], [0, ap, 0], rp)
    # trunk capsules laid across the body (radius = half the trunk depth)
    rl, rc = circ.lumbar_depth / 2 * H, circ.chest_depth / 2 * H
    for name, r, half_w, nxt in (
        ("Torso", rl, 0.080, "Spine"),
        ("Spine", (rl + rc) / 2, 0.085, "Chest"),
        ("Chest", rc, 0.087, "Neck"),
    ):
        a_w = max(half_w * H - r, 0.01)
        zc = off[nxt][2] * (0.45 if name == "Chest" else 0.5)
        g[name] = _capsule([0, -a_w, zc], [0, a_w, zc], r)
    g["Neck"] = _capsule(z0, 0.7 * off["Head"], r_of(circ.neck))
    rh = r_of(circ.head)
    g["Head"] = f'<geom type="sphere" pos="0 0 {(1.0 - c.head_joint) * H - rh:.6g}" size="{rh:.6g}"/>'
    fl, fw = b["foot_length"] * H, b["foot_width"] * H
    ankle_h = b["ankle"] * H
    for s, _y in SIDES:
        thigh, shank = off[f"{s}_Knee"], off[f"{s}_Ankle"]
        g[f"{s}_Hip"] = _capsule(0.08 * thigh, 0.92 * thigh, r_of(circ.thigh))
        g[f"{s}_Knee"] = _capsule(0.08 * shank, 0.85 * shank, r_of(circ.shank))
        x0, x1 = -c.heel_behind_ankle * fl, c.ball_ahead_of_ankle * fl
        g[f"{s}_Ankle"] = _box([(x0 + x1) / 2, 0, -ankle_h / 2], [(x1 - x0) / 2, fw / 2, ankle_h / 2])
        toe_len = (1.0 - c.heel_behind_ankle - c.ball_ahead_of_ankle) * fl
        bh = c.ball_height * H
        g[f"{s}_Toe"] = _box([toe_len / 2, 0, -bh / 2], [toe_len / 2, 0.9 * fw / 2, bh / 2])
        g[f"{s}_Thorax"] = _capsule(z0, 0.8 * off[f"{s}_Shoulder"], r_of(circ.thorax))
        g[f"{s}_Shoulder"] = _capsule(0.12 * off[f"{s}_Elbow"], 0.88 * off[f"{s}_Elbow"], r_of(circ.upper_arm))
        # forearm: mid-forearm radius near the elbow, tapering to the wrist's thickness (two capsules)
        wr, k = off[f"{s}_Wrist"], c.forearm_taper
        g[f"{s}_Elbow"] = _capsule(0.08 * wr, k * wr, r_of(circ.forearm)) + _capsule(
            k * wr, 0.88 * wr, c.wrist_half_thickness * HL
        )
        # palm: a box from the wrist to the metacarpal heads, as broad as the MCP spread plus a finger radius
        mcp = np.stack([off[f"{s}_{f}1"] for f in FINGERS if f != "Thumb"])
        rf = circ.finger[0] * HL
        lo = np.array([mcp[:, 0].min() - rf, min(0.0, mcp[:, 1].min()), 0.0])
        hi = np.array([mcp[:, 0].max() + rf, max(0.0, mcp[:, 1].max()), 0.0])
        half = np.array([(hi[0] - lo[0]) / 2, (hi[1] - lo[1]) / 2, c.palm_half_thickness * HL])
        g[f"{s}_Wrist"] = _box((lo + hi) / 2, half)
        for f in FINGERS:
            radii = circ.thumb if f == "Thumb" else circ.finger
            distal = a.hand[f][-1] * HL
            for k in (1, 2, 3):
                name = f"{s}_{f}{k}"
                r = radii[k - 1] * HL
                if k < 3:
                    end = off[f"{s}_{f}{k + 1}"]
                else:  # the distal segment ends at the fingertip: its capsule stops one radius short
                    d = off[name] / np.linalg.norm(off[name])
                    end = d * max(distal - r, 0.2 * distal)
                g[name] = _capsule(z0, end, r)
    return g


def _range(name: str, axis: int) -> str:
    """InterMimic's joint ranges (degrees): body joints free, fingers limited."""
    base = name.split("_", 1)[-1]
    if not base[-1].isdigit():
        return "-180 180"
    k = int(base[-1])
    if base.startswith("Thumb") and k == 1:
        return "-55.625 55.625"
    if base.startswith("Thumb") and k == 2:
        return "-5.625 5.625"
    if axis == 0 and k in (1, 2):
        return "-55.625 55.625"
    if axis == 0 and k == 3:
        return "-90 5.625" if name.startswith("L_") else "-5.625 90"
    return "-5.625 5.625"


def _gain(name: str) -> int:
    base = name.split("_", 1)[-1]
    return 100 if base[-1].isdigit() else _GAINS.get(base, 500)


def humanoid_mjcf(anthropometry: Anthropometry, model: str = "wristmimic_synth") -> str:
    """MJCF text of the synthetic humanoid."""
    off = _offsets(anthropometry)
    geoms = _geoms(anthropometry, off)

    def body(b: int, depth: int) -> list[str]:
        name, pad = BODY_NAMES[b], "  " * depth
        lines = [f'{pad}<body name="{name}" pos="{_f(off[name])}">']
        if b == 0:
            lines.append(f'{pad}  <freejoint name="{name}"/>')
        lines.append(f"{pad}  {geoms[name]}")
        for ax in range(3 if b else 0):
            k = _gain(name)
            axis = ("1 0 0", "0 1 0", "0 0 1")[ax]
            lines.append(
                f'{pad}  <joint name="{name}_{"xyz"[ax]}" type="hinge" pos="0 0 0" axis="{axis}" stiffness="{k}" '
                f'damping="{k // 10}" armature="0.02" range="{_range(name, ax)}"/>'
            )
        for kid in np.flatnonzero(PARENTS == b):
            lines += body(int(kid), depth + 1)
        return [*lines, f"{pad}</body>"]

    head = [
        f'<mujoco model="{model}">',
        "  <!-- generated by wristmimic.synth.humanoid; proportions: Drillis & Contini (1966) via Winter (2009),",
        f"       hand: Buchholz et al. (1992); stature {anthropometry.height:.3f} m -->",
        '  <compiler angle="degree"/>',
        "  <default>",
        '    <joint limited="true"/>',
        '    <geom contype="1" conaffinity="1" condim="3" density="1000" margin="0.001" rgba="0.8 0.6 .4 1"/>',
        "  </default>",
        "  <worldbody>",
        '    <geom name="floor" type="plane" size="100 100 .2" rgba="0.8 0.9 0.8 1"/>',
    ]
    motors = [f'    <motor name="{n}_{a}" joint="{n}_{a}" gear="1"/>' for n in BODY_NAMES[1:] for a in "xyz"]
    tail = ["  </worldbody>", "  <actuator>", *motors, "  </actuator>", "</mujoco>", ""]
    return "\n".join([*head, *body(0, 2), *tail])


def build_humanoid(height: float = 1.70, anthropometry: Anthropometry | None = None) -> SynthHumanoid:
    """The synthetic humanoid of a given stature (or of explicit proportions)."""
    a = anthropometry or Anthropometry(height=height)
    off = _offsets(a)
    HL, c = a.hand_length, a.choices
    h = c.palm_half_thickness * HL
    palm: dict[str, np.ndarray] = {}
    reach = 0.0
    for s, _y in SIDES:
        mcp = np.stack([off[f"{s}_{f}1"] for f in FINGERS if f != "Thumb"])
        p = np.array([mcp[:, 0].mean(), 0.5 * mcp[:, 1].mean(), -h])
        palm[s] = p
        tip = max(abs(off[f"{s}_{f}1"][1]) + (sum(a.hand[f][1:])) * HL for f in FINGERS if f != "Thumb")
        reach = tip - abs(p[1])
    mjcf = humanoid_mjcf(a)
    return SynthHumanoid(mjcf, a, off, palm, h, float(reach), _hand_points(mjcf))


def _hand_points(mjcf: str) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    import mujoco

    m = mujoco.MjModel.from_xml_string(mjcf)
    d = mujoco.MjData(m)
    mujoco.mj_kinematics(m, d)
    out = {}
    for s, _ in SIDES:
        w = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, f"{s}_Wrist")
        bodies = [b for b in range(m.nbody) if b == w or _ancestor(m, b, w)]
        pts, rad = [], []
        for g in np.flatnonzero(np.isin(m.geom_bodyid, bodies)):
            R = d.geom_xmat[g].reshape(3, 3)
            c = d.geom_xpos[g] - d.xpos[w]  # rest pose: the wrist frame is world-aligned
            if m.geom_type[g] == mujoco.mjtGeom.mjGEOM_CAPSULE:
                for sgn in (-1.0, 1.0):
                    pts.append(c + sgn * m.geom_size[g, 1] * R[:, 2])
                    rad.append(m.geom_size[g, 0])
            else:
                for corner in np.array(np.meshgrid([-1, 1], [-1, 1], [-1, 1])).T.reshape(-1, 3):
                    pts.append(c + R @ (corner * m.geom_size[g, :3]))
                    rad.append(0.0)
        out[s] = (np.asarray(pts), np.asarray(rad))
    return out


def _ancestor(m, b: int, a: int) -> bool:
    while b > 0:
        b = int(m.body_parentid[b])
        if b == a:
            return True
    return False
