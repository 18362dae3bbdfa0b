"""Assisted frame-0 rollouts: how far does a run's policy get with the training-only object controller at fixed gains?

Usage:  python scripts/assisted_rollout.py RUN_DIR [--gains 1,0.8,0.6,0.4,0.2,0] [--weights latest|deployed] [-o out.json]

One world per gain, each started at frame 0 in the run's own training environment (its `config.json`: env and scene
settings, with the object controller's motors), the policy's mean action at every step (no noise), and the virtual
object controller's wrench scaled by that world's gain for the whole rollout. Prints, per gain, the frame the
rollout ended at and why (``end``: the clip's last frame reached unterminated). With the curriculum gated on
completed episodes (``env.object_controller.gate``) this is the measure of progress before unassisted success: the
smallest gain at which the whole clip is completed (``reports/README.md``, ``gated_controller_20261207/``).
"""

from __future__ import annotations

import argparse
import json
from dataclasses import replace
from pathlib import Path
from typing import Any

import torch

from wristmimic.env.config import env_config_from_dict
from wristmimic.env.terminations import REASONS
from wristmimic.env.vec_env import WristMimicEnv
from wristmimic.evaluate.policy import load_eval_policy
from wristmimic.safe_io import atomic_output
from wristmimic.scene import scene_config_from_dict


def rollouts(run: Path, gains: list[float], weights: str = "latest") -> list[dict[str, Any]]:
    """Per gain: ``{"gain", "frames", "reason"}`` of one deterministic frame-0 rollout with that much help."""
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
    with torch.no_grad():
        for step in range(env.ref.num_frames):
            obs, _, term, trunc, info = env.step(policy.act(obs, deterministic=True))
            for i in torch.nonzero(term | trunc).flatten().tolist():
                if out[i] is None:
                    reason = REASONS[int(info["termination_reason"][i])] if bool(term[i]) else "end"
                    out[i] = {"gain": gains[i], "frames": step + 1, "reason": reason}
            if all(o is not None for o in out):
                break
    env.close()
    return [
        o if o is not None else {"gain": g, "frames": env.ref.num_frames, "reason": "end"}
        for o, g in zip(out, gains, strict=True)
    ]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("run", type=Path)
    ap.add_argument("--gains", type=lambda t: [float(v) for v in t.split(",")], default=[1.0, 0.8, 0.6, 0.4, 0.2, 0.0])
    ap.add_argument("--weights", choices=("latest", "deployed"), default="latest")
    ap.add_argument("-o", "--output", type=Path)
    args = ap.parse_args()
    if not (args.run / "config.json").is_file():
        raise SystemExit(f"error: {args.run}: not a training run folder (no config.json)")
    if any(not 0.0 <= g <= 10.0 for g in args.gains):
        raise SystemExit(f"error: --gains: each gain must be in [0, 10], got {args.gains}")
    res = rollouts(args.run, args.gains, args.weights)
    for r in res:
        print(f"gain {r['gain']:.2f}: {r['frames']} frames ({r['reason']})")
    if args.output:
        with atomic_output(args.output) as tmp:
            Path(tmp).write_text(json.dumps({"run": str(args.run), "weights": args.weights, "rollouts": res}, indent=1))


if __name__ == "__main__":
    main()
