"""Small synthetic inputs written by the tests themselves (nothing from ../shared/data).

- :func:`smplx_like_mjcf`: a 52-body humanoid with InterMimic's SMPL-X body names and order.
- :func:`parahome_like_mjcf`: a 61-body humanoid with SkillMimic ParaHome body names and order.
- :func:`write_intermimic_folder` / :func:`write_parahome_folder`: source folders in each layout, with
  motions made by forward kinematics of those humanoids and a box object.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch
import trimesh

from wristmimic.humanoid.kinematics import forward_kinematics, joint_quat_from_hinges, qpos_from
from wristmimic.humanoid.skeleton import load_skeleton
from wristmimic.rotations import quat_to_rotvec, wxyz_to_xyzw

_FINGERS = ("Index", "Middle", "Pinky", "Ring", "Thumb")


def _smplx_tree() -> list[tuple[str, str | None, tuple[float, float, float]]]:
    t: list[tuple[str, str | None, tuple[float, float, float]]] = [("Pelvis", None, (0, 0, 0))]
    for s, y in (("L", 1), ("R", -1)):
        t += [
            (f"{s}_Hip", "Pelvis", (0, 0.08 * y, -0.09)),
            (f"{s}_Knee", f"{s}_Hip", (0, 0, -0.38)),
            (f"{s}_Ankle", f"{s}_Knee", (0, 0, -0.40)),
            (f"{s}_Toe", f"{s}_Ankle", (0.12, 0, -0.05)),
        ]
    t += [
        ("Torso", "Pelvis", (0, 0, 0.1)),
        ("Spine", "Torso", (0, 0, 0.13)),
        ("Chest", "Spine", (0, 0, 0.05)),
        ("Neck", "Chest", (0, 0, 0.22)),
        ("Head", "Neck", (0, 0, 0.09)),
    ]
    for s, y in (("L", 1), ("R", -1)):
        t += [
            (f"{s}_Thorax", "Chest", (0, 0.08 * y, 0.12)),
            (f"{s}_Shoulder", f"{s}_Thorax", (0, 0.12 * y, 0)),
            (f"{s}_Elbow", f"{s}_Shoulder", (0, 0.26 * y, 0)),
            (f"{s}_Wrist", f"{s}_Elbow", (0, 0.25 * y, 0)),
        ]
        for k, f in enumerate(_FINGERS):
            parent = f"{s}_Wrist"
            for j in (1, 2, 3):
                off = (0.02 * (k - 2), 0.09 * y, 0) if j == 1 else (0, 0.03 * y, 0)
                t.append((f"{s}_{f}{j}", parent, off))
                parent = f"{s}_{f}{j}"
    # InterMimic order: legs, spine, left arm+hand, right arm+hand
    order = [n for n, *_ in t]
    return [t[order.index(n)] for n in order]


def _parahome_tree() -> list[tuple[str, str | None, tuple[float, float, float]]]:
    t: list[tuple[str, str | None, tuple[float, float, float]]] = [("pHipOrigin", None, (0, 0, 0))]
    chain = ["jL5S1", "jL4L3", "jL1T12", "jT9T8", "jT1C7", "jC1Head"]
    parent = "pHipOrigin"
    for n in chain:
        t.append((n, parent, (0, 0, 0.08)))
        parent = n
    for side, y in (("Right", -1), ("Left", 1)):
        t += [
            (f"j{side}T4Shoulder", "jT9T8", (0, 0.03 * y, 0.1)),
            (f"j{side}Shoulder", f"j{side}T4Shoulder", (0, 0.15 * y, 0)),
            (f"j{side}Elbow", f"j{side}Shoulder", (0, 0.27 * y, 0)),
            (f"j{side}Wrist", f"j{side}Elbow", (0, 0.25 * y, 0)),
        ]
        t += [
            (f"j{side}FirstCMC", f"j{side}Wrist", (0.02, 0.02 * y, 0)),
            (f"j{side}FirstMCP", f"j{side}FirstCMC", (0.02, 0.03 * y, 0)),
            (f"j{side}IP", f"j{side}FirstMCP", (0.01, 0.03 * y, 0)),
        ]
        for k, f in enumerate(("Second", "Third", "Fourth", "Fifth")):
            t += [
                (f"j{side}{f}CMC", f"j{side}Wrist", (0.01 - 0.01 * k, 0.02 * y, 0)),
                (f"j{side}{f}MCP", f"j{side}{f}CMC", (0, 0.06 * y, 0)),
                (f"j{side}{f}PIP", f"j{side}{f}MCP", (0, 0.03 * y, 0)),
                (f"j{side}{f}DIP", f"j{side}{f}PIP", (0, 0.02 * y, 0)),
            ]
    for side, y in (("Right", -1), ("Left", 1)):
        t += [
            (f"j{side}Hip", "pHipOrigin", (0, 0.09 * y, -0.05)),
            (f"j{side}Knee", f"j{side}Hip", (0, 0, -0.42)),
            (f"j{side}Ankle", f"j{side}Knee", (0, 0, -0.42)),
            (f"j{side}BallFoot", f"j{side}Ankle", (0.14, 0, -0.06)),
        ]
    return t


def _mjcf(tree: list[tuple[str, str | None, tuple[float, float, float]]]) -> str:
    children: dict[str | None, list[tuple[str, tuple[float, float, float]]]] = {}
    for n, p, off in tree:
        children.setdefault(p, []).append((n, off))

    def body(name: str, off: tuple[float, float, float], depth: int) -> str:
        pad = "  " * depth
        pos = " ".join(f"{v:.4f}" for v in off)
        s = f'{pad}<body name="{name}" pos="{pos}">\n'
        if depth == 2:
            s += f'{pad}  <freejoint name="{name}"/>\n{pad}  <geom type="sphere" size="0.09"/>\n'
        else:
            for ax, a in (("x", "1 0 0"), ("y", "0 1 0"), ("z", "0 0 1")):
                s += f'{pad}  <joint name="{name}_{ax}" type="hinge" axis="{a}" range="-180 180"/>\n'
            kids = children.get(name, [])
            end = np.mean([k[1] for k in kids], axis=0) if kids else np.array([0.0, 0.0, 0.0])
            if np.linalg.norm(end) > 1e-6:
                s += (
                    f'{pad}  <geom type="capsule" size="0.02" fromto="0 0 0 '
                    f'{end[0] * 0.8:.4f} {end[1] * 0.8:.4f} {end[2] * 0.8:.4f}"/>\n'
                )
            else:
                s += f'{pad}  <geom type="box" size="0.02 0.02 0.01"/>\n'
        for c, coff in children.get(name, []):
            s += body(c, coff, depth + 1)
        return s + f"{pad}</body>\n"

    root, _, off = tree[0]
    return (
        '<mujoco model="synthetic">\n  <compiler angle="degree"/>\n  <worldbody>\n'
        '    <geom name="floor" type="plane" size="10 10 0.1"/>\n' + body(root, off, 2) + "  </worldbody>\n</mujoco>\n"
    )


def smplx_like_mjcf(bone_scale: dict[str, float] | None = None) -> str:
    """The SMPL-X-like humanoid; ``bone_scale`` {body name: factor} lengthens those bodies' offsets (another
    subject's skeleton)."""
    scale = bone_scale or {}
    return _mjcf([(n, p, tuple(scale.get(n, 1.0) * np.asarray(o))) for n, p, o in _smplx_tree()])


def parahome_like_mjcf() -> str:
    return _mjcf(_parahome_tree())


def write_box_object(folder: Path, name: str, extents=(0.3, 0.2, 0.2), layout: str = "intermimic") -> None:
    """A closed box mesh with a URDF, in the InterMimic or SkillMimic object layout."""
    folder.mkdir(parents=True, exist_ok=True)
    mesh = trimesh.creation.box(extents=extents)
    if layout == "intermimic":
        (folder / name).mkdir(exist_ok=True)
        mesh.export(folder / name / f"{name}.obj")
        rel = f"objects/{name}/{name}.obj"
    else:
        mesh.export(folder / f"{name}.obj")
        rel = f"{name}.obj"
    (folder / f"{name}.urdf").write_text(
        f'<?xml version="1.0"?>\n<robot name="{name}"><link name="baseLink"><contact>'
        '<lateral_friction value="0.9"/></contact><visual><geometry>'
        f'<mesh filename="{rel}" scale="1 1 1"/></geometry></visual></link></robot>\n'
    )


def _motion(mjcf: str, T: int, seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Root pos, root quat, joint quats, FK body pos and quats of a smooth random motion."""
    skel = load_skeleton(mjcf)
    rng = np.random.default_rng(seed)
    t = np.linspace(0, 1, T)[:, None, None]
    amp = rng.uniform(-0.5, 0.5, (1, skel.num_joints, 3))
    angles = amp * np.sin(2 * np.pi * t + rng.uniform(0, 6, (1, skel.num_joints, 3)))
    root_pos = np.stack([0.3 * t[:, 0, 0], np.zeros(T), np.full(T, 0.95)], -1)
    yaw = 0.4 * t[:, 0, 0]
    root_quat = np.stack([np.cos(yaw / 2), np.zeros(T), np.zeros(T), np.sin(yaw / 2)], -1)
    jq = joint_quat_from_hinges(angles)
    fk = forward_kinematics(skel.model, qpos_from(skel, root_pos, root_quat, angles))
    return root_pos, root_quat, jq, fk.body_pos, fk.body_quat


def intermimic_motion(T: int = 40, seed: int = 0, mjcf: str | None = None) -> np.ndarray:
    """A (T, 591) InterMimic tensor for ``mjcf`` (default :func:`smplx_like_mjcf`) with the object held at the left
    wrist."""
    root_pos, root_quat, jq, bpos, bquat = _motion(mjcf or smplx_like_mjcf(), T, seed)
    d = np.zeros((T, 591))
    d[:, 0:3] = root_pos
    d[:, 3:7] = wxyz_to_xyzw(root_quat)
    d[:, 9:162] = quat_to_rotvec(jq).reshape(T, -1)
    d[:, 162:318] = bpos.reshape(T, -1)
    d[:, 318:321] = bpos[:, 17] + np.array([0.0, 0.25, 0.0])
    d[:, 321:325] = [0, 0, 0, 1]
    d[:, 330] = 1
    d[:, 331:383] = -1
    d[:, 331 + 17] = 1
    d[:, 383:591] = wxyz_to_xyzw(bquat).reshape(T, -1)
    return d


def parahome_motion(T: int = 40, seed: int = 0, num_objects: int = 1) -> np.ndarray:
    """A (T, 409 | 415) SkillMimic ParaHome tensor for :func:`parahome_like_mjcf`."""
    root_pos, root_quat, jq, bpos, _ = _motion(parahome_like_mjcf(), T, seed)
    d = np.zeros((T, 402 + 6 * num_objects + 1))
    d[:, 0:3] = root_pos
    d[:, 3:6] = quat_to_rotvec(root_quat)
    d[:, 9:189] = quat_to_rotvec(jq).reshape(T, -1)
    d[:, 189 : 189 + 183] = bpos.reshape(T, -1)
    for k in range(num_objects):
        d[:, 402 + 6 * k : 405 + 6 * k] = [0.5 + 0.4 * k, 0.0, 0.8]  # resting in mid-air, untouched
    return d


def save_pt(path: Path, arr: np.ndarray) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    torch.save(torch.tensor(arr, dtype=torch.float32), path)


def write_intermimic_folder(root: Path, sequences: tuple[str, ...] = ("sub1_box_000",), T: int = 40) -> Path:
    """An InterMimic-layout folder: humanoid.xml, motions/<seq>.pt, objects/box.urdf + objects/box/box.obj."""
    root.mkdir(parents=True, exist_ok=True)
    (root / "humanoid.xml").write_text(smplx_like_mjcf())
    for i, s in enumerate(sequences):
        save_pt(root / "motions" / f"{s}.pt", intermimic_motion(T, seed=i))
    for obj in sorted({s.split("_")[1] for s in sequences}):
        write_box_object(root / "objects", obj)
    return root


def write_parahome_folder(root: Path, clips: dict[str, int] | None = None, T: int = 40) -> Path:
    """A SkillMimic-layout folder; ``clips`` maps file stem -> number of objects."""
    clips = clips or {"001_s1_move_box": 1}
    root.mkdir(parents=True, exist_ok=True)
    subjects = set()
    for i, (stem, n) in enumerate(clips.items()):
        save_pt(root / "motions" / "set" / stem / f"{stem}.pt", parahome_motion(T, seed=i, num_objects=n))
        subjects.add(stem.split("_")[1])
    (root / "humanoids").mkdir(exist_ok=True)
    for s in subjects:
        (root / "humanoids" / f"{s}.xml").write_text(parahome_like_mjcf())
    for obj in ("box", "cup", "kettle"):
        write_box_object(root / "objects", obj, extents=(0.15, 0.12, 0.1), layout="skillmimic")
    return root


def tiny_ppo_toml(max_frames: int) -> str:
    """A pipeline's ``[train.ppo]`` table for a few-second training run (2 worlds, horizon 4, 16-unit MLPs)."""
    return (
        "[train.ppo]\nnum_envs = 2\nhorizon = 4\nminibatch_size = 8\nepochs = 1\n"
        f"actor_hidden = [16]\ncritic_hidden = [16]\nmax_frames = {max_frames}"
    )


def converted_intermimic(tmp: Path, T: int) -> Path:
    """A canonical file converted from :func:`write_intermimic_folder` (one ``sub1_box_000``-style sequence of ``T``
    frames) under ``tmp``; hulls cached in ``tmp/c``."""
    from wristmimic.convert.common import ConvertOptions
    from wristmimic.convert.intermimic import convert_intermimic

    opts = ConvertOptions(hull_cache_dir=tmp / "c", show_progress=False)
    convert_intermimic(write_intermimic_folder(tmp / "im", T=T), tmp / "im.h5", options=opts)
    return tmp / "im.h5"
