"""Per-subject skeletons fitted to a source's body positions.

InterMimic's OMOMO files store every body's world position, computed in Isaac Gym by forward kinematics of a
humanoid generated for that subject (PHC's ``SMPL_Robot`` from the subject's SMPL-X betas), but ship one
generic ``omomo.xml``. Its bone offsets differ from the subjects' by up to 4 cm per bone (sub2: shins 2-4 cm,
spine 4 cm, forearms 4 cm longer), so FK of the generic humanoid floats the feet 8-11 cm above the floor and
moves the hands 4 cm off the object. Because the stored positions are exact FK of a rigid skeleton (offsets in
the parent frame vary by less than 0.01 mm over all frames), the subject's offsets can be read back:
``offset_b = R_parent^T (x_b - x_parent)``. :func:`refit_mjcf` writes them into the MJCF and carries each body's
geoms along with its one child's bone (PHC places capsules from 0.2 to 0.8 of the bone and boxes at its middle),
keeping geom sizes.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET

import numpy as np

from wristmimic.humanoid.skeleton import Skeleton
from wristmimic.rotations import quat_to_matrix, rotvec_to_quat

FIT_TOL_M = 1e-3
"""Largest allowed spread (m) of a bone offset over frames: above it the positions are not FK of one skeleton."""


def fit_offsets(
    skel: Skeleton, body_pos: np.ndarray, body_quat: np.ndarray, valid: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Bone offsets (B, 3) in the parent frame read from world positions (T, B, 3) and rotations (T, B, 4 wxyz)
    of the bodies marked ``valid`` (B,); the root's and any body whose own or parent's position is not valid keep
    the MJCF's rest offset. Also returns each fitted bone's spread (B,) (max over frames of the distance from its
    mean offset, m; 0 where not fitted)."""
    offsets = skel.rest_pos.astype(np.float64).copy()
    spread = np.zeros(skel.num_bodies)
    R = quat_to_matrix(np.asarray(body_quat, np.float64))  # (T, B, 3, 3)
    pos = np.asarray(body_pos, np.float64)
    for b in range(1, skel.num_bodies):
        p = int(skel.parents[b])
        if not (valid[b] and valid[p]):
            continue
        local = np.einsum("tji,tj->ti", R[:, p], pos[:, b] - pos[:, p])  # (T, 3)
        offsets[b] = local.mean(0)
        spread[b] = float(np.linalg.norm(local - offsets[b], axis=-1).max())
    return offsets, spread


def _align(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Rotation matrix taking the direction of ``u`` to that of ``v`` (the shortest arc)."""
    a, b = u / np.linalg.norm(u), v / np.linalg.norm(v)
    w = np.cross(a, b)
    if np.linalg.norm(w) < 1e-12:  # parallel or opposite: any axis perpendicular to a
        w = np.cross(a, np.eye(3)[int(np.argmin(np.abs(a)))])
    angle = np.arctan2(np.linalg.norm(np.cross(a, b)), a @ b)
    return quat_to_matrix(rotvec_to_quat(angle * w / np.linalg.norm(w)))


def _fmt(v: np.ndarray) -> str:
    return " ".join(f"{x:.6g}" for x in np.asarray(v, float).ravel())


def refit_mjcf(mjcf: str, skel: Skeleton, offsets: np.ndarray, min_change_m: float = 1e-5) -> str:
    """``mjcf`` with body ``pos`` set to ``offsets`` (B, 3). A body with exactly one child whose bone changed gets
    its geoms' positions (``pos``, ``fromto``) mapped by the similarity that takes the old bone onto the new one;
    geom sizes and orientations stay. Bodies are matched by name."""
    root = ET.fromstring(mjcf)
    by_name = {el.get("name"): el for el in root.iter("body")}
    old = skel.rest_pos
    for b in range(skel.num_bodies):
        el = by_name[skel.body_names[b]]
        if b > 0 and np.linalg.norm(offsets[b] - old[b]) > min_change_m:
            el.set("pos", _fmt(offsets[b]))
        kids = skel.children(b)
        if len(kids) != 1:
            continue
        c = kids[0]
        u, v = old[c], offsets[c]
        if np.linalg.norm(v - u) <= min_change_m or np.linalg.norm(u) < 1e-6:
            continue
        A = (np.linalg.norm(v) / np.linalg.norm(u)) * _align(u, v)
        for g in el.findall("geom"):
            if g.get("fromto") is not None:
                ft = np.array(g.get("fromto").split(), float).reshape(2, 3)
                g.set("fromto", _fmt(ft @ A.T))
            if g.get("pos") is not None:
                g.set("pos", _fmt(A @ np.array(g.get("pos").split(), float)))
    return ET.tostring(root, encoding="unicode")


def lowest_foot_height(mjcf: str, qpos: np.ndarray, feet: list[str]) -> float:
    """Lowest signed distance (m) of any geom of the bodies ``feet`` above the z = 0 plane over the poses
    ``qpos`` (T, nq)."""
    import mujoco

    m = mujoco.MjModel.from_xml_string(mjcf)
    d = mujoco.MjData(m)
    ids = {mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, n) for n in feet}
    geoms = [g for g in range(m.ngeom) if int(m.geom_bodyid[g]) in ids]
    low = np.inf
    for q in np.asarray(qpos, np.float64):
        d.qpos[:] = q
        mujoco.mj_kinematics(m, d)
        for g in geoms:
            # the lowest point of a box / capsule / sphere along world z
            R = d.geom_xmat[g].reshape(3, 3)
            size = m.geom_size[g]
            if m.geom_type[g] == mujoco.mjtGeom.mjGEOM_BOX:
                reach = float(np.abs(R[2]) @ size)
            elif m.geom_type[g] == mujoco.mjtGeom.mjGEOM_CAPSULE:
                reach = float(size[0] + abs(R[2, 2]) * size[1])
            else:
                reach = float(size[0])
            low = min(low, float(d.geom_xpos[g, 2]) - reach)
    return low


def thicken_feet(mjcf: str, feet: list[str], depth: float) -> str:
    """``mjcf`` with every box geom of the bodies ``feet`` extended ``depth`` (m) down its body's -z (a shoe
    sole: PHC sizes the foot boxes from the barefoot mesh, OMOMO's subjects stand on shoes)."""
    if depth <= 0:
        return mjcf
    root = ET.fromstring(mjcf)
    for el in root.iter("body"):
        if el.get("name") not in feet:
            continue
        for g in el.findall("geom"):
            quat = np.array(g.get("quat", "1 0 0 0").split(), float)
            if g.get("type") != "box" or not np.allclose(np.abs(quat), [1, 0, 0, 0]):
                continue
            size = np.array(g.get("size").split(), float)
            pos = np.array(g.get("pos", "0 0 0").split(), float)
            size[2] += depth / 2
            pos[2] -= depth / 2
            g.set("size", _fmt(size))
            g.set("pos", _fmt(pos))
    return ET.tostring(root, encoding="unicode")
