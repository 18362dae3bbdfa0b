"""The ParaHome humanoid generated from a subject's ``bone_vectors.pkl`` (SkillMimic's 61-body layout).

``bone_vectors.pkl`` (raw ParaHome, one per sequence) is ``{'body' | 'lhand' | 'rhand': {parent: {child:
(3,) vector}}}``: T-pose offsets of each joint from its parent in the body frame (+x forward, +y left, +z up),
metres. Every body's MJCF ``pos`` is its bone vector and its rest orientation is the identity, so joint
rotations are ``parent^-1 * child`` of the ParaHome global orientations. Bodies, order, joint names
(``<body>_x|_y|_z``), PD gains and geoms follow SkillMimic-V2's per-subject humanoids (61 bodies: 23 body joints +
2 x 19 hand joints, no fingertip bodies; fingertip vectors only size the last finger capsule):

- capsules along the bone to the child, radius per part (spine 3 cm, neck 2 cm, clavicle 4 cm, upper arm
  3.6 cm, forearm 3.4 cm ending 6.6 cm short of the wrist, fingers 5 mm, thigh 6.05 cm, shin 5.33 cm ending
  6.4 cm short of the ankle);
- boxes for wrists (palm), ankles (foot) and balls of the feet; a sphere for the pelvis and the chest; a
  cylinder for the head. Densities: pelvis 4629.6, thighs 2040.8, shins 1234.6, everything else 1000 kg/m^3.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

import numpy as np

from wristmimic.errors import InputError

_SPINE = ("jL5S1", "jL4L3", "jL1T12", "jT9T8", "jT1C7", "jC1Head")
_ORDINALS = ("First", "Second", "Third", "Fourth", "Fifth")


def _finger_chain(side: str, ordinal: str) -> tuple[str, ...]:
    if ordinal == "First":
        return (f"j{side}FirstCMC", f"j{side}FirstMCP", f"j{side}IP")
    return tuple(f"j{side}{ordinal}{j}" for j in ("CMC", "MCP", "PIP", "DIP"))


def _tree() -> list[tuple[str, str | None]]:
    """(body, parent) in MuJoCo (depth-first) order."""
    t: list[tuple[str, str | None]] = [("pHipOrigin", None)]
    t += list(zip(_SPINE, ("pHipOrigin", *_SPINE[:-1]), strict=True))
    for side in ("Right", "Left"):
        arm = (f"j{side}T4Shoulder", f"j{side}Shoulder", f"j{side}Elbow", f"j{side}Wrist")
        t += list(zip(arm, ("jT9T8", *arm[:-1]), strict=True))
        for o in _ORDINALS:
            ch = _finger_chain(side, o)
            t += list(zip(ch, (f"j{side}Wrist", *ch[:-1]), strict=True))
    for side in ("Right", "Left"):
        leg = (f"j{side}Hip", f"j{side}Knee", f"j{side}Ankle", f"j{side}BallFoot")
        t += list(zip(leg, ("pHipOrigin", *leg[:-1]), strict=True))
    return t


TREE = _tree()
BODY_NAMES: tuple[str, ...] = tuple(n for n, _ in TREE)
"""The 61 bodies in MuJoCo order (SkillMimic-V2's ParaHome humanoid)."""
PARENT: dict[str, str | None] = dict(TREE)
TIPS = {_finger_chain(s, o)[-1]: f"p{s}{o}Tip" for s in ("Left", "Right") for o in _ORDINALS}
"""Last finger body -> its fingertip point in ``bone_vectors.pkl`` (sizes the last capsule)."""
_BODY_MOTORS = (
    "jL5S1 jRightHip jLeftHip jL4L3 jL1T12 jT9T8 jT1C7 jRightT4Shoulder jLeftT4Shoulder jC1Head jRightShoulder "
    "jRightElbow jRightWrist jLeftShoulder jLeftElbow jLeftWrist jRightKnee jRightAnkle jRightBallFoot jLeftKnee "
    "jLeftAnkle jLeftBallFoot"
).split()
ACTUATOR_ORDER: tuple[str, ...] = tuple(
    _BODY_MOTORS
    + [
        n
        for side in ("Left", "Right")
        for n in (
            [_finger_chain(side, o)[0] for o in _ORDINALS]
            + [m for o in ("Fifth", "Fourth", "Third", "Second") for m in _finger_chain(side, o)[1:]]
            + list(_finger_chain(side, "First")[1:])
        )
    ]
)
"""Motor order of SkillMimic's humanoids (the order of ``bone_vectors.pkl``)."""


def read_bone_vectors(path: str | Path) -> dict[tuple[str, str], np.ndarray]:
    """``{(parent, child): (3,) float64}`` from a raw ParaHome ``bone_vectors.pkl`` (restricted unpickling)."""
    from wristmimic.safe_io import safe_pickle_load

    path = Path(path)
    data = safe_pickle_load(path)
    if not isinstance(data, Mapping):
        raise InputError(path, "<root>", f"holds a {type(data).__name__}", "a dict with 'body', 'lhand', 'rhand'")
    bones: dict[tuple[str, str], np.ndarray] = {}
    for part in ("body", "lhand", "rhand"):
        tree = data.get(part)
        if not isinstance(tree, Mapping):
            raise InputError(path, part, "missing or not a dict", "{parent: {child: (3,) vector}}")
        for parent, children in tree.items():
            if not isinstance(children, Mapping):
                raise InputError(path, f"{part}/{parent}", "not a dict", "{child: (3,) vector}")
            for child, vec in children.items():
                v = np.asarray(vec, dtype=np.float64).reshape(-1)
                if v.shape != (3,) or not np.isfinite(v).all() or np.linalg.norm(v) > 1.5:
                    raise InputError(path, f"{part}/{parent}/{child}", f"bad bone vector {vec!r}", "3 finite metres")
                bones[(str(parent), str(child))] = v
    check_bones(bones, path)
    return bones


def _bone_key(parent: str, body: str) -> str:
    finger = any(k in body for k in ("CMC", "MCP", "PIP", "DIP", "IP")) or body.startswith("p")
    part = ("lhand" if "Left" in body else "rhand") if finger else "body"
    return f"{part}/{parent}/{body}"


def check_bones(bones: Mapping[tuple[str, str], np.ndarray], source: str | Path | None = None) -> None:
    """Raise :class:`InputError` naming the first missing (parent, child) bone of the 61-body tree."""
    for body, parent in TREE[1:]:
        if (parent, body) not in bones:
            raise InputError(source, _bone_key(str(parent), body), "bone vector missing", "the 61-body ParaHome tree")


def _f(v: np.ndarray | float) -> str:
    return " ".join(f"{float(x):.10g}" for x in np.atleast_1d(v))


_DENSITY = {"Hip": 2040.816327, "Knee": 1234.567901}
_CAPSULES = {  # part -> (radius, start offset along the bone axis, shortening of the end)
    "spine": (0.03, 0.0, 0.0),
    "jT1C7": (0.02, 0.03, 0.0),
    "T4Shoulder": (0.04, 0.05, 0.0),
    "Shoulder": (0.036, 0.05, 0.0),
    "Elbow": (0.034, 0.05, 0.066),
    "finger": (0.005, 0.0, 0.0),
    "Hip": (0.0605, 0.08, 0.0),
    "Knee": (0.0533, 0.1, 0.064),
}


def _part(body: str) -> str:
    if body in ("pHipOrigin", "jT9T8", "jT1C7", "jC1Head"):
        return body
    if body in _SPINE:
        return "spine"
    side = "Left" if "Left" in body else "Right"
    key = body.removeprefix(f"j{side}")
    return key if key in ("T4Shoulder", "Shoulder", "Elbow", "Wrist", "Hip", "Knee", "Ankle", "BallFoot") else "finger"


def _geom(body: str, end: np.ndarray) -> str:
    """The body's collision geom; ``end`` = child offset (or fingertip) in the body frame."""
    part = _part(body)
    if part == "pHipOrigin":
        return '<geom type="sphere" density="4629.6296296296305" size="0.07011" pos="0 0 0"/>'
    if part == "jT9T8":
        return '<geom type="sphere" density="1000" size="0.05011" pos="0 0 0.05"/>'
    if part == "jC1Head":
        return '<geom type="cylinder" density="1000" fromto="0 0 0 0 0 0.15" size="0.05"/>'
    if part == "Wrist":
        return '<geom type="box" density="1000" pos="0 0 0" size="0.035 0.03 0.01"/>'
    if part == "Ankle":
        return '<geom type="box" density="1000" pos="0.04 0 -0.03" size="0.1 0.05 0.03"/>'
    if part == "BallFoot":
        return '<geom type="box" density="1000" pos="0 0 0.02" size="0.01 0.05 0.01"/>'
    radius, start, short = _CAPSULES["spine" if body == "jL5S1" else part]
    axis = int(np.argmax(np.abs(end)))  # bones run along one body axis in the T-pose
    a, b = np.zeros(3), np.asarray(end, dtype=np.float64).copy()
    a[axis] = start * np.sign(end[axis])
    b[axis] -= short * np.sign(end[axis])
    if body == "jL5S1":
        a[:] = (0.0, 0.0, 0.02)
    dens = _DENSITY.get(part, 1000)
    return f'<geom type="capsule" density="{dens}" fromto="{_f(np.concatenate([a, b]))}" size="{radius}"/>'


def _joints(body: str) -> list[str]:
    return [
        f'<joint name="{body}_{ax}" type="hinge" pos="0 0 0" axis="{a}" stiffness="500" damping="500" '
        'armature="0.02" range="-180 180"/>'
        for ax, a in (("x", "1 0 0"), ("y", "0 1 0"), ("z", "0 0 1"))
    ]


def _body_xml(body: str, bones: Mapping[tuple[str, str], np.ndarray], depth: int) -> list[str]:
    pad = "  " * depth
    parent = PARENT[body]
    pos = np.zeros(3) if parent is None else bones[(parent, body)]
    kids = [c for c, p in TREE if p == body]
    end = bones[(body, kids[0])] if kids else bones.get((body, TIPS.get(body, "")), 0.8 * pos)
    lines = [f'{pad}<body name="{body}" pos="{_f(pos)}">']
    inner = [f'<freejoint name="{body}"/>'] if parent is None else []
    inner += [_geom(body, np.asarray(end, dtype=np.float64))] + ([] if parent is None else _joints(body))
    lines += [f"{pad}  {x}" for x in inner]
    for c in kids:
        lines += _body_xml(c, bones, depth + 1)
    return [*lines, f"{pad}</body>"]


def parahome_mjcf(bones: Mapping[tuple[str, str], np.ndarray], model: str = "parahome") -> str:
    """MJCF text of the 61-body humanoid with body offsets = ``bones`` ({(parent, child): (3,) vector})."""
    check_bones(bones)
    head = [
        f'<mujoco model="{model}">',
        '  <compiler angle="degree"/>',
        '  <option timestep="0.00555"/>',
        "  <default>",
        '    <motor ctrlrange="-1 1" ctrllimited="true"/>',
        '    <geom type="capsule" contype="1" conaffinity="1" condim="1" friction="1.0 0.05 0.05" '
        'solimp=".9 .99 .003" solref=".015 1"/>',
        '    <joint type="hinge" limited="true" solimplimit="0 .99 .01"/>',
        "  </default>",
        "  <worldbody>",
        '    <geom name="floor" type="plane" size="100 100 .2" conaffinity="1" condim="3" rgba="0.8 0.9 0.8 1"/>',
    ]
    body = _body_xml("pHipOrigin", bones, 2)
    motors = [f'    <motor name="{b}_{ax}" joint="{b}_{ax}" gear="500"/>' for b in ACTUATOR_ORDER for ax in "xyz"]
    return "\n".join([*head, *body, "  </worldbody>", "  <actuator>", *motors, "  </actuator>", "</mujoco>", ""])


def generate_parahome_humanoid(bone_vectors: str | Path, model: str | None = None) -> str:
    """MJCF text of the humanoid of one ``bone_vectors.pkl`` (model name: its sequence folder, e.g. ``s110``)."""
    path = Path(bone_vectors)
    bones = read_bone_vectors(path)
    return parahome_mjcf(bones, model or path.parent.name or "parahome")
