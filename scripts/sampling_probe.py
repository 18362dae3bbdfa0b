"""Sampling-based trajectory optimisation probe (MPPI / CEM, as SPIDER uses): does a rollout of the clip exist?

Usage:  python scripts/sampling_probe.py DATASET.h5 --scene SEQ [-o probe.json]
        [--policy RUN_DIR --start FRAME]      # nominal = the policy's mean action + an optimised perturbation
        [--frames 110] [--worlds 64] [--horizon 12] [--knot 4] [--iters 3] [--commit 4]
        [--sigma 0.1] [--finger-sigma 0.2] [--elite 0.1] [--temperature 1.0] [--objective task|reward]
        [--set env.FIELD=VALUE ...] [--seed 0]

Receding horizon from frame 0 (or from ``--start``, reached by the policy alone): every world of the environment
is set to the current state; ``--worlds`` action sequences (knots every ``--knot`` frames, linear in between,
Gaussian noise of ``--sigma`` on body and wrist actions and ``--finger-sigma`` on finger actions around the
nominal; world 0 runs the nominal itself) are rolled out ``--horizon`` frames; the ``--elite`` fraction with the
highest return, softmax-weighted with ``--temperature`` x their return spread, is the new nominal; after
``--iters`` iterations the nominal's first ``--commit`` frames are executed and the window slides. A termination
costs ``--penalty`` x the share of the horizon it cuts off. ``--objective reward`` scores the environment's
reward; ``task`` scores what success needs: 1 per frame alive, + exp(-(object error / 5 cm)^2), + 0.5 x the share
of hands whose contact matches the reference's, - 5 x wrist error (m) - 0.5 x wrist rotation error (rad).

Without ``--policy`` the environment is the CPU recipe's (with ``--set`` overrides; the object controller and the
start-state bank off); with it, the policy's own evaluation environment. Prints one line per committed window
and writes ``-o`` (JSON: arguments and per-frame errors). A diagnostic, not a training method: see
``reports/README.md`` for what it found on ``sub2_largetable_000``.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path
from typing import Any

import torch

from wristmimic.env.config import env_config_from_dict
from wristmimic.env.vec_env import WristMimicEnv
from wristmimic.errors import InputError
from wristmimic.rl.config import preset_env, to_jsonable
from wristmimic.rl.overrides import apply_overrides
from wristmimic.safe_io import atomic_output


def broadcast(state: dict[str, Any], world: int, n: int) -> dict[str, Any]:
    """``state`` (:meth:`WristMimicEnv.state_dict`) with every per-world entry replaced by ``world``'s row."""
    out = dict(state)
    for k, v in state.items():
        if isinstance(v, torch.Tensor) and v.dim() >= 1 and v.shape[0] == n and k != "generator":
            out[k] = v[world : world + 1].expand_as(v).clone()
    return out


def knots_to_sequence(knots: torch.Tensor, horizon: int, spacing: int) -> torch.Tensor:
    """(K, nk, A) knots at frames 0, spacing, 2 spacing, ... -> (K, horizon, A), linear in between."""
    t = torch.arange(horizon, dtype=torch.float32) / spacing
    i0 = t.floor().long().clamp(max=knots.shape[1] - 1)
    i1 = (i0 + 1).clamp(max=knots.shape[1] - 1)
    w = (t - i0.float())[None, :, None]
    return knots[:, i0] * (1 - w) + knots[:, i1] * w


def task_score(errors: dict[str, torch.Tensor]) -> torch.Tensor:
    """(N,) per-frame task score from the environment's evaluation errors (see the module docstring)."""
    match = (errors["sim_hand"] == errors["ref_hand"]).float().mean(-1)
    return (
        1.0
        + torch.exp(-((errors["obj_pos"] / 0.05) ** 2))
        + 0.5 * match
        - 5.0 * errors["wrist_pos"]
        - 0.5 * errors["wrist_rot"]
    )


def build(args: argparse.Namespace) -> tuple[WristMimicEnv, Any]:
    """The environment (all worlds at frame 0) and the policy (or None)."""
    if args.policy:
        from wristmimic.evaluate.policy import load_eval_policy
        from wristmimic.evaluate.trials import make_env

        policy = load_eval_policy(args.policy)
        env = make_env(policy.metadata, args.worlds, nthread=args.nthread, dataset=args.dataset)
    else:
        policy = None
        if any(not text.startswith("env.") for text in args.set):
            raise SystemExit("--set: only env.FIELD overrides apply here")
        cfg = apply_overrides({"env": to_jsonable(preset_env("cpu", "wristmimic"))}, args.set)["env"]
        cfg["starts"]["bank"] = 0.0
        env = WristMimicEnv.from_file(
            args.dataset, args.scene, args.worlds, env_config_from_dict(cfg), seed=args.seed, nthread=args.nthread
        )
    env.eval_info = True
    env.reset(start_frames=torch.zeros(args.worlds, dtype=torch.long))
    return env, policy


def probe(args: argparse.Namespace, log: Any = print) -> list[dict[str, Any]]:
    """Run the receding-horizon optimisation; one record per executed frame."""
    from wristmimic.evaluate.policy import act_rows

    torch.set_num_threads(1)
    env, policy = build(args)
    N, A, T = env.num_worlds, env.action_size, env.ref.num_frames
    finger = ~env.residual_hinges.cpu() if env.cfg.action_mode == "residual" else torch.zeros(A, dtype=torch.bool)
    sigma = torch.where(finger, torch.tensor(args.finger_sigma), torch.tensor(args.sigma))

    def act(obs: torch.Tensor, extra: torch.Tensor) -> torch.Tensor:
        return extra if policy is None else act_rows(policy, obs) + extra

    gen = torch.Generator().manual_seed(args.seed)
    nk = args.horizon // args.knot + 1
    nominal = torch.zeros(nk, A)
    state, frame, records, t0 = env.state_dict(), 0, [], time.perf_counter()
    if args.start:
        if policy is None:
            raise SystemExit("--start needs --policy (the frames before it are the policy's)")
        obs = env.observe()
        for _ in range(args.start):
            obs = env.step(act(obs, torch.zeros(N, A)))[0]
        state, frame = env.state_dict(), args.start
    stop = T - 1 if args.frames <= 0 else min(T - 1, args.frames)
    while frame < stop:
        H = min(args.horizon, T - 1 - frame)
        stats = (0.0, 0.0, 0)
        for _ in range(args.iters):
            env.load_state_dict(broadcast(state, 0, N))
            obs = env.observe()
            noise = torch.randn(N, nk, A, generator=gen) * sigma
            noise[0] = 0.0
            knots = (nominal[None] + noise).clamp(-1.0, 1.0)
            seq = knots_to_sequence(knots, H, args.knot)
            ret, alive = torch.zeros(N), torch.ones(N, dtype=torch.bool)
            for h in range(H):
                obs, r, term, trunc, info = env.step(act(obs, seq[:, h]))
                score = task_score(info["eval"]) if args.objective == "task" else r
                ret += torch.where(alive, score, torch.zeros_like(score))
                ret -= (alive & term).float() * args.penalty * (H - h) / H
                alive &= ~(term | trunc)
            elite = torch.topk(ret, max(1, int(args.elite * N)))
            w = torch.softmax(
                (elite.values - elite.values.max()) / (args.temperature * (elite.values.std(correction=0) + 1e-6)), 0
            )
            nominal = (w[:, None, None] * knots[elite.indices]).sum(0)
            stats = (float(ret[0]), float(elite.values[0]), int(alive.sum()))
        env.load_state_dict(broadcast(state, 0, N))
        obs = env.observe()
        seq = knots_to_sequence(nominal[None].expand(N, -1, -1), H, args.knot)
        ended = False
        for h in range(min(args.commit, H)):
            obs, r, term, trunc, info = env.step(act(obs, seq[:, h]))
            e = {k: (v[0].tolist() if v.dim() > 1 else float(v[0])) for k, v in info["eval"].items()}
            reason = env.reason_name(int(info["termination_reason"][0])) if bool(term[0]) else ""
            records.append({"frame": frame + h + 1, "reward": float(r[0]), "termination": reason, **e})
            if bool(term[0]) or bool(trunc[0]):
                ended = True
                break
        state, frame = env.state_dict(), records[-1]["frame"]
        last = records[-1]
        log(
            f"frame {frame:4d}  return nominal {stats[0]:7.2f} best {stats[1]:7.2f} (alive {stats[2]:3d}/{N})  "
            f"object {last['obj_pos']:.3f} m  wrist {last['wrist_pos']:.3f} m  hands {last['sim_hand']} "
            f"(ref {last['ref_hand']})  {last['termination']}  {time.perf_counter() - t0:.0f} s"
        )
        if ended:
            break
        shift = min(args.commit, H) // args.knot
        if shift:
            nominal = torch.cat([nominal[shift:], nominal[-1:].expand(shift, -1)], 0)
    env.close()
    return records


def parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("dataset", type=Path)
    ap.add_argument("--scene", required=True)
    ap.add_argument("-o", "--out", type=Path, default=Path("probe.json"))
    ap.add_argument("--policy", help="training run folder: its mean action is the nominal")
    ap.add_argument("--start", type=int, default=0, help="frames run by the policy alone first")
    ap.add_argument("--frames", type=int, default=0, help="stop at this frame (0: the clip's end)")
    ap.add_argument("--worlds", type=int, default=64, help="samples per iteration")
    ap.add_argument("--horizon", type=int, default=12)
    ap.add_argument("--knot", type=int, default=4, help="frames between knots")
    ap.add_argument("--iters", type=int, default=3, help="iterations per window")
    ap.add_argument("--commit", type=int, default=4, help="frames executed per window")
    ap.add_argument("--sigma", type=float, default=0.1)
    ap.add_argument("--finger-sigma", type=float, default=0.2)
    ap.add_argument("--elite", type=float, default=0.1)
    ap.add_argument("--temperature", type=float, default=1.0)
    ap.add_argument("--penalty", type=float, default=20.0)
    ap.add_argument("--objective", choices=("task", "reward"), default="task")
    ap.add_argument("--set", action="append", default=[], help="env.FIELD=VALUE (without --policy)")
    ap.add_argument("--nthread", type=int, default=None)
    ap.add_argument("--seed", type=int, default=0)
    return ap


def main() -> None:
    args = parser().parse_args()
    try:
        records = probe(args)
    except InputError as exc:
        raise SystemExit(f"error: {exc}") from None
    with atomic_output(args.out) as tmp:
        Path(tmp).write_text(json.dumps({"args": {k: str(v) for k, v in vars(args).items()}, "frames": records}))
    print(f"wrote {args.out}: {len(records)} frames")


if __name__ == "__main__":
    main()
