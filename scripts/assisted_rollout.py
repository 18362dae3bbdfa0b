"""Assisted frame-0 rollouts: how far does a run's policy get with the training-only object controller at fixed gains?

Usage:  python scripts/assisted_rollout.py RUN_DIR [--gains 1,0.8,0.6,0.4,0.2,0] [--weights latest|deployed] [--loads]
        [-o out.json]

One world per gain, each started at frame 0 in the run's own training environment (its `config.json`: env and scene
settings, with the object controller's motors), the policy's mean action at every step (no noise), and the virtual
object controller's wrench scaled by that world's gain for the whole rollout. Prints, per gain, the frame the
rollout ended at and why (``end``: the clip's last frame reached unterminated). With the curriculum gated on
completed episodes (``env.object_controller.gate``) this is the measure of progress before unassisted success: the
smallest gain at which the whole clip is completed (``reports/README.md``, ``gated_controller_20261207/``).

``--loads``: who carries the (first dynamic) object. After every step the world's state is re-evaluated
(``mj_forward`` with the step's controls) and the forces on the object are summed by what exerts them: the hands'
bodies, the rest of the humanoid, the supports (floor and static objects), other dynamic objects and the object
controller. Reported per rollout over the frames where the reference has a hand on the object: ``lift``, each
source's mean vertical force as a share of the object's weight, and ``drive`` (N), each source's mean force along
the reference object's horizontal direction of motion over the frames where it moves faster than 5 cm/s (floor
friction against a drag is negative). A curriculum that works moves the load from the controller to the hands.

``--trace``: where and how each rollout drifts off, per frame (stepped-to state, before any reset): the object's
centre error (cm) and rotation error (deg) as the evaluation measures them, the mean wrist error (cm), the root's
offset from the reference root (x, y, z, cm; absent at the terminating frame, whose world is already reset) and
which hands touch the object in simulation and in the reference. Printed every 8th frame and at the last one.
"""

from __future__ import annotations

import argparse
import json
from dataclasses import replace
from pathlib import Path
from typing import Any

import mujoco
import numpy as np
import torch

from wristmimic.env.config import env_config_from_dict
from wristmimic.env.rewards import DRIVE_MIN_SPEED
from wristmimic.env.terminations import REASONS
from wristmimic.env.vec_env import WristMimicEnv
from wristmimic.evaluate.policy import load_eval_policy
from wristmimic.safe_io import atomic_output
from wristmimic.scene import scene_config_from_dict

SOURCES = ("hands", "body", "supports", "objects", "controller")


class LoadMeter:
    """Forces on one dynamic object by source (:data:`SOURCES`), summed per world and frame (see ``--loads``)."""

    def __init__(self, env: WristMimicEnv) -> None:
        scene, m = env.scene, env.scene.model
        self.env, self.m, self.data = env, m, mujoco.MjData(m)
        self.body = scene.dynamic_objects[0].body_id
        self.weight = float(m.body_subtreemass[self.body] * np.linalg.norm(m.opt.gravity))
        hands = np.concatenate([scene.body_ids[h.cpu().numpy()] for h in env.hands])
        # geom -> source index (-1: the object itself)
        source = np.full(m.nbody, SOURCES.index("supports"))  # world body and static objects
        source[scene.body_ids] = SOURCES.index("body")
        source[hands] = SOURCES.index("hands")
        for o in scene.dynamic_objects:
            source[o.body_id] = SOURCES.index("objects")
        source[self.body] = -1
        self.geom_source = source[m.geom_bodyid]
        self.force_cols = env._voc_cols[0, :3].cpu().numpy() if env.has_object_controller else None
        self._f6 = np.zeros(6)

    def __call__(self, world: int) -> np.ndarray:
        """(len(SOURCES), 3) world-frame forces on the object in ``world`` at its current state and controls."""
        env, m, d = self.env, self.m, self.data
        d.qpos[:] = env.backend.qpos[world].cpu().numpy()
        d.qvel[:] = env.backend.qvel[world].cpu().numpy()
        d.ctrl[:] = env._ctrl[world].cpu().numpy()
        mujoco.mj_forward(m, d)
        out = np.zeros((len(SOURCES), 3))
        for c in range(d.ncon):
            con = d.contact[c]
            s1, s2 = self.geom_source[con.geom1], self.geom_source[con.geom2]
            if (s1 == -1) == (s2 == -1):
                continue
            mujoco.mj_contactForce(m, d, c, self._f6)
            on2 = con.frame.reshape(3, 3).T @ self._f6[:3]  # the force geom1 exerts on geom2, world frame
            out[s1 if s2 == -1 else s2] += on2 if s2 == -1 else -on2
        if self.force_cols is not None:
            out[SOURCES.index("controller")] = d.ctrl[self.force_cols]
        return out


def summarize_loads(forces: np.ndarray, frames: np.ndarray, ref: Any, weight: float) -> dict[str, dict[str, float]]:
    """``{"lift": {source: share of the weight}, "drive": {source: N}}`` from (F, len(SOURCES), 3) forces at the
    stepped-to ``frames`` (F,): means over the frames where the reference has a hand on the object (lift) and,
    of those, where the reference object moves horizontally faster than 5 cm/s (drive, along that motion)."""
    touch = ref.hand[frames].any(-1).cpu().numpy()
    vel = ref.obj_linvel[frames, 0, :2].cpu().numpy()
    speed = np.linalg.norm(vel, axis=-1)
    moving = touch & (speed > DRIVE_MIN_SPEED)  # the frames the drive factor looks at
    lift = forces[touch, :, 2].mean(0) / weight if touch.any() else np.full(len(SOURCES), np.nan)
    along = np.einsum("fsk,fk->fs", forces[moving, :, :2], vel[moving] / speed[moving, None])
    drive = along.mean(0) if moving.any() else np.full(len(SOURCES), np.nan)
    return {
        "lift": {s: round(float(v), 4) for s, v in zip(SOURCES, lift, strict=True)},
        "drive": {s: round(float(v), 2) for s, v in zip(SOURCES, drive, strict=True)},
    }


def trace_rows(env: WristMimicEnv, info: dict[str, Any], frame: int, live: list[int], done: torch.Tensor) -> list[dict]:
    """One ``--trace`` row per world in ``live`` at the stepped-to ``frame`` (see the module's docstring)."""
    e = info["eval"]
    root = env.sim_state().body_pos[:, 0] - env.ref.body_pos[frame, 0]  # reset worlds: not the stepped-to state
    rows = []
    for i in live:
        row = {
            "frame": frame,
            "obj_cm": round(100 * float(e["obj_pos"][i]), 2),
            "obj_deg": round(float(np.degrees(float(e["obj_rot"][i]))), 2),
            "wrist_cm": round(100 * float(e["wrist_pos"][i]), 2),
            "root_cm": None if bool(done[i]) else [round(100 * float(v), 2) for v in root[i]],
            "sim_hand": [int(v) for v in e["sim_hand"][i]],
            "ref_hand": [int(v) for v in e["ref_hand"][i]],
        }
        rows.append(row)
    return rows


def rollouts(
    run: Path, gains: list[float], weights: str = "latest", loads: bool = False, trace: bool = False
) -> list[dict[str, Any]]:
    """Per gain: ``{"gain", "frames", "reason"}`` of one deterministic frame-0 rollout with that much help (with
    ``loads``: also ``"lift"`` and ``"drive"``, see :func:`summarize_loads`; with ``trace``: ``"trace"``, one row
    per frame, see :func:`trace_rows`)."""
    policy = load_eval_policy(run, weights)
    cfg = json.loads((run / "config.json").read_text())
    env_cfg = env_config_from_dict(cfg["env"])
    scene_cfg = replace(scene_config_from_dict(cfg["scene_config"]), object_actuators=True)
    env = WristMimicEnv.from_file(
        cfg["dataset"]["path"], cfg["scene"], len(gains), env_cfg, scene_cfg, nthread=1, seed=0
    )
    obs, _ = env.reset(start_frames=torch.zeros(len(gains), dtype=torch.long))
    env.object_gain = 1.0
    env.object_scale = torch.tensor(gains, dtype=torch.float32)  # each world's share of the gain: its own gain
    out: list[dict[str, Any] | None] = [None] * len(gains)
    meter = LoadMeter(env) if loads else None
    forces: list[list[np.ndarray]] = [[] for _ in gains]
    rows: list[list[dict]] = [[] for _ in gains]
    env.eval_info = trace
    with torch.no_grad():
        for step in range(env.ref.num_frames):
            obs, _, term, trunc, info = env.step(policy.act(obs, deterministic=True))
            done = term | trunc
            live = [i for i in range(len(gains)) if out[i] is None]
            if meter is not None:  # the state just stepped to: not in a world that ended (and was reset) here
                for i in live:
                    if not bool(done[i]):
                        forces[i].append(meter(i))
            if trace:
                for i, row in zip(live, trace_rows(env, info, step + 1, live, done), strict=True):
                    rows[i].append(row)
            for i in torch.nonzero(done).flatten().tolist():
                if out[i] is None:
                    reason = REASONS[int(info["termination_reason"][i])] if bool(term[i]) else "end"
                    out[i] = {"gain": gains[i], "frames": step + 1, "reason": reason}
            if all(o is not None for o in out):
                break
    env.close()
    res = [
        o if o is not None else {"gain": g, "frames": env.ref.num_frames, "reason": "end"}
        for o, g in zip(out, gains, strict=True)
    ]
    if meter is not None:
        for r, f in zip(res, forces, strict=True):
            stacked = np.stack(f) if f else np.zeros((0, len(SOURCES), 3))
            r.update(summarize_loads(stacked, np.arange(1, len(f) + 1), env.ref, meter.weight))
    if trace:
        for r, t in zip(res, rows, strict=True):
            r["trace"] = t
    return res


def print_trace(res: dict[str, Any]) -> None:
    """Every 8th ``--trace`` row of one rollout and its last."""
    print(f"  gain {res['gain']:.2f}: frame  object cm  deg  wrist cm  root offset cm (x y z)  hands sim/ref")
    rows = res["trace"]
    for row in rows:
        if row["frame"] % 8 and row is not rows[-1]:
            continue
        root = " ".join(f"{v:6.1f}" for v in row["root_cm"]) if row["root_cm"] is not None else "   (reset)        "
        print(
            f"  {row['frame']:17d}  {row['obj_cm']:9.1f} {row['obj_deg']:4.1f}  {row['wrist_cm']:8.1f}  {root:>22s}"
            f"  {row['sim_hand']}/{row['ref_hand']}"
        )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("run", type=Path)
    ap.add_argument("--gains", type=lambda t: [float(v) for v in t.split(",")], default=[1.0, 0.8, 0.6, 0.4, 0.2, 0.0])
    ap.add_argument("--weights", choices=("latest", "deployed"), default="latest")
    ap.add_argument("--loads", action="store_true", help="also report who carries the object (see above)")
    ap.add_argument("--trace", action="store_true", help="also report the errors frame by frame (see above)")
    ap.add_argument("-o", "--output", type=Path)
    args = ap.parse_args()
    if not (args.run / "config.json").is_file():
        raise SystemExit(f"error: {args.run}: not a training run folder (no config.json)")
    if any(not 0.0 <= g <= 10.0 for g in args.gains):
        raise SystemExit(f"error: --gains: each gain must be in [0, 10], got {args.gains}")
    res = rollouts(args.run, args.gains, args.weights, args.loads, args.trace)
    for r in res:
        line = f"gain {r['gain']:.2f}: {r['frames']} frames ({r['reason']})"
        if args.loads:
            line += "; lift " + " ".join(f"{k} {v:.2f}" for k, v in r["lift"].items())
            line += "; drive (N) " + " ".join(f"{k} {v:.0f}" for k, v in r["drive"].items())
        print(line)
        if args.trace:
            print_trace(r)
    if args.output:
        with atomic_output(args.output) as tmp:
            Path(tmp).write_text(json.dumps({"run": str(args.run), "weights": args.weights, "rollouts": res}, indent=1))


if __name__ == "__main__":
    main()
