"""Kinematic grip probe: can the reference's own wrist path carry the object with any finger pose?

Usage:  python scripts/kinematic_grip_probe.py DATASET.h5 --scene SEQ --start F0 --stop F1
        [--hands right|left|both] [--samples 48] [--iters 10] [--sigma 0.5] [--synergy 0]
        [--set scene_config.FIELD=VALUE ...] [--seed 0] [-o probe.json]

Every non-finger degree of freedom of the humanoid (the root and every body and wrist hinge) follows the reference
exactly: before each physics substep its position (interpolated between the two frames) and velocity are set, so
the wrists are where the mocap puts them whatever the load. The finger hinges are PD-driven to constant targets, the
start frame's reference angle plus an offset, and the objects are free. A cross-entropy search over the offsets of
the chosen hands' finger hinges (``--samples`` per iteration, the cheapest eighth kept, noise ``--sigma`` rad
annealed by 0.85) minimises the mean object-position error over the frames after ``--start``. ``--synergy S``
searches one number per hand instead: S times it along the grasp synergy's closure (:mod:`wristmimic.env.synergy`).

``--wrist-offset W`` also searches, per chosen hand, a constant offset (W m per unit, in the reference object's
frame) applied while the reference hand touches the object, through the arm's hinges only (:class:`ArmOffsetMap`:
the damped pseudo-inverse of the wrist's 6-D Jacobian over the collar, shoulder, elbow and wrist hinges at the
reference pose, ramped in and out over 10 frames), so the hand moves rigidly with the object and keeps its
orientation to first order: can a corrected wrist path carry what the mocap one cannot? ``--hold F`` keeps the
object on its reference (kinematic) before frame F, so the grasp forms on it before the object is released.

A success here (an error that stays small) says the reference's wrist path can carry the object and a policy's
fingers have something to find; a failure says the wrists themselves must leave the reference. A diagnostic, not a
training method: ``reports/README.md`` says what it found on the shared scenes. Prints one line per iteration and
the best sample's error per frame; ``-o`` writes them as JSON.
"""

from __future__ import annotations

import argparse
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import mujoco
import numpy as np
import torch

from wristmimic.env.config import EnvConfig
from wristmimic.env.synergy import closure_coefficients
from wristmimic.env.vec_env import WristMimicEnv
from wristmimic.errors import InputError
from wristmimic.rl.config import to_jsonable
from wristmimic.rl.overrides import apply_overrides
from wristmimic.rotations import quat_to_matrix
from wristmimic.safe_io import atomic_output
from wristmimic.scene import SceneConfig, scene_config_from_dict

HANDS = {"left": ("left",), "right": ("right",), "both": ("left", "right")}
SIDES = ("left", "right")
ARM_BODIES = 4
"""Bodies of the arm chain, from the wrist up: wrist, elbow, shoulder, collar."""


@dataclass
class ArmOffsetMap:
    """Per frame and hand, the linear map from an object-frame wrist offset (m) to arm hinge angle changes."""

    qpos_index: np.ndarray  # (2, A) qpos addresses of each hand's arm hinges
    dof_index: np.ndarray  # (2, A) dof addresses of the same hinges
    maps: np.ndarray  # (T, 2, A, 3) world-frame offset -> hinge change
    obj_rot: np.ndarray  # (T, 3, 3) reference object rotation
    weight: np.ndarray  # (T, 2) contact ramp per hand
    fps: float

    def deltas(self, offsets: np.ndarray) -> np.ndarray:
        """(T, 2, A) hinge angle changes for ``offsets`` (2, 3): per hand, metres in the object's frame."""
        world = np.einsum("tij,hj->thi", self.obj_rot, np.asarray(offsets, dtype=np.float64))
        return self.weight[..., None] * np.einsum("thai,thi->tha", self.maps, world)

    def apply(self, qpos: np.ndarray, qvel: np.ndarray, offsets: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Refined copies of the reference ``qpos`` (T, nq) and ``qvel`` (T, nv): arm hinges moved, velocities of
        the moved hinges changed by the offsets' finite difference."""
        d = self.deltas(offsets)
        q, v = qpos.copy(), qvel.copy()
        q[:, self.qpos_index.reshape(-1)] += d.reshape(len(q), -1)
        dv = np.gradient(d, axis=0) * self.fps if len(d) > 1 else np.zeros_like(d)
        v[:, self.dof_index.reshape(-1)] += dv.reshape(len(v), -1)
        return q, v


def contact_ramp(touch: np.ndarray, ramp: int) -> np.ndarray:
    """(T, H) weight: 1 where ``touch`` (T, H) is true, falling linearly to 0 over ``ramp`` frames away from it."""
    T, H = touch.shape
    t = np.arange(T)
    out = np.zeros((T, H))
    for h in range(H):  # two hands, once per sequence
        frames = np.flatnonzero(touch[:, h])
        if frames.size:
            dist = np.abs(t[:, None] - frames[None, :]).min(axis=1)
            out[:, h] = np.clip(1.0 - dist / max(ramp, 1), 0.0, 1.0)
    return out


def arm_chain(skel: Any, wrist_body: int) -> list[int]:
    """Joint indices of the arm chain ending at ``wrist_body``: the wrist and its ``ARM_BODIES - 1`` ancestors."""
    chain, b = [], wrist_body
    for _ in range(ARM_BODIES):
        j = np.flatnonzero(skel.joint_bodies == b)
        if not j.size:
            break
        chain.append(int(j[0]))
        b = int(skel.parents[b])
    return chain


def arm_offset_map(
    scene: Any,
    ref_qpos: np.ndarray,
    obj_quat: np.ndarray,
    touch: np.ndarray,
    fps: float,
    ramp: int = 10,
    damping: float = 0.02,
) -> ArmOffsetMap:
    """The :class:`ArmOffsetMap` of a scene's humanoid along the reference ``ref_qpos`` (T, nq); ``obj_quat``
    (T, 4) wxyz is the carried object's reference orientation, ``touch`` (T, 2) each hand's reference contact."""
    m, skel, roles = scene.model, scene.skeleton, scene.humanoid.roles
    d = mujoco.MjData(m)
    wrists = [int(np.atleast_1d(roles[f"{s}_hand"])[0]) for s in SIDES]
    chains = [arm_chain(skel, w) for w in wrists]
    qidx = np.stack([scene.hinge_qposadr[c].reshape(-1) for c in chains])
    didx = np.stack([scene.hinge_dofadr[c].reshape(-1) for c in chains])
    T, A = len(ref_qpos), qidx.shape[1]
    maps = np.zeros((T, 2, A, 3))
    jacp, jacr = np.zeros((3, m.nv)), np.zeros((3, m.nv))
    for t in range(T):  # preprocessing, once per sequence
        d.qpos[:] = ref_qpos[t]
        mujoco.mj_kinematics(m, d)
        mujoco.mj_comPos(m, d)
        for h, w in enumerate(wrists):
            mujoco.mj_jacBody(m, d, jacp, jacr, int(scene.body_ids[w]))
            J = np.concatenate([jacp[:, didx[h]], jacr[:, didx[h]]])  # (6, A)
            pinv = J.T @ np.linalg.inv(J @ J.T + damping**2 * np.eye(6))
            maps[t, h] = pinv[:, :3]
    return ArmOffsetMap(qidx, didx, maps, quat_to_matrix(obj_quat), contact_ramp(touch, ramp), fps)


class KinematicReplay:
    """One MuJoCo world replaying the reference with the body kinematic and the fingers PD-driven."""

    def __init__(self, env: WristMimicEnv, start: int, stop: int):
        self.m = env.scene.model
        self.d = mujoco.MjData(self.m)
        qpos, qvel = env.reference_state(torch.arange(env.ref.num_frames))
        self.qpos, self.qvel = qpos.numpy(), qvel.numpy()
        self.hinge_q = env.scene.hinge_qposadr.reshape(-1)
        fingers = env.finger_actions.numpy().astype(bool)
        self.fingers = fingers
        self.body_q = np.concatenate([np.arange(7), self.hinge_q[~fingers]])
        self.body_v = np.concatenate([np.arange(6), env.scene.hinge_dofadr.reshape(-1)[~fingers]])
        self.act = env.scene.actuator_ids.reshape(-1)
        self.lo, self.hi = env.scene.ctrl_range[:, 0], env.scene.ctrl_range[:, 1]
        obj = env.scene.dynamic_objects[0]
        self.obj_q = obj.qposadr + np.arange(3)  # the first object's position
        self.obj_pose_q, self.obj_v = obj.qposadr + np.arange(7), obj.dofadr + np.arange(6)
        self.substeps = env.scene.config.substeps
        self.start, self.stop = start, stop
        r = env.ref
        touch = r.hand.numpy().astype(bool)
        self.arms = arm_offset_map(env.scene, self.qpos, r.obj_quat[:, 0].numpy(), touch, float(r.fps))

    def errors(
        self, finger_offset: np.ndarray, wrist_offsets: np.ndarray | None = None, hold_until: int = -1
    ) -> np.ndarray:
        """(stop - start,) object position error (m) at each frame reached, finger targets = start pose + offset,
        each hand moved by ``wrist_offsets`` (2, 3) m in the object's frame while it touches (:class:`ArmOffsetMap`);
        the object is held on its reference (kinematic) before frame ``hold_until``, so the grasp forms on it."""
        m, d, q, v = self.m, self.d, self.qpos, self.qvel
        if wrist_offsets is not None:
            q, v = self.arms.apply(q, v, wrist_offsets)
        d.qpos[:], d.qvel[:] = q[self.start], v[self.start]
        d.act[:] = 0.0
        mujoco.mj_forward(m, d)
        fingers = np.clip(q[self.start][self.hinge_q] + finger_offset, self.lo, self.hi)
        out = []
        for t in range(self.start, self.stop):
            for s in range(self.substeps):
                a = (s + 1) / self.substeps
                pose = (1 - a) * q[t] + a * q[t + 1]
                pose[3:7] /= np.linalg.norm(pose[3:7])
                d.qpos[self.body_q], d.qvel[self.body_v] = pose[self.body_q], v[t][self.body_v]
                d.ctrl[self.act] = np.where(self.fingers, fingers, pose[self.hinge_q])
                mujoco.mj_step(m, d)
                if t < hold_until:  # a kinematic object: on the substep's reference pose after every step
                    qo = pose[self.obj_pose_q]
                    qo[3:] /= np.linalg.norm(qo[3:])
                    d.qpos[self.obj_pose_q], d.qvel[self.obj_v] = qo, v[t][self.obj_v]
            out.append(float(np.linalg.norm(d.qpos[self.obj_q] - q[t + 1][self.obj_q])))
        return np.asarray(out)


def build(args: argparse.Namespace) -> WristMimicEnv:
    if any(not text.startswith("scene_config.") for text in args.set):
        raise SystemExit("--set: only scene_config.FIELD overrides apply here")
    cfg = apply_overrides({"scene_config": to_jsonable(SceneConfig())}, args.set)["scene_config"]
    env = WristMimicEnv.from_file(args.dataset, args.scene, 1, EnvConfig(), scene_config_from_dict(cfg), nthread=1)
    if not env.scene.dynamic_objects:
        raise SystemExit(f"error: {args.dataset}: scene {args.scene} has no dynamic object to carry")
    T = env.ref.num_frames
    if not 0 <= args.start < args.stop < T:
        raise SystemExit(f"error: need 0 <= --start < --stop < {T} (the scene's frames), got {args.start}, {args.stop}")
    return env


def probe(args: argparse.Namespace, log: Any = print) -> dict[str, Any]:
    env = build(args)
    replay = KinematicReplay(env, args.start, args.stop)
    skel, roles = env.scene.skeleton, env.scene.humanoid.roles
    chosen = np.zeros(env.num_hinges, dtype=bool)
    for side in HANDS[args.hands]:
        chosen |= np.repeat(np.isin(skel.joint_bodies, roles[f"{side}_hand"]), 3) & replay.fingers
    if args.synergy > 0:
        closure = closure_coefficients(env.scene)[[("left", "right").index(h) for h in HANDS[args.hands]]]
        basis = args.synergy * closure  # (hands, H): one search dimension per hand
    else:
        basis = np.eye(env.num_hinges)[chosen]  # one search dimension per finger hinge
    n_fingers = len(basis)
    hands = [SIDES.index(h) for h in HANDS[args.hands]]
    n_dims = n_fingers + (3 * len(hands) if args.wrist_offset > 0 else 0)

    def run(xi: np.ndarray) -> np.ndarray:
        offsets = None
        if args.wrist_offset > 0:
            offsets = np.zeros((2, 3))
            offsets[hands] = args.wrist_offset * xi[n_fingers:].reshape(len(hands), 3)
        return replay.errors(xi[:n_fingers] @ basis, offsets, args.hold)

    rng = np.random.default_rng(args.seed)
    mean, sigma = np.zeros(n_dims), args.sigma
    keep = max(args.samples // 8, 2)
    best: tuple[float, np.ndarray, np.ndarray] = (np.inf, mean, np.zeros(0))
    iterations = []
    for it in range(args.iters):
        x = mean + sigma * rng.standard_normal((args.samples, n_dims))
        x[0] = mean
        errs = [run(xi) for xi in x]
        cost = np.array([e.mean() for e in errs])
        elite = np.argsort(cost)[:keep]
        if cost[elite[0]] < best[0]:
            best = (float(cost[elite[0]]), x[elite[0]].copy(), errs[elite[0]])
        mean, sigma = x[elite].mean(axis=0), sigma * 0.85
        row = {
            "iteration": it,
            "nominal": float(cost[0]),
            "best": float(cost.min()),
            "elite": float(cost[elite].mean()),
        }
        iterations.append(row)
        log(
            f"{it}: mean error nominal {100 * row['nominal']:.1f} cm, best {100 * row['best']:.1f}, elite {100 * row['elite']:.1f}"
        )
    frames = list(range(args.start + 1, args.stop + 1))
    log(
        "best sample's object error (cm): "
        + " ".join(f"{f}:{100 * e:.1f}" for f, e in list(zip(frames, best[2], strict=True))[::4])
    )
    result_offsets = {}
    if args.wrist_offset > 0:
        off = args.wrist_offset * best[1][n_fingers:].reshape(len(hands), 3)
        result_offsets = {"wrist_offsets": {SIDES[h]: off[i].tolist() for i, h in enumerate(hands)}}
        log(
            "best wrist offsets (cm, object frame): "
            + ", ".join(
                f"{k} {np.round(100 * np.array(v), 1).tolist()}" for k, v in result_offsets["wrist_offsets"].items()
            )
        )
    return {
        **result_offsets,
        "dimensions": n_dims,
        "iterations": iterations,
        "best_mean_error": best[0],
        "best_errors": dict(zip(frames, best[2].tolist(), strict=True)),
        "best_parameters": best[1].tolist(),
    }


def parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("dataset", type=Path)
    ap.add_argument("--scene", required=True)
    ap.add_argument("--start", type=int, required=True, help="reference frame the replay starts from")
    ap.add_argument("--stop", type=int, required=True, help="last frame reached")
    ap.add_argument("--hands", choices=tuple(HANDS), default="both")
    ap.add_argument("--samples", type=int, default=48)
    ap.add_argument("--iters", type=int, default=10)
    ap.add_argument("--sigma", type=float, default=0.5, help="initial noise (rad; synergy units with --synergy)")
    ap.add_argument("--synergy", type=float, default=0.0, help="> 0: search the grasp synergy (rad per unit)")
    ap.add_argument(
        "--wrist-offset",
        type=float,
        default=0.0,
        help="> 0: also search each hand's offset in the object frame (m per unit)",
    )
    ap.add_argument("--hold", type=int, default=-1, help="hold the object on its reference before this frame")
    ap.add_argument("--set", action="append", default=[], help="scene_config.FIELD=VALUE")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("-o", "--out", type=Path, default=Path("grip_probe.json"))
    return ap


def main() -> None:
    args = parser().parse_args()
    try:
        result = probe(args)
    except InputError as exc:
        raise SystemExit(f"error: {exc}") from None
    with atomic_output(args.out) as tmp:
        Path(tmp).write_text(json.dumps({"args": {k: str(v) for k, v in vars(args).items()}, **result}))
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
