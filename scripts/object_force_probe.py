"""How hard must the hands push or pull to move the object along its reference?

The humanoid's collisions are switched off and the training-only virtual object controller
(``EnvConfig.object_controller``, the same PD wrench training applies at gain 1) alone drives the object along its
reference, against gravity, the floor and any supports. The force it applies each control step is what the hands
would have to supply to carry the object along its reference; the object's position and rotation errors say
whether even this controller can follow the reference. Printed per frame (every ``--every``) and written as JSON.

    python scripts/object_force_probe.py DATASET --scene SEQ [--gain-scale S] [--set scene_config.FIELD=VALUE]
"""

from __future__ import annotations

import argparse
import json
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import torch

from wristmimic.env.config import variant_config
from wristmimic.env.vec_env import WristMimicEnv
from wristmimic.errors import InputError
from wristmimic.rl.config import to_jsonable
from wristmimic.rl.overrides import apply_overrides
from wristmimic.rotations import quat_angle
from wristmimic.safe_io import atomic_output
from wristmimic.scene import SceneConfig, scene_config_from_dict


def build(args: argparse.Namespace) -> WristMimicEnv:
    """One world of the scene with object actuators, no episode end, the humanoid's contacts off."""
    if any(not text.startswith("scene_config.") for text in args.set):
        raise SystemExit("--set: only scene_config.FIELD overrides apply here")
    if not (np.isfinite(args.gain_scale) and args.gain_scale > 0):
        raise SystemExit("--gain-scale: a finite number > 0")
    sc = apply_overrides({"scene_config": to_jsonable(SceneConfig())}, args.set)["scene_config"]
    sc = replace(scene_config_from_dict(sc), object_actuators=True)
    cfg = variant_config("wristmimic", wrist_resets=False)
    oc, k = cfg.object_controller, args.gain_scale
    cfg = replace(
        cfg,
        object_controller=replace(oc, kp=oc.kp * k, kd=oc.kd * k**0.5, kr=oc.kr * k, dr=oc.dr * k**0.5),
        termination=replace(
            cfg.termination, fall_height=-1e3, body_error=1e3, object_error=1e3, contact_lost_frames=10**9
        ),
    )
    env = WristMimicEnv.from_file(args.dataset, args.scene, 1, cfg, sc, seed=0, nthread=1)
    if not env.scene.dynamic_objects:
        raise SystemExit(f"error: {args.dataset}: scene {args.scene} has no dynamic object")
    m = env.scene.model
    humanoid = np.isin(m.geom_bodyid, env.scene.body_ids)
    m.geom_contype[humanoid], m.geom_conaffinity[humanoid] = 0, 0
    env.object_gain = 1.0
    return env


def probe(env: WristMimicEnv) -> dict[str, Any]:
    """Step the clip once from frame 0: per frame reached, the controller's world force on the first dynamic object
    (N, held over the step into that frame) and the object's position (m) and rotation (rad) errors."""
    o = env.scene.dynamic_objects[0]
    cols = env._voc_cols[0, :3]
    zero = torch.zeros(1, env.action_size)
    frames, force, pos_err, rot_err = [], [], [], []

    def record(s: Any, _action: torch.Tensor) -> None:  # the state reached, before the clip's end resets it
        f = int(env.frame[0])
        frames.append(f)
        pos_err.append(float(torch.linalg.vector_norm(s.obj_pos[0, 0] - env.ref.obj_pos[f, 0])))
        rot_err.append(float(quat_angle(s.obj_quat[0, 0].numpy(), env.ref.obj_quat[f, 0].numpy())))

    env.reset(start_frames=torch.zeros(1, dtype=torch.long))
    env.on_step = record
    for _ in range(env.ref.num_frames - 1):
        ctrl = env.prepare_step(zero)
        force.append(ctrl[0, cols].numpy().astype(float))
        env.backend.step(ctrl, env.scene.config.substeps)
        env.finish_step(zero)
    env.on_step = None
    F = np.asarray(force)
    weight = float(env.scene.model.body_subtreemass[o.body_id]) * 9.81
    return {
        "object": o.id,
        "weight_n": weight,
        "frames": frames,
        "force_n": F.tolist(),
        "horizontal_n": np.hypot(F[:, 0], F[:, 1]).tolist(),
        "pos_err_m": pos_err,
        "rot_err_rad": rot_err,
    }


def parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("dataset", type=Path)
    ap.add_argument("--scene", required=True)
    ap.add_argument("--gain-scale", type=float, default=1.0, help="stiffness x S, damping x sqrt(S)")
    ap.add_argument("--set", action="append", default=[], help="scene_config.FIELD=VALUE")
    ap.add_argument("--every", type=int, default=6, help="print every N frames")
    ap.add_argument("-o", "--out", type=Path, default=Path("object_force_probe.json"))
    return ap


def main() -> None:
    args = parser().parse_args()
    try:
        out = probe(build(args))
    except InputError as exc:
        raise SystemExit(f"error: {exc}") from None
    print(f"{out['object']}: weight {out['weight_n']:.0f} N")
    for i, f in enumerate(out["frames"]):
        if f % max(args.every, 1) == 0:
            F = np.round(out["force_n"][i]).astype(int).tolist()
            print(
                f"frame {f:4d}  force {F} N  horizontal {out['horizontal_n'][i]:5.0f} N  "
                f"error {100 * out['pos_err_m'][i]:5.1f} cm {np.degrees(out['rot_err_rad'][i]):5.1f} deg"
            )
    with atomic_output(args.out) as tmp:
        Path(tmp).write_text(json.dumps({"args": {k: str(v) for k, v in vars(args).items()}, **out}))
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
