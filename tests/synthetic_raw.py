"""Small raw-release fixtures written by the tests (nothing from ../shared/data, no licensed file).

- :func:`write_smplx_model`: a synthetic SMPL-X model ``.npz`` with the documented keys and shapes (10475
  vertices, 55 joints, 400 shape directions) that the real ``smplx`` code loads; its rest joints sit on
  dedicated vertices (one-hot J regressor) of a plausible skeleton, limbs are point cylinders.
- :func:`joblib_like_dump`: a file laid out as ``joblib.dump`` writes it (array bytes after each
  ``NumpyArrayWrapper``), without joblib.
- :func:`write_parahome_raw`: a ParaHome ``seq/sN`` folder + ``scan/`` meshes made by the documented forward
  kinematics from random smooth rotations (the true joint positions are known).
- :func:`write_omomo_raw`: an OMOMO record pickle + ``captured_objects/`` meshes.
"""

from __future__ import annotations

import io
import json
import pickle
import sys
import types
from pathlib import Path

import numpy as np
import trimesh

from wristmimic.humanoid.parahome import BODY_NAMES as PH_BODIES
from wristmimic.humanoid.parahome import TIPS
from wristmimic.humanoid.smplx_body import SMPLX_PARENTS
from wristmimic.rotations import matrix_to_sixd_rows, quat_to_matrix, rotvec_to_quat

NV = 10475
_FING = ("index", "middle", "pinky", "ring", "thumb")


# ----------------------------------------------------------------------------------------------- SMPL-X


def _rest_offsets() -> np.ndarray:
    """(55, 3) joint offsets from the parent, SMPL-X axes (x left, y up, z forward)."""
    off = np.zeros((55, 3))
    body = {
        1: (0.06, -0.09, 0), 3: (0, 0.11, -0.01), 4: (0.01, -0.38, 0), 6: (0, 0.13, 0.01), 7: (0, -0.40, -0.02),
        9: (0, 0.05, 0.02), 10: (0.01, -0.05, 0.12), 12: (0, 0.22, -0.03), 13: (0.07, 0.12, -0.01),
        15: (0, 0.09, 0.05), 16: (0.11, 0.04, -0.02), 18: (0.26, 0, 0), 20: (0.25, 0, 0), 22: (0, 0.02, 0.05),
        23: (0.03, 0.06, 0.08),
    }  # fmt: skip
    for j, v in body.items():
        off[j] = v
    for left, right in ((1, 2), (4, 5), (7, 8), (10, 11), (13, 14), (16, 17), (18, 19), (20, 21), (23, 24)):
        off[right] = off[left] * (-1, 1, 1)
    first = {"index": (0.09, 0, 0.025), "middle": (0.095, 0, 0.005), "pinky": (0.075, 0, -0.035)}
    first |= {"ring": (0.085, 0, -0.015), "thumb": (0.025, -0.01, 0.03)}
    for i, f in enumerate(_FING):
        for side, s in ((25, 1), (40, -1)):
            j = side + 3 * i
            off[j] = np.multiply(first[f], (s, 1, 1))
            off[j + 1] = (0.03 * s, 0, 0.01 if f == "thumb" else 0)
            off[j + 2] = (0.022 * s, 0, 0)
    return off


def rest_joints() -> np.ndarray:
    off = _rest_offsets()
    j = np.zeros((55, 3))
    for k in range(1, 55):
        j[k] = j[SMPLX_PARENTS[k]] + off[k]
    return j + (0, 0.3, 0)


def write_smplx_model(folder: Path, gender: str = "male", seed: int = 0) -> Path:
    """``folder/smplx/SMPLX_<GENDER>.npz``: a synthetic SMPL-X model with the documented keys and shapes."""
    rng = np.random.default_rng(seed)
    J = rest_joints()
    v = np.zeros((NV, 3))
    w = np.zeros((NV, 55))
    v[:55], w[np.arange(55), np.arange(55)] = J, 1.0  # joints sit on vertices 0..54
    children = {p: [c for c in range(55) if SMPLX_PARENTS[c] == p] for p in range(55)}
    per = (NV - 55) // 55
    for j in range(55):
        a = J[j]
        b = J[children[j][0]] if children[j] else J[j] + 0.5 * (J[j] - J[SMPLX_PARENTS[j]])
        r = 0.05 if j < 22 else 0.008
        t = rng.uniform(0, 1, per)[:, None]
        d = rng.normal(size=(per, 3))
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        idx = slice(55 + j * per, 55 + (j + 1) * per)
        v[idx] = a + t * (b - a) + r * d
        w[idx, j] = 1.0
    w[55 + 55 * per :, 0] = 1.0
    v[55 + 55 * per :] = J[0]
    shapedirs = np.zeros((NV, 3, 400), np.float32)
    shapedirs[:, :, :16] = rng.normal(0, 0.004, (NV, 3, 16))
    faces = (np.arange(20908 * 3) % (NV - 2)).reshape(-1, 3) + np.array([0, 1, 2]) * 0
    kintree = np.array([[2**32 - 1, *SMPLX_PARENTS[1:]], list(range(55))], dtype=np.uint32)
    data = dict(
        v_template=v, f=faces.astype(np.uint32), J_regressor=np.eye(55, NV), weights=w, kintree_table=kintree,
        shapedirs=shapedirs, posedirs=np.zeros((NV, 3, 486), np.float32),
        lmk_faces_idx=np.arange(51, dtype=np.int64), lmk_bary_coords=np.full((51, 3), 1 / 3),
        dynamic_lmk_faces_idx=np.zeros((79, 17), np.int64), dynamic_lmk_bary_coords=np.full((79, 17, 3), 1 / 3),
        hands_componentsl=np.eye(45), hands_componentsr=np.eye(45), hands_meanl=np.zeros(45),
        hands_meanr=np.zeros(45),
    )  # fmt: skip
    out = folder / "smplx" / f"SMPLX_{gender.upper()}.npz"
    out.parent.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(out, **data)
    return out


# ----------------------------------------------------------------------------------------------- joblib


class NumpyArrayWrapper:
    """The metadata record joblib writes in place of an array (attribute names as joblib's)."""

    def __init__(self, subclass, shape, order, dtype, allow_mmap=False, numpy_array_alignment_bytes=16):
        self.subclass, self.shape, self.order, self.dtype = subclass, shape, order, dtype
        self.allow_mmap, self.numpy_array_alignment_bytes = allow_mmap, numpy_array_alignment_bytes


class _JoblibLikePickler(pickle._Pickler):  # type: ignore[name-defined]
    def __init__(self, fh: io.BytesIO, align: bool):
        super().__init__(fh, protocol=4)
        self.fh, self.align = fh, align

    def save(self, obj, save_persistent_id=True):  # noqa: ANN001
        if type(obj) is not np.ndarray:
            return super().save(obj, save_persistent_id)
        order = "F" if obj.flags.f_contiguous and not obj.flags.c_contiguous else "C"
        super().save(NumpyArrayWrapper(np.ndarray, obj.shape, order, obj.dtype, True, 16 if self.align else None))
        self.framer.commit_frame(force=True)
        if obj.dtype.hasobject:
            pickle.dump(obj, self.fh, protocol=2)
            return None
        if self.align:
            pad = 16 - (self.fh.tell() + 1) % 16
            self.fh.write(bytes([pad]) + b"\xff" * pad)
        self.fh.write(obj.tobytes(order="F" if order == "F" else "C"))
        return None


def joblib_like_bytes(obj: object, align: bool = True) -> bytes:
    """``obj`` serialised the way ``joblib.dump`` lays it out (uncompressed)."""
    pkg, mod = types.ModuleType("joblib"), types.ModuleType("joblib.numpy_pickle")
    mod.NumpyArrayWrapper = NumpyArrayWrapper  # type: ignore[attr-defined]
    NumpyArrayWrapper.__module__ = "joblib.numpy_pickle"
    saved = {k: sys.modules.get(k) for k in ("joblib", "joblib.numpy_pickle")}
    sys.modules.update({"joblib": pkg, "joblib.numpy_pickle": mod})
    try:
        buf = io.BytesIO()
        _JoblibLikePickler(buf, align).dump(obj)
        return buf.getvalue()
    finally:
        for k, m in saved.items():
            if m is None:
                sys.modules.pop(k, None)
            else:
                sys.modules[k] = m


# ----------------------------------------------------------------------------------------------- OMOMO


def write_box_obj(path: Path, extents=(0.3, 0.2, 0.2), offset=(0.0, 0.0, 0.0)) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    m = trimesh.creation.box(extents=extents)
    m.apply_translation(offset)
    m.export(path)


def _smooth(rng: np.random.Generator, T: int, shape: tuple[int, ...], amp: float) -> np.ndarray:
    t = np.linspace(0, 1, T).reshape(T, *([1] * len(shape)))
    return amp * np.sin(2 * np.pi * t + rng.uniform(0, 6, shape)) * rng.uniform(0.3, 1.0, shape)


def omomo_record(name: str, T: int, seed: int, two_part: bool = False, scale: float = 1.0) -> dict:
    """One OMOMO record: SMPL-X root/body pose (Z-up world), object pose and scale (obj at the left hand)."""
    rng = np.random.default_rng(seed)
    up = quat_to_matrix(rotvec_to_quat(np.array([np.pi / 2, 0, 0])))  # SMPL-X y-up body -> z-up world
    yaw = np.stack([np.zeros(T), np.zeros(T), np.linspace(0, 0.5, T)], -1)
    root = np.einsum("tij,jk->tik", quat_to_matrix(rotvec_to_quat(yaw)), up)
    from wristmimic.rotations import matrix_to_quat, quat_to_rotvec

    rec = {
        "seq_name": name,
        "betas": rng.normal(0, 1, (1, 16)),
        "gender": "male",
        "trans": np.stack([np.linspace(0, 0.3, T), np.zeros(T), np.full(T, 0.6)], -1),
        "root_orient": quat_to_rotvec(matrix_to_quat(root)),
        "pose_body": _smooth(rng, T, (63,), 0.3),
        "obj_trans": np.stack([np.full(T, 0.35), np.linspace(0.1, 0.3, T), np.full(T, 0.75)], -1)[..., None],
        "obj_rot": np.broadcast_to(np.eye(3), (T, 3, 3)).copy(),
        "obj_scale": np.full(T, scale),
        "obj_com_pos": np.zeros((T, 3)),
    }
    if two_part:
        rec["obj_bottom_trans"] = rec["obj_trans"] + np.array([0, 0, -0.3])[:, None]
        rec["obj_bottom_rot"] = rec["obj_rot"].copy()
        rec["obj_bottom_scale"] = np.full(T, scale)
    return rec


def write_omomo_raw(folder: Path, T: int = 24) -> tuple[Path, Path]:
    """(``test_diffusion_manip_seq_joints24.p`` joblib-like, ``captured_objects/``) under ``folder``."""
    objs = folder / "captured_objects"
    write_box_obj(objs / "largebox_cleaned_simplified.obj")
    write_box_obj(objs / "mop_cleaned_simplified.obj", (0.05, 0.05, 1.0))
    write_box_obj(objs / "mop_cleaned_simplified_top.obj", (0.05, 0.05, 0.6))
    write_box_obj(objs / "mop_cleaned_simplified_bottom.obj", (0.3, 0.1, 0.05))
    data = {
        0: omomo_record("sub1_largebox_000", T, 0, scale=0.9),
        1: omomo_record("sub1_mop_000", T, 1, two_part=True),
        2: omomo_record("sub2_largebox_001", T, 2, scale=1.1),
    }
    data[1]["betas"] = data[0]["betas"].copy()  # one subject, one shape
    p = folder / "test_diffusion_manip_seq_joints24.p"
    p.write_bytes(joblib_like_bytes(data))
    return p, objs


# ----------------------------------------------------------------------------------------------- ParaHome

BODY23 = (
    "pHipOrigin jL5S1 jL4L3 jL1T12 jT9T8 jT1C7 jC1Head jRightT4Shoulder jRightShoulder jRightElbow jRightWrist "
    "jLeftT4Shoulder jLeftShoulder jLeftElbow jLeftWrist jRightHip jRightKnee jRightAnkle jRightBallFoot "
    "jLeftHip jLeftKnee jLeftAnkle jLeftBallFoot"
).split()
HAND20 = (
    "Wrist FirstCMC SecondCMC ThirdCMC FourthCMC FifthCMC FifthMCP FifthPIP FifthDIP FourthMCP FourthPIP "
    "FourthDIP ThirdMCP ThirdPIP ThirdDIP SecondMCP SecondPIP SecondDIP FirstMCP IP"
).split()
HAND25 = (
    "Wrist FirstCMC SecondCMC ThirdCMC FourthCMC FifthCMC FifthMCP FifthPIP FifthDIP FifthTip FourthMCP "
    "FourthPIP FourthDIP FourthTip ThirdMCP ThirdPIP ThirdDIP ThirdTip SecondMCP SecondPIP SecondDIP SecondTip "
    "FirstMCP IP FirstTip"
).split()


def synthetic_bones(rng: np.random.Generator) -> dict:
    """bone_vectors.pkl content for the 61-body tree plus fingertips (body float64, hands float32)."""
    from wristmimic.humanoid.parahome import PARENT

    def vec(child: str) -> np.ndarray:
        side = 1.0 if "Left" in child else -1.0
        if any(k in child for k in ("CMC", "MCP", "PIP", "DIP", "IP", "Tip")):
            return np.array([rng.uniform(-0.02, 0.02), side * rng.uniform(0.02, 0.05), 0.0])
        if "Hip" in child:
            return np.array([0.0, side * 0.09, -0.05])
        if any(k in child for k in ("Knee", "Ankle")):
            return np.array([0.0, 0.0, -0.42])
        if "BallFoot" in child:
            return np.array([0.14, 0.0, -0.06])
        if any(k in child for k in ("Shoulder", "Elbow", "Wrist")):
            return np.array([0.0, side * rng.uniform(0.12, 0.28), 0.0])
        return np.array([0.0, 0.0, rng.uniform(0.07, 0.11)])

    out: dict = {"body": {}, "lhand": {}, "rhand": {}}
    pairs = [(PARENT[b], b) for b in PH_BODIES[1:]] + [(b, t) for b, t in TIPS.items()]
    for parent, child in pairs:
        finger = any(k in child for k in ("CMC", "MCP", "PIP", "DIP", "IP", "Tip"))
        part = ("lhand" if "Left" in child else "rhand") if finger else "body"
        v = vec(child)
        out[part].setdefault(parent, {})[child] = v.astype(np.float32 if finger else np.float64)
    return out


def _random_rotations(rng: np.random.Generator, T: int, n: int, amp: float) -> np.ndarray:
    """(T, n, 3, 3) smooth random rotations."""
    return quat_to_matrix(rotvec_to_quat(_smooth(rng, T, (n, 3), amp) + rng.normal(0, 0.2, (1, n, 3))))


def _hand_positions(bones: dict, part: str, side: str, rh: np.ndarray) -> np.ndarray:
    """(T, 25, 3) hand joint positions in the wrist frame: p_child = p_parent + R_parent b (hand orientations)."""
    T = rh.shape[0]
    rot = {n: rh[:, HAND20.index(n)] for n in HAND20}
    pos = {"Wrist": np.zeros((T, 3))}
    order = ["Wrist"] + [n for n in HAND25 if n != "Wrist"]
    for n in order[1:]:
        full = f"p{side}{n}" if n.endswith("Tip") else f"j{side}{n}"
        parent = next(p for p, ch in bones[part].items() if full in ch)
        pshort = parent.replace(f"j{side}", "")
        pos[n] = pos[pshort] + np.einsum("tij,j->ti", rot[pshort], bones[part][parent][full].astype(np.float64))
    return np.stack([pos[n] for n in HAND25], axis=1)


def parahome_fk(bones: dict, rb: np.ndarray, rh: np.ndarray, gt: np.ndarray) -> np.ndarray:
    """(T, 73, 3) world joint positions by ParaHome's documented FK (body orientations rb (T,23,3,3) in the
    body-centred frame, hand orientations rh (T,40,3,3) in the wrist frames, body->world transforms gt)."""
    from wristmimic.humanoid.parahome import PARENT

    T = rb.shape[0]
    p = {"pHipOrigin": np.zeros((T, 3))}
    for name in BODY23[1:]:
        par = PARENT[name]
        p[name] = p[par] + np.einsum("tij,j->ti", rb[:, BODY23.index(par)], bones["body"][par][name])
    body = np.stack([p[n] for n in BODY23], axis=1)
    hands = []
    for side, part, w, sl in (("Left", "lhand", 14, slice(0, 20)), ("Right", "rhand", 10, slice(20, 40))):
        ph = _hand_positions(bones, part, side, rh[:, sl])
        hands.append(np.einsum("tij,tkj->tki", rb[:, w], ph) + body[:, w][:, None])
    local = np.concatenate([body, *hands], axis=1)
    return np.einsum("tij,tkj->tki", gt[:, :3, :3], local) + gt[:, None, :3, 3]


def _tf(rot: np.ndarray, pos: np.ndarray) -> np.ndarray:
    m = np.eye(4)
    m[:3, :3], m[:3, 3] = rot, pos
    return m


def _rz(a: float) -> np.ndarray:
    return quat_to_matrix(rotvec_to_quat(np.array([0.0, 0.0, a])))


def _write_scene(seq: Path, scan: Path, joints: np.ndarray) -> None:
    """Meshes and object transforms: kettle at the right hand (dynamic), dining table (static by name), cup (still:
    static by motion), drawer (static base, sliding part1), microwave (static base, door turning about z), book
    (not in the scene)."""
    T = joints.shape[0]
    write_box_obj(scan / "kettle/simplified/base.obj", (0.12, 0.12, 0.15))
    write_box_obj(scan / "diningtable/simplified/base.obj", (1.0, 0.6, 0.05))
    write_box_obj(scan / "cup/simplified/base.obj", (0.06, 0.06, 0.1))
    write_box_obj(scan / "drawer/simplified/base.obj", (0.4, 0.4, 0.4))
    write_box_obj(scan / "drawer/simplified/part1.obj", (0.35, 0.35, 0.1), (0.0, 0.0, 0.1))
    write_box_obj(scan / "microwave/simplified/base.obj", (0.4, 0.3, 0.3))
    write_box_obj(scan / "microwave/simplified/part1.obj", (0.02, 0.28, 0.28), (0.2, 0.14, 0.0))
    write_box_obj(scan / "book/simplified/base.obj", (0.2, 0.15, 0.03))
    I3 = np.eye(3)
    frames = {}
    for f in range(T):
        d = {
            "kettle_base": _tf(_rz(0.02 * f), joints[f, 48] + (0.0, 0.0, -0.09)),
            "diningtable_base": _tf(I3, (1.5, 0.0, 0.75 + 0.0005 * (f % 2))),
            "cup_base": _tf(I3, (1.5, 0.2, 0.82)) if f != 7 else np.eye(4),
            "drawer_base": _tf(I3, (-1.0, 1.0, 0.2)),
            "drawer_part1": _tf(I3, (-1.0 + 0.012 * min(f, 20), 1.0, 0.2)),
            "microwave_base": _tf(_rz(0.3), (0.0, -1.5, 1.0)),
            "microwave_part1": _tf(_rz(0.3) @ _rz(-np.pi / 2 * f / (T - 1)), (0.0, -1.5, 1.0)),
            "book_base": _tf(I3, (2.0, 2.0, 0.8)),
        }
        if f in (5, 6):
            del d["kettle_base"]
        frames[f] = d
    _dump(seq / "object_transformations.pkl", frames)
    states = {"drawer_part1": {f: 0.012 * min(f, 20) for f in range(T)}}
    states["microwave_part1"] = {f: -np.pi / 2 * f / (T - 1) for f in range(T)}
    _dump(seq / "joint_states.pkl", states)
    scene = {"kettle": True, "diningtable": True, "cup": True, "drawer": True, "microwave": True, "book": False}
    (seq / "object_in_scene.json").write_text(json.dumps(scene))


def _dump(path: Path, obj: object) -> None:
    with open(path, "wb") as f:
        pickle.dump(obj, f, protocol=4)


def write_parahome_raw(root: Path, sequence: str = "s7", T: int = 40, seed: int = 0) -> dict[str, np.ndarray]:
    """``root/seq/<sequence>/*`` and ``root/scan/*``; returns the truth (joint positions, bones, ...)."""
    rng = np.random.default_rng(seed)
    seq = root / "seq" / sequence
    seq.mkdir(parents=True, exist_ok=True)
    bones = synthetic_bones(rng)
    rb = _random_rotations(rng, T, 23, 0.4)
    rh = _random_rotations(rng, T, 40, 0.4)
    gt = np.stack([_tf(_rz(0.3 * t / T) @ quat_to_matrix(rotvec_to_quat(np.array([0.1, 0.05, 0.0]))),
                       (0.2 * t / T, 0.0, 0.95)) for t in range(T)])  # fmt: skip
    joints = parahome_fk(bones, rb, rh, gt)
    _dump(seq / "bone_vectors.pkl", bones)
    _dump(seq / "body_joint_orientations.pkl", matrix_to_sixd_rows(rb).astype(np.float32))
    _dump(seq / "hand_joint_orientations.pkl", matrix_to_sixd_rows(rh).astype(np.float32))
    _dump(seq / "body_global_transform.pkl", gt)
    _dump(seq / "joint_positions.pkl", joints)
    _dump(seq / "head_tips.pkl", joints[:, 6] + (0, 0, 0.15))
    (seq / "text_annotation.json").write_text(json.dumps({"0 19": "move kettle", f"20 {T - 1}": "open microwave"}))
    _write_scene(seq, root / "scan", joints)
    return {"joints": joints, "rb": rb, "rh": rh, "gt": gt}
