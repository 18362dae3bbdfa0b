"""Kinematic grip probe: can the reference's own wrist path carry the object with any finger pose?

Usage:  python scripts/kinematic_grip_probe.py DATASET.h5 --scene SEQ --start F0 --stop F1
        [--hands right|left|both] [--samples 48] [--iters 10] [--sigma 0.5] [--synergy 0]
        [--set scene_config.FIELD=VALUE | env.FIELD=VALUE ...] [--seed 0] [-o probe.json]

Every non-finger degree of freedom of the humanoid (the root and every body and wrist hinge) follows the reference
exactly: before each physics substep its position (interpolated between the two frames) and velocity are set, so
the wrists are where the mocap puts them whatever the load. The finger hinges are PD-driven to constant targets, the
start frame's reference angle plus an offset, and the objects are free. A cross-entropy search over the offsets of
the chosen hands' finger hinges (``--samples`` per iteration, the cheapest eighth kept, noise ``--sigma`` rad
annealed by 0.85) minimises the mean object-position error over the frames after ``--start`` (plus
``--penetration-weight`` times the deepest penetration of the kinematic body, palms and arms, into the object: a
body of infinite strength can carry an object by pressing into it, which a policy's PD arms cannot). ``--synergy S``
searches one number per hand instead: S times it along the grasp synergy's closure (:mod:`wristmimic.env.synergy`);
with ``--per-finger`` one number per finger, the closure restricted to that finger's chain.

``--wrist-offset W`` also searches, per chosen hand, a constant offset (W m per unit, in the reference object's
frame) applied while the reference hand touches the object, through the arm's hinges only (:class:`wristmimic.env.clearance.ArmOffsetMap`:
the damped pseudo-inverse of the wrist's 6-D Jacobian over the collar, shoulder, elbow and wrist hinges at the
reference pose, ramped in and out over 10 frames), so the hand moves rigidly with the object and keeps its
orientation to first order: can a corrected wrist path carry what the mocap one cannot? ``--hold F`` keeps the
object on its reference (kinematic) before frame F, so the grasp forms on it before the object is released.

A success here (an error that stays small) says the reference's wrist path can carry the object and a policy's
fingers have something to find; a failure says the wrists themselves must leave the reference. A diagnostic, not a
training method: ``reports/README.md`` says what it found on the shared scenes. Prints one line per iteration and
the best sample's error per frame; ``-o`` writes them as JSON, with the best finger targets as ``finger_grip``
(``--set env.finger_grip=[...]`` centres a policy's finger actions on them while the hands touch).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

import mujoco
import numpy as np
import torch

from wristmimic.env.clearance import arm_offset_map
from wristmimic.env.config import EnvConfig, env_config_from_dict
from wristmimic.env.synergy import closure_coefficients
from wristmimic.env.vec_env import WristMimicEnv
from wristmimic.errors import InputError
from wristmimic.rl.config import to_jsonable
from wristmimic.rl.overrides import apply_overrides
from wristmimic.safe_io import atomic_output
from wristmimic.scene import SceneConfig, scene_config_from_dict

HANDS = {"left": ("left",), "right": ("right",), "both": ("left", "right")}
SIDES = ("left", "right")


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
        m = self.m
        fingers_b = {int(env.scene.skeleton.joint_bodies[j]) for j in np.flatnonzero(fingers[::3])}
        kinematic = np.zeros(m.nbody, dtype=bool)  # humanoid bodies the replay sets: all but the finger segments
        kinematic[[int(env.scene.body_ids[b]) for b in range(len(env.scene.body_ids)) if b not in fingers_b]] = True
        carried = np.zeros(m.nbody, dtype=bool)
        carried[[int(m.jnt_bodyid[j]) for j in range(m.njnt) if m.jnt_qposadr[j] == obj.qposadr]] = True
        self.kinematic_geom, self.object_geom = kinematic[m.geom_bodyid], carried[m.geom_bodyid]
        self.penetration = np.zeros(0)
        """(stop - start,) deepest penetration (m) of a kinematic humanoid geom into the object after each frame of
        the last :meth:`errors` call: what a body of infinite strength forces, and a policy's PD arms cannot."""
        r = env.ref
        touch = r.hand.numpy().astype(bool)
        self.arms = arm_offset_map(env.scene, self.qpos, r.obj_quat[:, 0].numpy(), touch, float(r.fps))

    def grip(self, finger_offset: np.ndarray) -> np.ndarray:
        """The finger hinges' PD targets (rad, action order) that :meth:`errors` holds for ``finger_offset``:
        ``env.finger_grip``'s value."""
        return np.clip(self.qpos[self.start][self.hinge_q] + finger_offset, self.lo, self.hi)[self.fingers]

    def errors(
        self, finger_offset: np.ndarray, wrist_offsets: np.ndarray | None = None, hold_until: int = -1
    ) -> np.ndarray:
        """(stop - start,) object position error (m) at each frame reached, finger targets = start pose + offset,
        each hand moved by ``wrist_offsets`` (2, 3) m in the object's frame while it touches (:class:`~wristmimic.env.clearance.ArmOffsetMap`);
        the object is held on its reference (kinematic) before frame ``hold_until``, so the grasp forms on it."""
        m, d, q, v = self.m, self.d, self.qpos, self.qvel
        if wrist_offsets is not None:
            q, v = self.arms.apply(q, v, wrist_offsets)
        d.qpos[:], d.qvel[:] = q[self.start], v[self.start]
        d.act[:] = 0.0
        mujoco.mj_forward(m, d)
        fingers = np.clip(q[self.start][self.hinge_q] + finger_offset, self.lo, self.hi)
        out: list[float] = []
        pen: list[float] = []
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
            g1, g2, dist = d.contact.geom1[: d.ncon], d.contact.geom2[: d.ncon], d.contact.dist[: d.ncon]
            hit = (self.kinematic_geom[g1] & self.object_geom[g2]) | (self.kinematic_geom[g2] & self.object_geom[g1])
            pen.append(float(max(0.0, -dist[hit].min())) if hit.any() else 0.0)
        self.penetration = np.asarray(pen)
        return np.asarray(out)


def build(args: argparse.Namespace) -> WristMimicEnv:
    if any(not text.startswith(("scene_config.", "env.")) for text in args.set):
        raise SystemExit("--set: only scene_config.FIELD and env.FIELD overrides apply here")
    cfg = apply_overrides({"scene_config": to_jsonable(SceneConfig()), "env": to_jsonable(EnvConfig())}, args.set)
    env = WristMimicEnv.from_file(
        args.dataset,
        args.scene,
        1,
        env_config_from_dict(cfg["env"]),
        scene_config_from_dict(cfg["scene_config"]),
        nthread=1,
    )
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
        if args.per_finger:  # one search dimension per finger: the synergy's closure restricted to its chain
            rows = []
            for row, side in zip(basis, HANDS[args.hands], strict=True):
                wrist = int(np.atleast_1d(roles[f"{side}_hand"])[0])
                for child in skel.children(wrist):
                    in_chain = np.repeat(np.isin(skel.joint_bodies, skel.subtree(child)), 3)
                    rows.append(np.where(in_chain, row, 0.0))
            basis = np.stack(rows)
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
        err = replay.errors(xi[:n_fingers] @ basis, offsets, args.hold)
        return err + args.penetration_weight * replay.penetration, err, replay.penetration.copy()

    rng = np.random.default_rng(args.seed)
    mean, sigma = np.zeros(n_dims), args.sigma
    keep = max(args.samples // 8, 2)
    best: tuple[float, np.ndarray, np.ndarray] = (np.inf, mean, np.zeros(0))
    best_pen = np.zeros(0)
    iterations = []
    for it in range(args.iters):
        x = mean + sigma * rng.standard_normal((args.samples, n_dims))
        x[0] = mean
        runs = [run(xi) for xi in x]
        cost = np.array([r[0].mean() for r in runs])
        elite = np.argsort(cost)[:keep]
        if cost[elite[0]] < best[0]:
            best = (float(cost[elite[0]]), x[elite[0]].copy(), runs[elite[0]][1])
            best_pen = runs[elite[0]][2]
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
    log(
        "its deepest kinematic penetration (mm): "
        + " ".join(f"{f}:{1000 * e:.1f}" for f, e in list(zip(frames, best_pen, strict=True))[::4])
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
        "best_mean_error": float(best[2].mean()),
        "best_cost": best[0],
        "best_errors": dict(zip(frames, best[2].tolist(), strict=True)),
        "best_penetration": dict(zip(frames, best_pen.tolist(), strict=True)),
        "best_parameters": best[1].tolist(),
        "finger_grip": replay.grip(best[1][:n_fingers] @ basis).tolist(),
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
        "--penetration-weight",
        type=float,
        default=0.0,
        help="cost = object error + this x the deepest penetration of the kinematic body into the object (m/m)",
    )
    ap.add_argument(
        "--per-finger", action="store_true", help="with --synergy: one closure per finger instead of one per hand"
    )
    ap.add_argument(
        "--wrist-offset",
        type=float,
        default=0.0,
        help="> 0: also search each hand's offset in the object frame (m per unit)",
    )
    ap.add_argument("--hold", type=int, default=-1, help="hold the object on its reference before this frame")
    ap.add_argument("--set", action="append", default=[], help="scene_config.FIELD=VALUE or env.FIELD=VALUE")
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
