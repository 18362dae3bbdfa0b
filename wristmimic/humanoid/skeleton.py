"""The humanoid's kinematic structure, read from its MJCF with MuJoCo.

A supported humanoid has one free-joint root body and, on every other body, three hinges with axes
x, y, z in that order (InterMimic's SMPL-X ``omomo.xml``, SkillMimic's ParaHome humanoids). The hinge
angles are intrinsic XYZ Euler angles of the body's rotation relative to its parent (after the body's
rest orientation), see :mod:`wristmimic.rotations`.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from pathlib import Path

import mujoco
import numpy as np

from wristmimic.errors import InputError

_AXES = np.eye(3)


@dataclass(frozen=True)
class Skeleton:
    """Body tree and joint layout of a humanoid MJCF (bodies in MuJoCo order, world excluded)."""

    mjcf: str
    body_names: tuple[str, ...]
    parents: np.ndarray  # (B,) int32, -1 for the root
    rest_pos: np.ndarray  # (B, 3) body offset in its parent frame (MJCF body pos)
    rest_quat: np.ndarray  # (B, 4) wxyz body orientation in its parent frame (MJCF body quat)
    joint_bodies: np.ndarray  # (J,) int32 body index of each 3-DoF joint (every body but the root)
    hinge_qposadr: np.ndarray  # (J, 3) int32 qpos address of the x, y, z hinge of each joint
    joint_range: np.ndarray  # (J, 3, 2) hinge ranges (rad)
    nq: int

    @property
    def num_bodies(self) -> int:
        return len(self.body_names)

    @property
    def num_joints(self) -> int:
        return len(self.joint_bodies)

    @property
    def joint_names(self) -> tuple[str, ...]:
        return tuple(self.body_names[b] for b in self.joint_bodies)

    def index(self, name: str) -> int:
        """Body index of ``name``."""
        try:
            return self.body_names.index(name)
        except ValueError:
            raise KeyError(f"humanoid has no body {name!r}") from None

    def children(self, b: int) -> list[int]:
        return [int(i) for i in np.flatnonzero(self.parents == b)]

    def subtree(self, b: int) -> list[int]:
        """``b`` and all of its descendants, in body order."""
        out = [b]
        for c in self.children(b):
            out.extend(self.subtree(c))
        return sorted(out)

    @cached_property
    def model(self) -> mujoco.MjModel:
        """The compiled MuJoCo model (cached)."""
        return mujoco.MjModel.from_xml_string(self.mjcf)


def load_skeleton(mjcf: str, source: str | Path | None = None) -> Skeleton:
    """Parse an MJCF humanoid; raise :class:`InputError` (naming ``source``) if it is not supported."""
    try:
        model = mujoco.MjModel.from_xml_string(mjcf)
    except Exception as exc:  # mujoco raises ValueError with a multi-line message
        raise InputError(source, "mjcf", f"MuJoCo cannot compile it: {str(exc).splitlines()[0]}") from None
    nb = model.nbody - 1
    if nb < 2:
        raise InputError(source, "mjcf", f"{nb} bodies", "a humanoid with a root and joints")
    names = tuple(mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_BODY, i + 1) or f"body{i}" for i in range(nb))
    parents = model.body_parentid[1:].astype(np.int32) - 1
    if parents[0] != -1 or np.any(parents[1:] < 0):
        raise InputError(source, "mjcf", "more than one body attached to the world", "a single root body")
    root_j = np.flatnonzero(model.jnt_bodyid == 1)
    if len(root_j) != 1 or model.jnt_type[root_j[0]] != mujoco.mjtJoint.mjJNT_FREE:
        raise InputError(source, f"body {names[0]}", "root has no free joint", "one free joint on the root")
    joint_bodies, qadr, ranges = [], [], []
    for b in range(1, nb):
        js = np.flatnonzero(model.jnt_bodyid == b + 1)
        ok = len(js) == 3 and all(model.jnt_type[j] == mujoco.mjtJoint.mjJNT_HINGE for j in js)
        ok = ok and all(np.allclose(model.jnt_axis[j], _AXES[k]) for k, j in enumerate(js))
        ok = ok and all(np.allclose(model.jnt_pos[j], 0.0) for j in js)
        if not ok:
            raise InputError(
                source,
                f"body {names[b]}",
                "joints are not three hinges x, y, z at the body origin",
                "3 hinges with axes 1 0 0, 0 1 0, 0 0 1 in that order",
            )
        joint_bodies.append(b)
        qadr.append(model.jnt_qposadr[js])
        ranges.append(np.where(model.jnt_limited[js, None] > 0, model.jnt_range[js], [[-np.pi, np.pi]]))
    return Skeleton(
        mjcf=mjcf,
        body_names=names,
        parents=parents,
        rest_pos=model.body_pos[1:].copy(),
        rest_quat=model.body_quat[1:].copy(),
        joint_bodies=np.asarray(joint_bodies, dtype=np.int32),
        hinge_qposadr=np.asarray(qadr, dtype=np.int32),
        joint_range=np.asarray(ranges, dtype=np.float64),
        nq=int(model.nq),
    )
