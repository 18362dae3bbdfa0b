"""Static hold probe: can the hands hold the object at all, near the reference's grasp, with nothing else touching it?

Usage:  python scripts/hold_probe.py DATASET.h5 --scene SEQ --frame F [--hands right|left|both]
        [--closures 0.8,1,1.2,1.5,2] [--synergy S] [--floor] [--offset DX,DY,DZ,RX,RY,RZ] [--samples 0 --iters 0 --translate 0.02 --rotate 0.4]
        [--close 10 --hold 12 --frames 40] [--set scene_config.FIELD=VALUE | env.FIELD=VALUE ...] [--seed 0] [-o out.json]

The humanoid stands still in the reference pose of frame F, kinematic (every non-finger degree of freedom set before
each physics substep, as in ``kinematic_grip_probe.py``), optionally moved rigidly by a 6-D offset (m, and a rotation
vector in rad about the first chosen hand's wrist; world frame). Only the chosen hands (wrist and finger bodies) and
the object collide: every other geom (the rest of the humanoid, the floor, supports, other objects) has its
collisions turned off, so whatever keeps the object up is the hands (``--floor`` keeps the floor and static
objects: an object the reference tilts up off the floor, such as ``sub2_largetable_000``'s table, must then be held
up by the hands at its raised end). The object is held on its frame-F reference
pose while the chosen hands' fingers close from open (target 0) to k x the reference's finger angles (clipped to
the joint ranges; with ``--synergy S`` k x S rad along the grasp synergy's closure, :mod:`wristmimic.env.synergy`,
for hands without a finger reference) over ``--close`` frames; at ``--hold`` frames it is released, and it is watched for ``--frames``
frames in all. Reported per candidate: the frames it stayed within 5 cm of its held position after release
(``held``, at most frames - hold) and its displacement at the end (m; a free fall covers g t^2 / 2).

For each closure in ``--closures`` the reference hand (plus ``--offset``) is tried; ``--samples`` > 0 also runs a
cross-entropy search (``--iters`` iterations, the best eighth kept) over the 6-D offset (initial sigma
``--translate`` m and ``--rotate`` rad) and the closure, minimising the final displacement. A diagnostic, not a
training method: a hand that cannot hold the object standing still cannot carry it. It tests holds the fingers make
on their own (hooks, wraps, pinches): kinematic palms posed on a reference that only touches an object do not press
it, so a squeeze between two palms (the synthetic box's carry, which trained policies make by pressing in) is not
held here either. ``reports/README.md`` says what it found on the shared scenes.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

import mujoco
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from kinematic_grip_probe import HANDS, KinematicReplay, build  # noqa: E402

from wristmimic.env.synergy import closure_coefficients  # noqa: E402
from wristmimic.rl.config import to_jsonable  # noqa: E402
from wristmimic.rotations import quat_mul  # noqa: E402
from wristmimic.safe_io import atomic_output  # noqa: E402

DROP = 0.05
"""m: the object counts as held while it stays this close to its held position."""


def _rotvec_quat(rv: np.ndarray) -> np.ndarray:
    """wxyz quaternion of a rotation vector."""
    angle = float(np.linalg.norm(rv))
    if angle < 1e-12:
        return np.array([1.0, 0.0, 0.0, 0.0])
    return np.concatenate([[np.cos(angle / 2)], np.sin(angle / 2) * rv / angle])


class HoldProbe:
    """One world: the kinematic humanoid at one reference frame, only the chosen hands and the object colliding."""

    def __init__(self, args: argparse.Namespace):
        self.env = env = build(
            argparse.Namespace(
                dataset=args.dataset, scene=args.scene, start=args.frame, stop=args.frame + 1, set=args.set
            )
        )
        self.replay = rp = KinematicReplay(env, args.frame, args.frame + 1)
        self.m, self.d = m, d = rp.m, rp.d
        skel, roles = env.scene.skeleton, env.scene.humanoid.roles
        hand_bodies = np.concatenate([np.atleast_1d(roles[f"{s}_hand"]) for s in HANDS[args.hands]])
        self.fingers = np.repeat(np.isin(skel.joint_bodies, hand_bodies), 3) & rp.fingers
        keep = np.zeros(m.nbody, dtype=bool)
        keep[[int(env.scene.body_ids[b]) for b in hand_bodies]] = True
        keep |= np.isin(np.arange(m.nbody), np.unique(m.geom_bodyid[rp.object_geom]))
        if args.floor:  # the floor and static objects too: only the rest of the humanoid is turned off
            keep |= ~np.isin(np.arange(m.nbody), np.asarray(env.scene.body_ids))
        off = ~keep[m.geom_bodyid]
        m.geom_contype[off], m.geom_conaffinity[off] = 0, 0
        self.frame, self.close, self.hold, self.frames = args.frame, args.close, args.hold, args.frames
        self.base = rp.qpos[args.frame].copy()
        d.qpos[:] = self.base
        mujoco.mj_kinematics(m, d)
        wrist = int(np.atleast_1d(roles[f"{HANDS[args.hands][0]}_hand"])[0])
        self.pivot = d.xpos[int(env.scene.body_ids[wrist])].copy()
        self.obj_pose = self.base[rp.obj_pose_q].copy()
        sides = [("left", "right").index(h) for h in HANDS[args.hands]]
        closure = closure_coefficients(env.scene)[sides].sum(axis=0)
        self.closed = args.synergy * closure if args.synergy > 0 else rp.qpos[args.frame][rp.hinge_q]
        """Finger targets at closure 1 (action order): the reference's angles, or the synergy's."""

    def run(self, x: np.ndarray) -> tuple[int, float]:
        """(frames held after release, final displacement in m) for x = (dx, dy, dz, rx, ry, rz, closure)."""
        rp, m, d = self.replay, self.m, self.d
        q = self.base.copy()
        rot = _rotvec_quat(np.asarray(x[3:6], dtype=np.float64))
        rmat = np.zeros(9)
        mujoco.mju_quat2Mat(rmat, rot)
        q[0:3] = rmat.reshape(3, 3) @ (q[0:3] - self.pivot) + self.pivot + np.asarray(x[:3])
        q[3:7] = quat_mul(rot, q[3:7])
        mujoco.mj_resetData(m, d)
        d.qpos[:] = q
        d.qpos[rp.obj_pose_q] = self.obj_pose
        hinges = q[rp.hinge_q]
        start = np.where(self.fingers, 0.0, hinges)
        d.qpos[rp.hinge_q[self.fingers]] = 0.0  # the chosen hands' fingers start open
        target = np.where(self.fingers, np.clip(self.closed * x[6], rp.lo, rp.hi), hinges)
        held, dropped = 0, False
        for t in range(self.frames):
            a = min(t / max(self.close, 1), 1.0)
            d.ctrl[rp.act] = np.clip((1 - a) * start + a * target, rp.lo, rp.hi)
            for _ in range(rp.substeps):
                d.qpos[rp.body_q], d.qvel[rp.body_v] = q[rp.body_q], 0.0
                mujoco.mj_step(m, d)
                if t < self.hold:  # held on its pose after every substep: free from the first substep of frame hold
                    d.qpos[rp.obj_pose_q], d.qvel[rp.obj_v] = self.obj_pose, 0.0
            if t >= self.hold and not dropped:
                dropped = np.linalg.norm(d.qpos[rp.obj_q] - self.obj_pose[:3]) > DROP
                held += not dropped
        return held, float(np.linalg.norm(d.qpos[rp.obj_q] - self.obj_pose[:3]))


def probe(args: argparse.Namespace, log: Any = print) -> dict[str, Any]:
    if not 0 <= args.close <= args.hold < args.frames:
        raise SystemExit(f"error: need 0 <= --close <= --hold < --frames, got {args.close}, {args.hold}, {args.frames}")
    hp = HoldProbe(args)
    offset = np.asarray(args.offset, dtype=np.float64)
    out: dict[str, Any] = {
        "args": {k: to_jsonable(v) for k, v in vars(args).items()},
        "release_frames": args.frames - args.hold,
    }
    nominal = []
    for k in args.closures:
        held, disp = hp.run(np.concatenate([offset, [k]]))
        nominal.append({"closure": k, "held": held, "displacement": disp})
        log(
            f"closure {k:.2f}: held {held} of {args.frames - args.hold} frames after release, displaced {100 * disp:.1f} cm"
        )
    out["nominal"] = nominal
    if args.samples > 0 and args.iters > 0:
        rng = np.random.default_rng(args.seed)
        best = min(nominal, key=lambda r: r["displacement"])
        mu = np.concatenate([offset, [best["closure"]]])
        sd = np.array([args.translate] * 3 + [args.rotate] * 3 + [0.5])
        lo_k, hi_k = min(args.closures), max(args.closures)
        found = (best["displacement"], best["held"], mu.copy())
        its = []
        for it in range(args.iters):
            xs = mu + sd * rng.standard_normal((args.samples, 7))
            xs[:, 6] = np.clip(xs[:, 6], lo_k, hi_k)
            res = [hp.run(x) for x in xs]
            disp = np.array([r[1] for r in res])
            order = np.argsort(disp, kind="stable")
            elite = xs[order[: max(args.samples // 8, 2)]]
            mu, sd = elite.mean(0), elite.std(0) + 1e-4
            i = int(order[0])
            if disp[i] < found[0]:
                found = (float(disp[i]), res[i][0], xs[i].copy())
            its.append({"best": float(disp[i]), "median": float(np.median(disp)), "held_best": res[i][0]})
            log(f"iter {it}: best {100 * disp[i]:.1f} cm (held {res[i][0]}), median {100 * np.median(disp):.1f} cm")
        out["search"] = {
            "iterations": its,
            "best_displacement": found[0],
            "best_held": found[1],
            "best_offset": found[2][:6].tolist(),
            "best_closure": float(found[2][6]),
        }
    return out


def _floats(text: str) -> list[float]:
    return [float(v) for v in text.split(",")]


def parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("dataset", type=Path)
    ap.add_argument("--scene", required=True)
    ap.add_argument("--frame", type=int, required=True, help="reference frame whose pose the hands hold")
    ap.add_argument("--hands", choices=tuple(HANDS), default="both")
    ap.add_argument(
        "--closures", type=_floats, default=[0.8, 1.0, 1.2, 1.5, 2.0], help="k x the reference's finger angles"
    )
    ap.add_argument("--synergy", type=float, default=0.0, help="> 0: close along the grasp synergy (rad per unit)")
    ap.add_argument("--offset", type=_floats, default=[0.0] * 6, help="DX,DY,DZ (m),RX,RY,RZ (rad) of the humanoid")
    ap.add_argument("--samples", type=int, default=0, help="> 0: cross-entropy search over offset and closure")
    ap.add_argument("--iters", type=int, default=6)
    ap.add_argument("--translate", type=float, default=0.02, help="initial search sigma of the translation (m)")
    ap.add_argument("--rotate", type=float, default=0.4, help="initial search sigma of the rotation (rad)")
    ap.add_argument(
        "--floor", action="store_true", help="keep the floor and static objects (an object resting on them, lifted)"
    )
    ap.add_argument("--close", type=int, default=10, help="frames over which the fingers close")
    ap.add_argument("--hold", type=int, default=12, help="frames the object is held before its release")
    ap.add_argument("--frames", type=int, default=40, help="frames simulated in all")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("-o", "--output", type=Path)
    return ap


def main() -> None:
    args = parser().parse_args()
    if len(args.offset) != 6:
        raise SystemExit(f"error: --offset needs 6 numbers (DX,DY,DZ,RX,RY,RZ), got {len(args.offset)}")
    out = probe(args)
    if args.output:
        with atomic_output(args.output) as tmp:
            Path(tmp).write_text(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
