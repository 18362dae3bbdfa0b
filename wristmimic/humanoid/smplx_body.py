"""The SMPL-X humanoid (InterMimic's 52 bodies) generated from a subject's shape with the ``smplx`` package.

The SMPL-X model files are licensed and not part of this project: the user passes a folder holding
``SMPLX_{MALE,FEMALE,NEUTRAL}.npz`` (or ``smplx/SMPLX_*.npz``) from https://smpl-x.is.tue.mpg.de (free
registration). The file is checked with the restricted ``.npz`` reader first (keys, shapes, kinematic tree;
pickled entries may hold only numpy data and builtin containers), then loaded by ``smplx``.

Joint positions are the model's J regressor applied to the shaped rest mesh (betas, zero pose, flat hands):
each body's MJCF offset is ``P (J_child - J_parent)`` where ``P`` (wxyz ``0.5 0.5 0.5 0.5``) turns SMPL-X's
rest axes (x left, y up, z forward) into the humanoid's (x forward, y left, z up), as InterMimic's
``upright_start`` humanoid; bodies carry no rest rotation. Body names, order, joint names, PD gains and
ranges follow InterMimic's ``omomo.xml``. Geoms (capsules on limbs and fingers, boxes for feet, toes and
palms, spheres for pelvis and head) are sized from the skinned vertices of each body's segment, clamped
to [0.6, 1.6] x typical radii.
"""

from __future__ import annotations

import contextlib
import io
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from wristmimic.errors import InputError
from wristmimic.rotations import quat_to_matrix

MODEL_URL = "https://smpl-x.is.tue.mpg.de"
FINGERS = ("Index", "Middle", "Pinky", "Ring", "Thumb")
SMPLX_PARENTS = (
    [-1, 0, 0, 0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 9, 9, 12, 13, 14, 16, 17, 18, 19, 15, 15, 15]
    + [20, 25, 26, 20, 28, 29, 20, 31, 32, 20, 34, 35, 20, 37, 38]
    + [21, 40, 41, 21, 43, 44, 21, 46, 47, 21, 49, 50, 21, 52, 53]
)
"""Parents of the 55 SMPL-X joints (body 22, jaw, eyes, 15 + 15 finger joints)."""
_BODY = [
    ("Pelvis", 0), ("L_Hip", 1), ("L_Knee", 4), ("L_Ankle", 7), ("L_Toe", 10),
    ("R_Hip", 2), ("R_Knee", 5), ("R_Ankle", 8), ("R_Toe", 11),
    ("Torso", 3), ("Spine", 6), ("Chest", 9), ("Neck", 12), ("Head", 15),
    ("L_Thorax", 13), ("L_Shoulder", 16), ("L_Elbow", 18), ("L_Wrist", 20),
]  # fmt: skip
_LFING = [(f"L_{f}{k}", 25 + 3 * i + k - 1) for i, f in enumerate(FINGERS) for k in (1, 2, 3)]
_RARM = [("R_Thorax", 14), ("R_Shoulder", 17), ("R_Elbow", 19), ("R_Wrist", 21)]
_RFING = [(f"R_{f}{k}", 40 + 3 * i + k - 1) for i, f in enumerate(FINGERS) for k in (1, 2, 3)]
BODY_NAMES: tuple[str, ...] = tuple(n for n, _ in _BODY + _LFING + _RARM + _RFING)
"""The 52 bodies in MuJoCo order (InterMimic's ``omomo.xml``)."""
SMPLX_INDEX = np.array([j for _, j in _BODY + _LFING + _RARM + _RFING], dtype=np.int64)
"""SMPL-X joint (of 55) of each MJCF body."""
PARENTS = np.array([-1] + [int(np.flatnonzero(SMPLX_INDEX == SMPLX_PARENTS[j])[0]) for j in SMPLX_INDEX[1:]])
UPRIGHT_QUAT = np.array([0.5, 0.5, 0.5, 0.5])
"""wxyz rotation from SMPL-X rest axes to the humanoid's: x -> y, y -> z, z -> x."""
_REQUIRED = {  # key -> shape with None for "any"; V = vertices
    "v_template": (None, 3),
    "f": (None, 3),
    "J_regressor": (55, None),
    "weights": (None, 55),
    "kintree_table": (2, 55),
    "shapedirs": (None, 3, None),
    "posedirs": (None, 3, 486),
}


@dataclass
class ShapedBody:
    """A subject's SMPL-X rest shape: joints, vertices and skinning weights (SMPL-X axes, metres)."""

    joints: np.ndarray  # (55, 3)
    vertices: np.ndarray  # (V, 3)
    weights: np.ndarray  # (V, 55)
    gender: str
    betas: np.ndarray
    model_file: Path


def find_model_file(models_dir: str | Path, gender: str) -> Path:
    """``SMPLX_<GENDER>.npz`` in ``models_dir`` or ``models_dir/smplx``; a clear error says what is missing."""
    models_dir = Path(models_dir)
    g = str(gender).lower()
    if g not in ("male", "female", "neutral"):
        raise InputError(None, "gender", f"unknown gender {gender!r}", "male, female or neutral")
    name = f"SMPLX_{g.upper()}.npz"
    for cand in (models_dir / name, models_dir / "smplx" / name):
        if cand.is_file():
            return cand
    raise InputError(
        models_dir,
        name,
        f"SMPL-X model file missing (looked for {name} and smplx/{name})",
        f"the SMPL-X model files (npz) from {MODEL_URL} after free registration",
    )


def check_model_file(path: Path, num_betas: int) -> int:
    """Check keys, shapes and the kinematic tree; returns how many shape components the model has."""
    data = _load_npz(path)
    V = None
    for key, shape in _REQUIRED.items():
        if key not in data:
            raise InputError(path, key, "missing", f"an SMPL-X model file (from {MODEL_URL})")
        a = data[key]
        if a.ndim != len(shape) or any(s is not None and s != n for s, n in zip(shape, a.shape, strict=False)):
            raise InputError(path, key, f"shape {a.shape}", f"{tuple('*' if s is None else s for s in shape)}")
        V = a.shape[0] if key == "v_template" else V
        if key in ("weights", "shapedirs", "posedirs") and a.shape[0] != V:
            raise InputError(path, key, f"{a.shape[0]} vertices, v_template has {V}", "the same vertex count")
    parents = data["kintree_table"][0].astype(np.int64)
    if not np.array_equal(parents[1:], SMPLX_PARENTS[1:]):
        raise InputError(path, "kintree_table", "not the SMPL-X kinematic tree", "the 55-joint SMPL-X parents")
    comps = 300 if data["shapedirs"].shape[-1] >= 300 else min(10, data["shapedirs"].shape[-1])
    return comps


def _load_npz(path: Path) -> dict[str, np.ndarray]:
    from wristmimic.safe_io import safe_npz_load

    return safe_npz_load(path)


class SmplxModels:
    """Loads each gender's model once (``smplx.SMPLX``, float64, flat hands, no PCA)."""

    def __init__(self, models_dir: str | Path):
        self.models_dir = Path(models_dir)
        self._models: dict[tuple[str, int], object] = {}

    def model(self, gender: str, num_betas: int) -> tuple[object, Path]:
        import smplx
        import torch

        path = find_model_file(self.models_dir, gender)
        key = (str(path), num_betas)
        if key not in self._models:
            comps = check_model_file(path, num_betas)
            if num_betas > comps:
                raise InputError(path, "shapedirs", f"{comps} shape components, the subject has {num_betas} betas",
                                 f"the SMPL-X v1.1 model (300 shape components) from {MODEL_URL}")  # fmt: skip
            with contextlib.redirect_stdout(io.StringIO()):  # smplx prints notices on stdout
                self._models[key] = smplx.SMPLX(
                    model_path=str(path), gender=gender.lower(), num_betas=num_betas, use_pca=False,
                    flat_hand_mean=True, ext="npz", dtype=torch.float64,
                )  # fmt: skip
        return self._models[key], path

    def shaped_body(self, gender: str, betas: np.ndarray) -> ShapedBody:
        """Rest joints and vertices of a subject (zero pose, flat hands)."""
        import torch

        betas = np.asarray(betas, dtype=np.float64).reshape(-1)
        model, path = self.model(gender, len(betas))
        with torch.no_grad():
            out = model(betas=torch.from_numpy(betas[None]), return_verts=True)  # type: ignore[operator]
        weights = model.lbs_weights.detach().numpy()  # type: ignore[attr-defined]
        return ShapedBody(
            joints=out.joints[0, :55].numpy().astype(np.float64),
            vertices=out.vertices[0].numpy().astype(np.float64),
            weights=weights.astype(np.float64),
            gender=gender.lower(),
            betas=betas,
            model_file=path,
        )


# ------------------------------------------------------------------------------------------------ MJCF

_RADIUS = {  # typical capsule / sphere radii (m) of an adult, InterMimic-like
    "Pelvis": 0.105, "Hip": 0.059, "Knee": 0.056, "Torso": 0.082, "Spine": 0.069, "Chest": 0.115,
    "Neck": 0.044, "Head": 0.105, "Thorax": 0.057, "Shoulder": 0.053, "Elbow": 0.042,
    "1": 0.009, "2": 0.0073, "3": 0.0063, "Thumb1": 0.012, "Thumb2": 0.0093, "Thumb3": 0.0088,
}  # fmt: skip
_BOX = {"Ankle": (0.091, 0.050, 0.022), "Toe": (0.019, 0.049, 0.021), "Wrist": (0.041, 0.043, 0.0077)}
_DENSITY = {"Pelvis": 4629.6296296296305, "Hip": 2040.816327, "Knee": 1234.567901}
_DENSITY.update({k: 1100.0 for k in ("Torso", "Spine", "Chest")})
_GAINS = {"Hip": 800, "Knee": 800, "Ankle": 800, "Toe": 500, "Torso": 1000, "Spine": 1000, "Chest": 1000}
_GAINS.update({"Wrist": 300})


def _kind(name: str) -> str:
    base = name.split("_", 1)[-1]
    if base[-1].isdigit():
        return base if base.startswith("Thumb") else base[-1]
    return base


def _f(v: np.ndarray | float) -> str:
    return " ".join(f"{float(x):.8g}" for x in np.atleast_1d(v))


def _range(name: str, axis: int) -> str:
    kind = _kind(name)
    if kind in ("1", "2", "3") or kind.startswith("Thumb"):
        if kind == "Thumb1":
            return "-55.625 55.625"
        if axis == 0 and kind in ("1", "2"):
            return "-55.625 55.625"
        if axis == 0 and kind in ("3", "Thumb3"):
            return "-90 5.625" if name.startswith("L_") else "-5.625 90"
        return "-5.625 5.625"
    return "-180 180"


def _gain(name: str) -> int:
    kind = _kind(name)
    return 100 if kind in ("1", "2", "3") or kind.startswith("Thumb") else _GAINS.get(kind, 500)


def _segment_points(body: ShapedBody, b: int) -> np.ndarray:
    """Vertices whose dominant joint is body ``b``'s (jaw and eyes count as head), in its upright frame."""
    dom = np.argmax(body.weights, axis=1)
    j = int(SMPLX_INDEX[b])
    sel = np.isin(dom, [j, 22, 23, 24]) if j == 15 else dom == j
    return (body.vertices[sel] - body.joints[j]) @ quat_to_matrix(UPRIGHT_QUAT).T


def _clamp(value: float, typical: float) -> float:
    return float(np.clip(value, 0.6 * typical, 1.6 * typical)) if np.isfinite(value) else typical


def _geom(name: str, b: int, end: np.ndarray, pts: np.ndarray) -> str:
    """Geom of body ``b``; ``end`` = offset of its (first) child or, for leaves, of itself."""
    kind = _kind(name)
    dens = _DENSITY.get(kind, 1000.0)
    if kind in _BOX:
        typical = np.asarray(_BOX[kind])
        if len(pts) >= 20:
            lo, hi = np.percentile(pts, [3, 97], axis=0)
            center, half = (lo + hi) / 2, np.array([_clamp(h, t) for h, t in zip((hi - lo) / 2, typical, strict=True)])
        else:
            center, half = 0.5 * end, typical
        return f'<geom type="box" density="{dens}" pos="{_f(center)}" size="{_f(half)}"/>'
    typical = _RADIUS[kind]
    if kind in ("Pelvis", "Head"):
        center = np.median(pts, axis=0) if kind == "Head" and len(pts) >= 20 else np.zeros(3)
        r = np.median(np.linalg.norm(pts - center, axis=1)) if len(pts) >= 20 else typical
        return f'<geom type="sphere" density="{dens}" pos="{_f(center)}" size="{_f(_clamp(r, typical))}"/>'
    a, c = 0.2 * end, 0.8 * end
    axis = end / max(np.linalg.norm(end), 1e-9)
    t = pts @ axis
    inside = pts[(t >= a @ axis) & (t <= c @ axis)]
    perp = inside - np.outer(inside @ axis, axis)
    r = np.median(np.linalg.norm(perp, axis=1)) if len(inside) >= 10 else typical
    return (
        f'<geom type="capsule" density="{dens}" fromto="{_f(np.concatenate([a, c]))}" size="{_f(_clamp(r, typical))}"/>'
    )


def _body_xml(b: int, body: ShapedBody, offsets: np.ndarray, depth: int) -> list[str]:
    name, pad = BODY_NAMES[b], "  " * depth
    kids = [int(k) for k in np.flatnonzero(PARENTS == b)]  # index order: Chest -> Neck first
    end = offsets[kids[0]] if kids else offsets[b]
    if name.endswith("_Wrist"):
        end = offsets[BODY_NAMES.index(name[0] + "_Middle1")]
    lines = [f'{pad}<body name="{name}" pos="{_f(offsets[b])}">']
    if b == 0:
        lines.append(f'{pad}  <freejoint name="{name}"/>')
    lines.append(f"{pad}  {_geom(name, b, end, _segment_points(body, b))}")
    axes = ("1 0 0", "0 1 0", "0 0 1") if b else ()
    for ax, vec in enumerate(axes):
        k = _gain(name)
        lines.append(
            f'{pad}  <joint name="{name}_{"xyz"[ax]}" type="hinge" pos="0 0 0" axis="{vec}" stiffness="{k}" '
            f'damping="{k // 10}" armature="0.02" range="{_range(name, ax)}"/>'
        )
    for k in kids:
        lines += _body_xml(k, body, offsets, depth + 1)
    return [*lines, f"{pad}</body>"]


def body_offsets(joints: np.ndarray) -> np.ndarray:
    """(52, 3) MJCF body offsets from (55, 3) SMPL-X rest joints (root offset = 0)."""
    rot = quat_to_matrix(UPRIGHT_QUAT)
    j = joints[SMPLX_INDEX]
    off = np.zeros((len(BODY_NAMES), 3))
    off[1:] = (j[1:] - j[PARENTS[1:]]) @ rot.T
    return off


def smplx_mjcf(body: ShapedBody, model: str = "smplx") -> str:
    """MJCF text of the 52-body humanoid of one shaped SMPL-X body."""
    offsets = body_offsets(body.joints)
    head = [
        f'<mujoco model="{model}">',
        '  <compiler angle="degree"/>',
        "  <default>",
        '    <joint limited="true"/>',
        '    <geom contype="1" conaffinity="1" condim="3" margin="0.001" rgba="0.8 0.6 .4 1"/>',
        "  </default>",
        "  <worldbody>",
        '    <geom name="floor" type="plane" size="100 100 .2" rgba="0.8 0.9 0.8 1"/>',
    ]
    motors = [f'    <motor name="{n}_{a}" joint="{n}_{a}" gear="1"/>' for n in BODY_NAMES[1:] for a in "xyz"]
    tail = ["  </worldbody>", "  <actuator>", *motors, "  </actuator>", "</mujoco>", ""]
    return "\n".join([*head, *_body_xml(0, body, offsets, 2), *tail])
