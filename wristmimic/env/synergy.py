"""Grasp synergy: one extra action per hand that curls all of its fingers toward the palm.

Fingers get no pose targets in this method, so a grip has to be found by exploring 45-57 independent finger
hinges; the policies trained on the real scenes hold their fingers straight through the lift (rendered on
``s110_move_kettle``: the hand pushes under the handle's loop with straight fingers). With
``EnvConfig.finger_synergy`` = s rad, the action vector gains two dimensions, one per hand (left, right), and each
finger hinge's PD target moves by ``s * g * c`` where ``g`` in [-1, 1] is that hand's synergy action and ``c`` the
hinge's closure coefficient: a one-dimensional eigengrasp (postural synergy) whose positive direction closes the
hand. The finger actions keep their own mapping; the synergy adds to it, so the policy can still shape the grip.

The closure coefficients come from the humanoid's geometry alone, never from a reference: at the model's rest pose,
for every finger hinge, ``c = n . (axis x r) / |r|``, the rate at which turning the hinge moves the fingertips
beyond it (``r``: from the hinge's anchor to the mean of their far ends, :func:`tip_point`) along the palm normal ``n`` (the normal of the
plane through the wrist and the finger bases, on the palm's side). Flexion hinges get |c| near 1, abduction and
twist hinges near 0, and each hand's coefficients are scaled so that the largest is exactly 1. Deterministic for a
scene; applied identically by training, evaluation, ``view`` and ``export`` (they all map actions through the
environment).
"""

from __future__ import annotations

import mujoco
import numpy as np

from wristmimic.scene import Scene

HANDS = ("left", "right")
"""Order of the synergy actions (the last two action dimensions when enabled)."""


def palm_normal(points: np.ndarray, down: np.ndarray) -> np.ndarray:
    """Unit normal of the least-squares plane through ``points`` (P, 3), oriented along ``down`` (3,)."""
    centred = points - points.mean(axis=0)
    n = np.linalg.svd(centred)[2][2]
    return n if float(n @ down) >= 0.0 else -n


def tip_point(model: mujoco.MjModel, data: mujoco.MjData, body: int, parent: int) -> np.ndarray:
    """World position of a fingertip: the end of the tip body's collision geoms farthest from its parent body
    (a capsule's far cap centre, another geom's centre), else the body origin extended by half its bone."""
    origin, far = data.xpos[parent], None
    for g in np.flatnonzero(model.geom_bodyid == body):
        centre = data.geom_xpos[g]
        ends = [centre]
        if model.geom_type[g] == mujoco.mjtGeom.mjGEOM_CAPSULE:
            axis = data.geom_xmat[g].reshape(3, 3)[:, 2] * model.geom_size[g][1]
            ends = [centre + axis, centre - axis]
        for e in ends:
            if far is None or np.linalg.norm(e - origin) > np.linalg.norm(far - origin):
                far = e
    if far is None:
        far = data.xpos[body] + 0.5 * (data.xpos[body] - origin)
    return np.asarray(far, dtype=float)


def closure_coefficients(scene: Scene) -> np.ndarray:
    """(2, A) closure coefficient of every actuated hinge for the left and the right hand (zero off that hand's
    fingers), each row scaled to a largest magnitude of 1. The palm side is taken as the side the palms face at the
    model's rest pose, which is downward (-z) for the SMPL-X and ParaHome humanoids (T-pose, palms down)."""
    m = scene.model
    d = mujoco.MjData(m)
    d.qpos[:] = m.qpos0
    mujoco.mj_kinematics(m, d)  # body frames, joint anchors and axes
    skel, roles = scene.skeleton, scene.humanoid.roles
    body_id = np.array([mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, n) for n in skel.body_names])
    skel_of = {int(b): i for i, b in enumerate(body_id)}
    actuators = scene.actuator_ids.reshape(-1)
    out = np.zeros((2, len(actuators)))
    pos = d.xpos[body_id]
    for h, side in enumerate(HANDS):
        hand = {int(b) for b in roles[f"{side}_hand"]}
        wrists = [int(w) for w in roles["wrists"] if int(w) in hand]
        tips = [int(t) for t in roles.get(f"{side}_fingertips", [])]
        if not wrists or not tips:
            raise ValueError(f"finger_synergy needs the {side} hand's wrist and fingertips in the humanoid's roles")
        wrist = wrists[0]
        tip_at = {t: tip_point(m, d, int(body_id[t]), int(body_id[skel.parents[t]])) for t in tips}
        base = np.array([pos[c] for c in skel.children(wrist)] + [pos[wrist]])
        n = palm_normal(base, np.array([0.0, 0.0, -1.0]))
        for k, a in enumerate(actuators):
            joint = int(m.actuator_trnid[a, 0])
            b = skel_of.get(int(m.jnt_bodyid[joint]))
            if b is None or b not in hand or b == wrist:
                continue
            below = [t for t in skel.subtree(b) if t in tip_at]
            if not below:
                continue
            r = np.mean([tip_at[t] for t in below], axis=0) - d.xanchor[joint]
            dist = float(np.linalg.norm(r))
            if dist < 1e-4:
                continue
            out[h, k] = float(n @ np.cross(d.xaxis[joint], r)) / dist
        peak = np.abs(out[h]).max()
        if peak > 0.0:
            out[h] /= peak
    return out
