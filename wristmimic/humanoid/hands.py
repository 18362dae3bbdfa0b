"""Hand embodiments: a library of hands and the swap of a humanoid's hands at its wrist bodies.

WristMimic gives fingers no pose targets, so any hand can sit on the wrist and learn its own grasp (the paper's
hand-morphology study, Table 4). :func:`swap_hands` writes a canonical file holding one sequence whose humanoid
carries another hand; the body, wrist and object reference is unchanged.

**Hands.** A hand is a palm body and its subtree of finger bodies, each finger body with three hinges x, y, z at
its origin (the humanoid's joint layout) and primitive collision geoms (box, capsule, sphere, cylinder,
ellipsoid). Built-in hands (:data:`BUILTIN_HANDS`):

- ``smplx-intermimic``: the SMPL-X hand (3 bodies per finger) with InterMimic's finger joint ranges;
- ``smplx-free``: the same hand with every finger hinge in [-pi, pi] (the paper's scene-specific / OmniGrasp
  setting);
- ``parahome-box``: SkillMimic's ParaHome box hand (CMC, MCP, PIP, DIP per finger; thumb CMC, MCP, IP; 5 mm
  finger capsules, a 7 x 6 x 2 cm palm box) with the ranges the scene gives ParaHome hands (InterMimic's by
  position along each finger chain, metacarpals near-rigid);
- a user MJCF file (``--hand hand.xml --palm NAME``): the subtree of its palm body, with its own joint ranges.

Where the geometry comes from: the SMPL-X hand is the humanoid's own hand when the humanoid is SMPL-X (the
subject's hand: swapping it changes only the ranges), else the synthetic SMPL-X hand of
:mod:`wristmimic.synth.humanoid` (published segment proportions) sized so that its wrist-to-farthest-finger-joint
length equals the humanoid's. The ParaHome box hand is the humanoid's own hand when it is a ParaHome humanoid,
else it is regenerated with :mod:`wristmimic.humanoid.parahome`'s conventions from bone vectors taken from the
humanoid's SMPL-X hand (CMC at 35 % of the wrist-to-MCP offset, MCP, PIP, DIP at the SMPL-X finger joints,
fingertip 80 % of the last bone beyond the DIP).

**Frames.** Every supported humanoid has identity rest rotations and stands in a T-pose with x forward, y left,
z up; the hands extend sideways (right: -y, left: +y), palms down (-z), thumbs forward (+x). A hand is given in
that convention in its palm body's frame, and the palm frame is placed exactly at the wrist body's frame (the
palm body's own position and orientation in a user file are ignored), so the wrist pose of the reference is
unchanged. The wrist keeps its name, parent offset and hinges; its geoms become the palm's geoms and its
children the hand's finger bodies. A user file gives the right hand; the left hand is its reflection across
the sagittal plane (y -> -y in the palm frame): positions (x, -y, z), orientations (w, -x, y, -z), and the x and
z hinges change sign (range [a, b] -> [-b, -a]) while y is kept, so mirrored joint angles (-x, y, -z) give the
mirrored pose. A file that also holds a left hand names its palm with ``left_palm``.

**User hinges.** A finger body may have hinges about its own +-x, +-y or +-z axis at its origin (at most one per
axis, any order) or none; missing axes get the range +-1e-6 rad (locked). Slide, ball and free joints, hinges about
other axes or off the origin, and mesh geoms are refused with a one-line error; visual-only geoms
(contype = conaffinity = 0) are dropped. Geoms keep their shape only: the scene sets density and collision bits.

**Ranges** (``ranges``): ``intermimic`` (InterMimic's by chain position, :func:`wristmimic.scene.finger_ranges`),
``free`` ([-pi, pi]) or ``hand`` (the hand's own; unlimited hinges get [-pi, pi]). The ranges are written into the
humanoid MJCF and the humanoid records ``hand``, so the scene applies them as they are.
"""

from __future__ import annotations

import json
import xml.etree.ElementTree as ET
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import mujoco
import numpy as np

from wristmimic.errors import InputError
from wristmimic.format.records import HumanoidRecord, SequenceRecord
from wristmimic.humanoid.roles import compute_roles, detect_profile
from wristmimic.humanoid.skeleton import Skeleton, load_skeleton

RANGE_MODES = ("intermimic", "free", "hand")


@dataclass(frozen=True)
class BuiltinHand:
    name: str
    geometry: str  # "smplx" or "parahome-box"
    ranges: str  # one of RANGE_MODES
    description: str


BUILTIN_HANDS: dict[str, BuiltinHand] = {
    h.name: h
    for h in (
        BuiltinHand("smplx-intermimic", "smplx", "intermimic", "SMPL-X hand, InterMimic's finger joint ranges"),
        BuiltinHand("smplx-free", "smplx", "free", "SMPL-X hand, every finger hinge in [-pi, pi] (OmniGrasp-style)"),
        BuiltinHand(
            "parahome-box", "parahome-box", "intermimic", "SkillMimic's ParaHome box hand (19 finger bodies per hand)"
        ),
    )
}
"""Built-in hands by name."""
_GEOM_TYPES = {
    int(mujoco.mjtGeom.mjGEOM_BOX): "box",
    int(mujoco.mjtGeom.mjGEOM_CAPSULE): "capsule",
    int(mujoco.mjtGeom.mjGEOM_SPHERE): "sphere",
    int(mujoco.mjtGeom.mjGEOM_CYLINDER): "cylinder",
    int(mujoco.mjtGeom.mjGEOM_ELLIPSOID): "ellipsoid",
}
_NSIZE = {"box": 3, "capsule": 2, "sphere": 1, "cylinder": 2, "ellipsoid": 3}
_MIRROR = np.array([1.0, -1.0, 1.0])
_MIRROR_QUAT = np.array([1.0, -1.0, 1.0, -1.0])
_MIRROR_HINGE = np.array([-1.0, 1.0, -1.0])  # x and z hinge angles change sign, y is kept
LOCKED = np.array([-1e-6, 1e-6])
"""Range (rad) of a hinge a user hand does not have: MuJoCo needs lower < upper, so it is locked to +-1e-6."""
FINGER_GAINS = (100, 10)
"""Stiffness and damping written on new finger hinges (InterMimic's finger gains; the scene re-actuates)."""


@dataclass(frozen=True)
class HandGeom:
    """A primitive collision geom of a hand body (``body`` -1 = the palm), in that body's frame."""

    body: int
    type: str
    size: np.ndarray  # (3,) MuJoCo geom size
    pos: np.ndarray  # (3,)
    quat: np.ndarray  # (4,) wxyz


@dataclass(frozen=True)
class HandSide:
    """One hand in its palm frame: finger bodies (parents precede children), their hinges and geoms."""

    names: tuple[str, ...]
    parents: np.ndarray  # (n,) int, -1 = the palm
    pos: np.ndarray  # (n, 3) offset in the parent frame
    quat: np.ndarray  # (n, 4) wxyz rest orientation in the parent frame
    ranges: np.ndarray  # (n, 3, 2) rad, x, y, z hinge
    geoms: tuple[HandGeom, ...]

    def mirrored(self, names: tuple[str, ...] | None = None) -> HandSide:
        """The reflection across the palm frame's xz plane (y -> -y), see the module docstring."""
        lo, hi = self.ranges[..., 0], self.ranges[..., 1]
        flip = _MIRROR_HINGE[None, :] < 0
        ranges = np.stack([np.where(flip, -hi, lo), np.where(flip, -lo, hi)], axis=-1)
        geoms = tuple(replace(g, pos=g.pos * _MIRROR, quat=g.quat * _MIRROR_QUAT) for g in self.geoms)
        return HandSide(
            names or self.names, self.parents.copy(), self.pos * _MIRROR, self.quat * _MIRROR_QUAT, ranges, geoms
        )

    def renamed(self, names: tuple[str, ...]) -> HandSide:
        return replace(self, names=tuple(names))


@dataclass(frozen=True)
class Hand:
    """A resolved hand for one humanoid: both sides, the ranges mode, its label and where it came from."""

    name: str
    left: HandSide
    right: HandSide
    ranges: str
    source: str


# ----------------------------------------------------------------------------------------------- extraction


def _subtree(model: mujoco.MjModel, root: int) -> list[int]:
    """Model body ids below ``root`` (excluded), in model order (parents precede children)."""
    inside = {root}
    out = []
    for b in range(root + 1, model.nbody):
        if int(model.body_parentid[b]) in inside:
            inside.add(b)
            out.append(b)
    return out


def extract_side(model: mujoco.MjModel, palm: int, source: str | Path | None = None, names=None) -> HandSide:
    """The hand below model body ``palm`` as a :class:`HandSide` (hinges normalised to x, y, z; see module doc)."""
    bodies = _subtree(model, palm)
    slot = {b: i for i, b in enumerate(bodies)}
    body_name = lambda b: mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_BODY, b) or f"body{b}"  # noqa: E731
    ranges = np.tile(LOCKED, (len(bodies), 3, 1))
    for i, b in enumerate(bodies):
        seen: set[int] = set()
        for j in np.flatnonzero(model.jnt_bodyid == b):
            where = f"body {body_name(b)}"
            if model.jnt_type[j] != mujoco.mjtJoint.mjJNT_HINGE:
                raise InputError(source, where, "has a non-hinge joint", "hinges only (finger bodies)")
            axis = model.jnt_axis[j]
            k = int(np.argmax(np.abs(axis)))
            if abs(abs(axis[k]) - 1.0) > 1e-6 or not np.allclose(model.jnt_pos[j], 0.0, atol=1e-9) or k in seen:
                raise InputError(
                    source, where, "hinge not about the body's own x, y or z axis at its origin (or repeated)",
                    "at most one hinge per body axis, at the body origin (add a rotated body frame)",
                )  # fmt: skip
            seen.add(k)
            lo, hi = (model.jnt_range[j] if model.jnt_limited[j] else np.array([-np.pi, np.pi])).astype(float)
            ranges[i, k] = [lo, hi] if axis[k] > 0 else [-hi, -lo]
    geoms = []
    for g in range(model.ngeom):
        b = int(model.geom_bodyid[g])
        if b != palm and b not in slot:
            continue
        if model.geom_contype[g] == 0 and model.geom_conaffinity[g] == 0:
            continue  # visual only
        t = _GEOM_TYPES.get(int(model.geom_type[g]))
        if t is None:
            raise InputError(
                source, f"body {body_name(b)}", f"geom type {mujoco.mjtGeom(model.geom_type[g]).name} not supported",
                "primitive geoms: box, capsule, sphere, cylinder, ellipsoid",
            )  # fmt: skip
        geoms.append(HandGeom(slot.get(b, -1), t, model.geom_size[g].copy(), model.geom_pos[g].copy(),
                              model.geom_quat[g].copy()))  # fmt: skip
    parents = np.array([slot.get(int(model.body_parentid[b]), -1) for b in bodies], dtype=np.int64)
    return HandSide(
        tuple(names) if names is not None else tuple(body_name(b) for b in bodies),
        parents,
        model.body_pos[bodies].copy(),
        model.body_quat[bodies].copy(),
        ranges,
        tuple(geoms),
    )


def _model_body(model: mujoco.MjModel, name: str) -> int:
    return mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, name)


# ---------------------------------------------------------------------------------------------- built-ins


def _hand_reach(skel: Skeleton, wrist: int) -> float:
    """Distance from the wrist to its farthest finger joint in the rest pose (m)."""
    far, stack = 0.0, [(wrist, np.zeros(3))]
    while stack:
        b, p = stack.pop()
        far = max(far, float(np.linalg.norm(p)))
        stack += [(c, p + skel.rest_pos[c]) for c in skel.children(b)]
    return far


def current_hand(family: str, hand: str = "") -> str:
    """Geometry of the hand a humanoid has now: ``smplx``, ``parahome-box`` or ``custom`` (a user MJCF hand)."""
    if hand:
        base = hand.split("/")[0]
        return BUILTIN_HANDS[base].geometry if base in BUILTIN_HANDS else "custom"
    return {"smplx": "smplx", "parahome": "parahome-box"}.get(family, "custom")


def _smplx_hands(skel: Skeleton, current: str, wrists: tuple[int, int]) -> tuple[HandSide, HandSide, str]:
    """Left and right SMPL-X hands: the humanoid's own (if it has one) or the synthetic one sized to it."""
    if current == "smplx":
        model, src, wl, wr = skel.model, "the humanoid's own SMPL-X hand", wrists[0] + 1, wrists[1] + 1
    else:
        from wristmimic.synth.humanoid import build_humanoid

        ref = load_skeleton(build_humanoid(1.70).mjcf)
        reach = np.mean([_hand_reach(skel, w) for w in wrists])
        base = np.mean([_hand_reach(ref, ref.index(n)) for n in ("L_Wrist", "R_Wrist")])
        height = float(np.clip(1.70 * reach / base, 1.2, 2.2))
        model = mujoco.MjModel.from_xml_string(build_humanoid(height).mjcf)
        src = f"wristmimic.synth SMPL-X hand (stature {height:.3f} m, sized to the humanoid's hand)"
        wl, wr = _model_body(model, "L_Wrist"), _model_body(model, "R_Wrist")
    return extract_side(model, wl, src), extract_side(model, wr, src), src


_SMPLX_TO_PARAHOME = {"Index": "Second", "Middle": "Third", "Ring": "Fourth", "Pinky": "Fifth"}


def _parahome_box_side(skel: Skeleton, wrist: int, side: str, prefix: str) -> HandSide:
    """ParaHome box hand generated from the humanoid's SMPL-X hand joints (see module doc)."""
    from wristmimic.humanoid import parahome as P

    off = {skel.body_names[b]: skel.rest_pos[b] for b in skel.subtree(wrist)}
    bones: dict[tuple[str, str], np.ndarray] = {}
    for finger, ordinal in [("Thumb", "First"), *_SMPLX_TO_PARAHOME.items()]:
        names = [f"{prefix}{finger}{k}" for k in (1, 2, 3)]
        if not all(n in off for n in names):
            raise InputError(None, f"body {names[0]}", "SMPL-X finger chain missing", "an SMPL-X hand")
        chain = P._finger_chain(side, ordinal)
        o = [off[n] for n in names]
        if ordinal == "First":
            pts = o  # CMC, MCP, IP at the SMPL-X thumb joints
        else:
            pts = [0.35 * o[0], 0.65 * o[0], o[1], o[2]]
        parent = f"j{side}Wrist"
        for body, v in zip(chain, pts, strict=True):
            bones[(parent, body)] = np.asarray(v, dtype=float)
            parent = body
        bones[(parent, P.TIPS[parent])] = 0.8 * np.asarray(pts[-1], dtype=float)
    lines = ['<mujoco><compiler angle="radian"/><worldbody>', f'<body name="j{side}Wrist">',
             P._geom(f"j{side}Wrist", np.zeros(3))]  # fmt: skip

    def body(name: str) -> list[str]:
        kids = [c for c, p in P.TREE if p == name]
        end = bones[(name, kids[0])] if kids else bones[(name, P.TIPS[name])]
        out = [f'<body name="{name}" pos="{P._f(bones[(P.PARENT[name], name)])}">', P._geom(name, end)]
        out += [f'<joint name="{name}_{a}" type="hinge" axis="{v}" range="-3.14159 3.14159" limited="true"/>'
                for a, v in (("x", "1 0 0"), ("y", "0 1 0"), ("z", "0 0 1"))]  # fmt: skip
        for c in kids:
            out += body(c)
        return [*out, "</body>"]

    for c in [c for c, p in P.TREE if p == f"j{side}Wrist"]:
        lines += body(c)
    lines += ["</body></worldbody></mujoco>"]
    model = mujoco.MjModel.from_xml_string("\n".join(lines))
    return extract_side(model, _model_body(model, f"j{side}Wrist"))


def _parahome_hands(skel: Skeleton, current: str, wrists: tuple[int, int]) -> tuple[HandSide, HandSide, str]:
    if current == "parahome-box":
        src = "the humanoid's own ParaHome box hand"
        return extract_side(skel.model, wrists[0] + 1, src), extract_side(skel.model, wrists[1] + 1, src), src
    if current != "smplx":
        raise InputError(
            None, "hand parahome-box", f"cannot be built from the humanoid's {current} hand",
            "a humanoid with an SMPL-X or ParaHome hand",
        )  # fmt: skip
    left = _parahome_box_side(skel, wrists[0], "Left", "L_")
    right = _parahome_box_side(skel, wrists[1], "Right", "R_")
    return left, right, "ParaHome box hand regenerated from the humanoid's SMPL-X hand joints"


def _mjcf_hands(
    path: Path, palm: str, left_palm: str | None, wrist_names: tuple[str, str]
) -> tuple[HandSide, HandSide, str]:
    if not path.is_file():
        raise InputError(path, None, "hand MJCF not found", f"a built-in hand ({', '.join(BUILTIN_HANDS)}) or a file")
    try:
        model = mujoco.MjModel.from_xml_path(str(path))
    except Exception as exc:  # noqa: BLE001 - MuJoCo raises ValueError with the compiler's message
        raise InputError(path, "mjcf", f"MuJoCo cannot compile it: {str(exc).splitlines()[0]}") from None
    pid = _model_body(model, palm)
    if pid < 0:
        raise InputError(path, f"body {palm}", "palm body not found", "the palm body's name (--palm)")
    right = extract_side(model, pid, path)
    if not right.names:
        raise InputError(path, f"body {palm}", "palm body has no finger bodies below it", "a hand: palm + fingers")
    rnames = tuple(f"{wrist_names[1]}_{n}" for n in right.names)
    if left_palm:
        lid = _model_body(model, left_palm)
        if lid < 0:
            raise InputError(path, f"body {left_palm}", "left palm body not found", "the left palm's name")
        left = extract_side(model, lid, path)
        left = left.renamed(tuple(f"{wrist_names[0]}_{n}" for n in left.names))
        how = f"{path.name} (palms {palm}, {left_palm})"
    else:
        left = right.mirrored(tuple(f"{wrist_names[0]}_{n}" for n in right.names))
        how = f"{path.name} (palm {palm}; left = mirrored right)"
    return left, right.renamed(rnames), how


def resolve_hand(
    hand: str | Path,
    skel: Skeleton,
    family: str,
    roles: dict[str, np.ndarray],
    *,
    current: str | None = None,
    palm: str = "palm",
    left_palm: str | None = None,
    ranges: str | None = None,
) -> Hand:
    """A built-in hand name or an MJCF path -> both sides of that hand for this humanoid (``current``: the geometry
    of the hand it has now, :func:`current_hand`; default from the family)."""
    wrists = (int(roles["wrists"][0]), int(roles["wrists"][1]))
    if ranges is not None and ranges not in RANGE_MODES:
        raise InputError(None, "--ranges", f"{ranges!r}", f"one of {', '.join(RANGE_MODES)}")
    name = str(hand)
    if name in BUILTIN_HANDS:
        b = BUILTIN_HANDS[name]
        build = _smplx_hands if b.geometry == "smplx" else _parahome_hands
        left, right, src = build(skel, current or current_hand(family), wrists)
        mode = ranges or b.ranges
        label = name if mode == b.ranges else f"{name}/{mode}"
        return Hand(label, left, right, mode, src)
    path = Path(hand)
    if path.suffix.lower() != ".xml" and not path.exists():
        raise InputError(None, "--hand", f"unknown hand {name!r}", f"one of {', '.join(BUILTIN_HANDS)} or an MJCF file")
    left, right, src = _mjcf_hands(path, palm, left_palm, (skel.body_names[wrists[0]], skel.body_names[wrists[1]]))
    mode = ranges or "hand"
    label = path.stem if mode == "hand" else f"{path.stem}/{mode}"
    return Hand(label, left, right, mode, src)


# ------------------------------------------------------------------------------------------------ grafting


def _f(v: np.ndarray | float) -> str:
    return " ".join(f"{float(x):.12g}" for x in np.atleast_1d(v))


def _degrees(root: ET.Element) -> bool:
    c = root.find("compiler")
    return c is None or c.get("angle", "degree") != "radian"


def _side_elements(side: HandSide, deg: bool) -> tuple[list[ET.Element], list[ET.Element]]:
    """(palm geoms, top-level finger body elements) of one hand."""
    bodies = []
    for i, n in enumerate(side.names):
        el = ET.Element("body", {"name": n, "pos": _f(side.pos[i]), "quat": _f(side.quat[i])})
        bodies.append(el)
    for i, el in enumerate(bodies):
        for g in side.geoms:
            if g.body == i:
                el.append(_geom_el(g))
        for k, a in enumerate("xyz"):
            rng = np.rad2deg(side.ranges[i, k]) if deg else side.ranges[i, k]
            el.append(ET.Element("joint", {
                "name": f"{side.names[i]}_{a}", "type": "hinge", "pos": "0 0 0", "axis": _f(np.eye(3)[k]),
                "limited": "true", "range": _f(rng), "stiffness": str(FINGER_GAINS[0]),
                "damping": str(FINGER_GAINS[1]), "armature": "0.02",
            }))  # fmt: skip
    top = []
    for i, el in enumerate(bodies):  # parents precede children, so each body's geoms and joints come first
        p = int(side.parents[i])
        if p < 0:
            top.append(el)
        else:
            bodies[p].append(el)
    return [_geom_el(g) for g in side.geoms if g.body == -1], top


def _geom_el(g: HandGeom) -> ET.Element:
    return ET.Element("geom", {"type": g.type, "size": _f(g.size[: _NSIZE[g.type]]), "pos": _f(g.pos),
                               "quat": _f(g.quat)})  # fmt: skip


def graft_hands(mjcf: str, wrist_names: tuple[str, str], hand: Hand) -> str:
    """The humanoid MJCF with each wrist's geoms and finger subtree replaced by the hand's palm geoms and fingers.

    Everything else is kept as written; actuators, sensors, contact pairs/excludes, equalities and tendons that
    name a removed body, joint, geom or site are dropped, keyframes are dropped (their qpos size changes), and
    each new hinge gets an actuator like the wrist's.
    """
    root = ET.fromstring(mjcf)
    deg = _degrees(root)
    removed: set[str] = set()
    new_joints: list[str] = []
    tmpl: ET.Element | None = None  # the actuator of a wrist hinge: new hinges get one like it
    by_name = {el.get("name"): el for el in root.iter("body")}
    taken = set(by_name)
    for wname, side in zip(wrist_names, (hand.left, hand.right), strict=True):
        w = by_name.get(wname)
        if w is None:
            raise InputError(None, f"body {wname}", "wrist body not found in the humanoid MJCF")
        for child in list(w):
            if child.tag in ("body", "geom"):
                for el in child.iter():
                    if el.get("name"):
                        removed.add(el.get("name"))
                w.remove(child)
        taken -= removed
        clash = sorted(set(side.names) & taken)
        if clash:
            raise InputError(None, f"body {clash[0]}", "hand body name already used by the humanoid", "unique names")
        taken |= set(side.names)
        geoms, top = _side_elements(side, deg)
        kids = [c for c in w]
        insert_at = max([i + 1 for i, c in enumerate(kids) if c.tag in ("joint", "freejoint", "inertial")] or [0])
        for k, g in enumerate(geoms):
            w.insert(insert_at + k, g)
        for b in top:
            w.append(b)
        new_joints += [f"{n}_{a}" for n in side.names for a in "xyz"]
    wrist_joints = {f"{n}_x" for n in wrist_names}
    for section in ("actuator", "sensor", "contact", "equality", "tendon"):
        for sec in root.findall(section):
            for el in list(sec):
                refs = {v for e in el.iter() for k, v in e.attrib.items() if k != "name"}
                if refs & removed:
                    sec.remove(el)
                elif section == "actuator" and el.get("joint") in wrist_joints and tmpl is None:
                    tmpl = el
    for kf in root.findall("keyframe"):
        root.remove(kf)
    act = root.find("actuator")
    if act is not None:
        tag = tmpl.tag if tmpl is not None else "motor"
        attrs = {
            k: v for k, v in (tmpl.attrib if tmpl is not None else {"gear": "1"}).items() if k not in ("name", "joint")
        }
        for j in new_joints:
            act.append(ET.Element(tag, {"name": j, "joint": j, **attrs}))
    ET.indent(root, space="  ")
    return ET.tostring(root, encoding="unicode") + "\n"


def _with_ranges(side: HandSide, ranges: np.ndarray) -> HandSide:
    return replace(side, ranges=ranges)


def build_swapped_humanoid(hum: HumanoidRecord, hand: Hand, hid: str, source: str) -> tuple[HumanoidRecord, Skeleton]:
    """The humanoid record with ``hand`` on both wrists (ranges applied), its skeleton and recomputed roles."""
    skel = load_skeleton(hum.mjcf, source)
    profile = detect_profile(skel, source)
    wrist_names = (profile.left_wrist, profile.right_wrist)
    if hand.ranges == "free":

        def full(side: HandSide) -> HandSide:
            return _with_ranges(side, np.tile([-np.pi, np.pi], (len(side.names), 3, 1)))

        hand = replace(hand, left=full(hand.left), right=full(hand.right))
    mjcf = graft_hands(hum.mjcf, wrist_names, hand)
    new = load_skeleton(mjcf, f"{source} with hand {hand.name}")
    roles = compute_roles(new, detect_profile(new, source))
    if hand.ranges == "intermimic":
        from wristmimic.scene import finger_ranges

        fr = finger_ranges(new, roles)  # chains follow first children: bodies off them keep the hand's own

        def pick(side: HandSide) -> HandSide:
            own = zip(side.names, side.ranges, strict=True)
            return _with_ranges(side, np.stack([fr.get(new.index(n), r) for n, r in own]))

        hand = replace(hand, left=pick(hand.left), right=pick(hand.right))
        mjcf = graft_hands(hum.mjcf, wrist_names, hand)
        new = load_skeleton(mjcf, f"{source} with hand {hand.name}")
    rec = HumanoidRecord(
        name=hid,
        family=profile.family,
        mjcf=mjcf,
        body_names=list(new.body_names),
        parents=new.parents,
        joint_bodies=new.joint_bodies,
        roles=roles,
        source_file=hum.source_file,
        hand=hand.name,
        hand_source=hand.source,
        hand_ranges=hand.ranges,
    )
    return rec, new


# ------------------------------------------------------------------------------------------------ sequence


def swap_sequence(
    seq: SequenceRecord,
    old: Skeleton,
    old_roles: dict[str, np.ndarray],
    new: Skeleton,
    new_roles: dict[str, np.ndarray],
) -> SequenceRecord:
    """The sequence re-indexed to the new body list (see ``docs/format.md``, "Swapped hands").

    Non-finger bodies and joints are copied. New finger joints are at rest (angle 0, clipped into the range,
    identity rotation); their body poses are forward kinematics of the new humanoid under the reference
    wrist; ``source_body_pos`` = that pose, not valid. Contact labels of a new finger body: 1 where the
    hand-level flag ``contacts/hand`` of its side is set, else the wrist's label; geometric labels the same rule
    with the hand's geometric flag (any old hand body geometric 1); distance: the closest old hand body's.
    """
    from wristmimic.humanoid.kinematics import forward_kinematics, joint_quat_from_hinges, qpos_from

    T = seq.num_frames
    old_idx = {n: i for i, n in enumerate(old.body_names)}
    old_fingers = set(old_roles["fingers"].tolist())
    keep = {b: old_idx[n] for b, n in enumerate(new.body_names) if n in old_idx and old_idx[n] not in old_fingers}
    new_fingers = [b for b in range(new.num_bodies) if b not in keep]
    if sorted(new_fingers) != sorted(new_roles["fingers"].tolist()):
        raise AssertionError("non-finger bodies of the two humanoids differ")  # a bug, not bad input
    old_joint = {int(b): j for j, b in enumerate(old.joint_bodies)}
    jmap = [(j, old_joint.get(keep.get(int(b), -1))) for j, b in enumerate(new.joint_bodies)]
    angles = np.zeros((T, new.num_joints, 3), dtype=np.float64)
    for j, oj in jmap:
        if oj is not None:
            angles[:, j] = seq.joint_angles[:, oj]
        else:
            angles[:, j] = np.clip(0.0, new.joint_range[j, :, 0], new.joint_range[j, :, 1])
    jquat = joint_quat_from_hinges(angles)
    for j, oj in jmap:
        if oj is not None:
            jquat[:, j] = seq.joint_quat[:, oj]
    fk = forward_kinematics(new.model, qpos_from(new, seq.root_pos.astype(float), seq.root_quat.astype(float), angles))

    def per_body(old_a: np.ndarray, fill: np.ndarray) -> np.ndarray:
        out = np.array(fill, dtype=old_a.dtype, copy=True)
        for b, ob in keep.items():
            out[:, b] = old_a[:, ob]
        return out

    hand_of = {}
    for s, side in enumerate(("left", "right")):
        for b in new_roles[f"{side}_fingers"]:
            hand_of[int(b)] = (s, old_idx[new.body_names[int(new_roles["wrists"][s])]], old_roles[f"{side}_hand"])
    labels = per_body(seq.contact_labels, np.zeros((T, new.num_bodies), np.int8))
    geometric = per_body(seq.contact_geometric, np.zeros((T, new.num_bodies), np.int8))
    distance = per_body(seq.contact_distance, np.full((T, new.num_bodies), np.inf, np.float32))
    for b, (s, w, old_hand) in hand_of.items():
        labels[:, b] = np.where(seq.hand_contact[:, s], 1, seq.contact_labels[:, w])
        geo_flag = (seq.contact_geometric[:, old_hand] == 1).any(axis=1)
        geometric[:, b] = np.where(geo_flag, 1, seq.contact_geometric[:, w])
        distance[:, b] = seq.contact_distance[:, old_hand].min(axis=1)
    valid = np.zeros(new.num_bodies, dtype=bool)
    for b, ob in keep.items():
        valid[b] = seq.source_body_pos_valid[ob]
    return replace(
        seq,
        joint_quat=jquat.astype(np.float32),
        joint_angles=angles.astype(np.float32),
        body_pos=per_body(seq.body_pos, fk.body_pos),
        body_quat=per_body(seq.body_quat, fk.body_quat),
        source_body_pos=per_body(seq.source_body_pos, fk.body_pos),
        source_body_pos_valid=valid,
        contact_labels=labels,
        contact_geometric=geometric,
        contact_distance=distance,
    )


# ---------------------------------------------------------------------------------------------------- swap


@dataclass
class SwapResult:
    out: Path
    sequence_id: str
    humanoid_id: str
    hand: str
    hand_source: str
    num_bodies: tuple[int, int]
    """Bodies before and after."""
    num_fingers: tuple[int, int]
    """Finger bodies before and after (both hands)."""
    wrist_deviation: tuple[float, float]
    """Max wrist position (m) and rotation (rad) difference under reference replay, before vs after."""


def swap_hands(
    dataset: str | Path,
    sequence_id: str,
    hand: str | Path,
    out: str | Path,
    *,
    palm: str = "palm",
    left_palm: str | None = None,
    ranges: str | None = None,
) -> SwapResult:
    """Write ``out`` (atomically): sequence ``sequence_id`` of ``dataset`` with both hands of its humanoid
    replaced by ``hand`` (a built-in name or an MJCF path), its objects, and the humanoid's new roles."""
    from wristmimic.format.reader import open_dataset
    from wristmimic.format.validate import check_sequence
    from wristmimic.format.writer import DatasetWriter
    from wristmimic.safe_io import sha256_file

    dataset, out = Path(dataset), Path(out)
    if out.resolve() == dataset.resolve():
        raise InputError(out, None, "is the input file", "another output path")
    with open_dataset(dataset) as ds:
        check_sequence(ds, sequence_id)
        view = ds.sequence(sequence_id)
        hum = ds.humanoid(view.humanoid_id)
        where = f"{dataset}:humanoids/{view.humanoid_id}"
        old = load_skeleton(hum.mjcf, where)
        kind = current_hand(hum.family, hum.hand)
        h = resolve_hand(hand, old, hum.family, hum.roles, current=kind, palm=palm, left_palm=left_palm, ranges=ranges)
        hid = f"{view.humanoid_id}+{h.name.replace('/', '-')}"
        rec, new = build_swapped_humanoid(hum, h, hid, where)
        seq = view.load()
        objects = {oid: ds.object(oid) for oid in view.object_ids}
        attrs = ds.attrs
    swapped = swap_sequence(seq, old, hum.roles, new, rec.roles)
    swapped.humanoid_id = hid
    info: dict[str, Any] = {"source_file": dataset.name, "sequence": sequence_id, "hand": h.name,
                            "hand_source": h.source, "ranges": h.ranges, "from_humanoid": view.humanoid_id}  # fmt: skip
    swapped.extra = {**seq.extra, "hand_swap": info}
    inputs = {dataset.name: sha256_file(dataset)}
    if Path(hand).suffix.lower() == ".xml" and Path(hand).is_file():
        inputs[Path(hand).name] = sha256_file(Path(hand))
    extra = {"hand_swap": info}
    if "synth" in attrs:
        extra["synth"] = json.loads(attrs["synth"]) if isinstance(attrs["synth"], str) else attrs["synth"]
    with DatasetWriter(
        out,
        source_dataset=str(attrs.get("source_dataset", "")),
        source_format=str(attrs.get("source_format", "")),
        converter="swap-hands",
        input_sha256=inputs,
        extra_attrs=extra,
    ) as w:
        w.add_humanoid(hid, rec)
        for oid, o in objects.items():
            w.add_object(oid, o)
        w.add_sequence(sequence_id, swapped)
    dev = wrist_replay_deviation(old, seq, new, swapped, (hum.roles["wrists"], rec.roles["wrists"]))
    return SwapResult(
        out, sequence_id, hid, h.name, h.source, (old.num_bodies, new.num_bodies),
        (len(hum.roles["fingers"]), len(rec.roles["fingers"])), dev,
    )  # fmt: skip


def wrist_replay_deviation(
    a: Skeleton, seq_a: SequenceRecord, b: Skeleton, seq_b: SequenceRecord, wrists: tuple[np.ndarray, np.ndarray]
) -> tuple[float, float]:
    """Max world wrist position (m) and rotation (rad) difference between kinematic replays (MuJoCo FK of the
    stored root pose and joint angles) of two humanoids' references; ``wrists`` = each one's wrist indices."""
    from wristmimic.humanoid.kinematics import forward_kinematics, qpos_from
    from wristmimic.rotations import quat_conj, quat_mul

    def replay(s: Skeleton, q: SequenceRecord, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        qpos = qpos_from(s, q.root_pos.astype(float), q.root_quat.astype(float), q.joint_angles.astype(float))
        fk = forward_kinematics(s.model, qpos)
        return fk.body_pos[:, w], fk.body_quat[:, w]

    pa, qa = replay(a, seq_a, np.asarray(wrists[0]))
    pb, qb = replay(b, seq_b, np.asarray(wrists[1]))
    rel = quat_mul(quat_conj(qa), qb)  # 2 asin |v| is exact near 0, where acos of the dot product is not
    angle = 2.0 * np.arcsin(np.clip(np.linalg.norm(rel[..., 1:], axis=-1), 0.0, 1.0))
    return float(np.abs(pa - pb).max()), float(angle.max())
