"""``export``: rollouts of a trained policy written as canonical sequences (schema 1.2), a demonstration for the
run's embodiment that validates, trains, evaluates and views like any converted file.

Trials run with evaluation's machinery (:func:`wristmimic.evaluate.trials.run_trials`: seeds, protocol, deployed
sigma, early terminations); a :class:`StateRecorder` on the environment's ``on_step`` hook keeps every world's
state per step in (worlds, frames, ...) tensors, batched (no Python loop over worlds per step), and each completed
trial becomes one sequence ``<scene>__sim_<seed>`` (``<scene>__sim_mean`` for the policy-mean trial) of its frames
0..n, up to its last simulated frame when it ended early. Humanoid (swapped hands included) and objects are copied
from the run's dataset. Extra arrays ``sim/actions``, ``sim/pd_targets``, ``sim/contact_force``; provenance in the
root attribute ``export`` and each sequence's ``extra["export"]`` (see ``docs/format.md``).

>>> export_rollouts(load_eval_policy("runs/RUN"), Path("sim.h5"), trials=100, successful_only=True)
"""

from __future__ import annotations

import json
import math
import re
import time
from collections.abc import Callable
from dataclasses import dataclass, fields, replace
from pathlib import Path
from typing import Any

import numpy as np
import torch

from wristmimic.convert import contacts as C
from wristmimic.convert.common import contact_summary
from wristmimic.env.observations import SimState
from wristmimic.env.vec_env import WristMimicEnv
from wristmimic.errors import InputError
from wristmimic.evaluate.noise import trial_seeds
from wristmimic.evaluate.policy import EvalPolicy
from wristmimic.evaluate.protocol import NOISE_MODES, InitialStateNoise, Protocol, load_protocol
from wristmimic.evaluate.runner import _check_dataset, _env_dict, _progress
from wristmimic.evaluate.trials import Records, TrialSettings, make_env, run_trials
from wristmimic.format.records import SequenceRecord
from wristmimic.humanoid.kinematics import joint_quat_from_hinges
from wristmimic.rotations import quat_normalize
from wristmimic.safe_io import check_output_file, sha256_file
from wristmimic.sim.backend import BACKENDS

CONVERTER = "export"
SOURCE_FORMAT = "wristmimic-run"
LABELS_METHOD = "simulation: 1 where the body touches a dynamic object (MuJoCo contact), else 0 (unknown)"


@dataclass
class ExportResult:
    """What an export wrote."""

    out: Path
    sequences: list[str]
    trials_run: int
    successes: int
    seconds: float
    frames: int
    """Frames stepped by the trials (as evaluate counts them)."""


@dataclass(frozen=True)
class _Plan:
    """Which trials to run and how: the settings, trial numbers (None: 0..n-1) and how to describe them."""

    settings: TrialSettings
    early_termination: str
    n: int
    trial_ids: np.ndarray | None
    mode: str  # "mean", "trials" or "from-eval"
    backend: str
    source: dict[str, Any]
    eval_success: dict[int, bool]


# -- recording ---------------------------------------------------------------------------------------------
class StateRecorder:
    """Per-world buffers of one trial's frames, filled through ``env.on_step`` and :meth:`begin` (frame 0).

    Row ``t`` of ``actions`` / ``pd_targets`` is what was applied from frame t to t + 1; ``contact_force`` and
    ``touch`` of frame t are the contacts that acted while reaching it (frame 0: those of the start state)."""

    def __init__(self, env: WristMimicEnv, emit: Callable[[Records, int, dict[str, np.ndarray]], None]):
        self.env, self.emit = env, emit
        N, T, dev = env.num_worlds, env.ref.num_frames, env.device
        B, D, O = env.scene.skeleton.num_bodies, env.num_hinges, len(env.scene.dynamic_objects)
        self._qcols = torch.cat([torch.arange(7, device=dev), env._hinge_qpos])  # root free joint, then hinges
        self._rows = torch.arange(N, device=dev)

        def z(*shape: int, dtype: torch.dtype = torch.float32) -> torch.Tensor:
            return torch.zeros(N, T, *shape, dtype=dtype, device=dev)

        self.buf = {
            "qpos": z(7 + D),
            "body_pos": z(B, 3),
            "body_quat": z(B, 4),
            "obj_pos": z(O, 3),
            "obj_quat": z(O, 4),
            "contact_force": z(B, 3),
            "touch": z(B, dtype=torch.bool),
            "actions": z(env.action_size),
            "pd_targets": z(D),
        }
        env.on_step = self._on_step

    def _put(self, rows: torch.Tensor, f: torch.Tensor, s: dict[str, torch.Tensor]) -> None:
        for k, v in s.items():
            self.buf[k][rows, f] = v

    def _on_step(self, s: SimState, action: torch.Tensor) -> None:
        env, f, rows = self.env, self.env.steps, self._rows
        self._put(
            rows,
            f,
            {
                "qpos": env.backend.qpos[:, self._qcols].to(torch.float32),
                "body_pos": s.body_pos,
                "body_quat": s.body_quat,
                "obj_pos": s.obj_pos,
                "obj_quat": s.obj_quat,
                "contact_force": s.contact_force,
                "touch": s.contact_obj,
            },
        )
        self._put(rows, f - 1, {"actions": action.to(torch.float32), "pd_targets": env._ctrl[:, env._act_cols]})

    def begin(self, worlds: torch.Tensor) -> None:
        """Frame 0 of the trials starting in ``worlds``, from the backend's state and sensors."""
        env = self.env
        w = worlds.to(env.device)
        sd, i = env.backend.sensordata[w].to(torch.float32), env._tidx
        f = torch.zeros(len(w), dtype=torch.long, device=env.device)
        self._put(
            w,
            f,
            {
                "qpos": env.backend.qpos[w][:, self._qcols].to(torch.float32),
                "body_pos": sd[:, i["body_pos"]],
                "body_quat": sd[:, i["body_quat"]],
                "obj_pos": sd[:, i["obj_pos"]],
                "obj_quat": sd[:, i["obj_quat"]],
                "contact_force": sd[:, i["contact"]][..., 1:],
                "touch": (sd[:, i["touch"]] > 0).any(-1),
            },
        )

    def end(self, worlds: torch.Tensor, records: Records) -> None:
        """Hand each completed trial's frames 0..n to ``emit`` (one copy to the host for all of them)."""
        n = records["frames_completed"].astype(np.int64) + 1
        w = worlds.to(self.env.device)
        m = int(n.max())
        host = {k: v[w, :m].cpu().numpy() for k, v in self.buf.items()}
        for j in range(len(n)):
            self.emit(records, j, {k: v[j, : n[j]] for k, v in host.items()})


# -- sequences ---------------------------------------------------------------------------------------------
def _wrap(angles: np.ndarray) -> np.ndarray:
    """Hinge angles into [-pi, pi] (only those outside: the same rotation, as the format requires)."""
    out = angles.copy()
    big = np.abs(out) > np.pi
    out[big] = np.remainder(out[big] + np.pi, 2 * np.pi) - np.pi
    return out


def _finite_frames(a: dict[str, np.ndarray]) -> int:
    """Frames before the first one with a non-finite pose (a simulation that blew up)."""
    keys = ("qpos", "body_pos", "body_quat", "obj_pos", "obj_quat", "contact_force")
    bad = np.zeros(len(a["qpos"]), dtype=bool)
    for k in keys:
        bad |= ~np.isfinite(a[k].reshape(len(bad), -1)).all(1)
    return int(np.argmax(bad)) if bad.any() else len(bad)


def _unit(q: np.ndarray) -> np.ndarray:
    return quat_normalize(q).astype(np.float32)


class _SequenceBuilder:
    """Turns a trial's recorded frames into a :class:`SequenceRecord` of the source's humanoid and objects."""

    def __init__(self, env: WristMimicEnv, source: Any, roles: dict[str, np.ndarray], params: C.ContactParams):
        self.scene, self.source, self.roles, self.params = env.scene, source, roles, params
        m = env.scene.model
        self.objects = [  # (dynamic index or -1, static pose)
            (
                [d.id for d in env.scene.dynamic_objects].index(o.id) if o.dynamic else -1,
                m.body_pos[o.body_id].astype(np.float32),
                _unit(m.body_quat[o.body_id]),
            )
            for o in env.scene.objects
        ]

    def __call__(self, a: dict[str, np.ndarray], extra: dict[str, Any]) -> SequenceRecord:
        T = len(a["qpos"])
        B, J = self.scene.skeleton.num_bodies, self.scene.skeleton.num_bodies - 1
        angles = _wrap(a["qpos"][:, 7:].reshape(T, J, 3).astype(np.float64))
        pos = np.empty((T, len(self.objects), 3), np.float32)
        quat = np.empty((T, len(self.objects), 4), np.float32)
        for k, (d, p, q) in enumerate(self.objects):
            pos[:, k] = a["obj_pos"][:, d] if d >= 0 else p
            quat[:, k] = _unit(a["obj_quat"][:, d]) if d >= 0 else q
        labels = a["touch"].astype(np.int8)
        c = contact_summary(labels, self.roles, self.params)
        body_pos = a["body_pos"]
        last = lambda x: np.concatenate([x[:-1], x[-2:-1]]) if T > 1 else x  # noqa: E731 - no step follows
        return SequenceRecord(
            humanoid_id=self.source.humanoid_id,
            object_ids=list(self.source.object_ids),
            subject=self.source.subject,
            dataset=self.source.dataset,
            text=self.source.text,
            root_pos=a["qpos"][:, 0:3],
            root_quat=_unit(a["qpos"][:, 3:7]),
            joint_quat=joint_quat_from_hinges(angles).astype(np.float32),
            joint_angles=angles.astype(np.float32),
            body_pos=body_pos,
            body_quat=_unit(a["body_quat"]),
            source_body_pos=body_pos,
            source_body_pos_valid=np.ones(B, dtype=bool),
            object_pos=pos,
            object_quat=quat,
            contact_labels=labels,
            contact_geometric=labels,
            contact_distance=np.where(labels > 0, 0.0, np.inf).astype(np.float32),
            hand_contact=c["hand"],
            object_contact=c["hand"].any(1),
            first_contact_frame=c["first"],
            contact_window=c["window"],
            contact_meta={
                "labels_method": LABELS_METHOD,
                "geometric_method": "same as labels",
                "distance_method": "0 where the body touches a dynamic object, else inf (no distance computed)",
                "params": self.params.to_dict(),
                "t_b": self.params.t_b,
                "t_a": self.params.t_a,
            },
            source_file=extra.get("checkpoint", ""),
            extra={"export": extra},
            optional={
                "sim/actions": last(a["actions"]),
                "sim/pd_targets": last(a["pd_targets"]),
                "sim/contact_force": a["contact_force"],
            },
        )


# -- which trials ------------------------------------------------------------------------------------------
def parse_rows(spec: str) -> list[int]:
    """``"0-9,15"`` -> [0, ..., 9, 15] (trial numbers of an evaluation's table)."""
    out: list[int] = []
    for part in (p.strip() for p in spec.split(",")):
        m = re.fullmatch(r"(\d+)(?:-(\d+))?", part)
        if not m or (m.group(2) is not None and int(m.group(2)) < int(m.group(1))):
            raise InputError(None, "--rows", f"{part!r} in {spec!r}", "trial numbers and ranges, e.g. 0-9,15")
        a, b = int(m.group(1)), int(m.group(2) or m.group(1))
        out += range(a, b + 1)
    return sorted(set(out))


def _contact_params(meta: dict[str, Any]) -> C.ContactParams:
    """The source sequence's contact parameters (window t_b / t_a, min_run), else the defaults."""
    p = meta.get("params") if isinstance(meta.get("params"), dict) else {}
    names = {f.name for f in fields(C.ContactParams)}
    kw = {k: v for k, v in p.items() if k in names}
    for k in ("t_b", "t_a"):
        if isinstance(meta.get(k), int | np.integer):
            kw[k] = int(meta[k])
    return C.ContactParams(**kw)


def _from_eval(folder: Path, meta: dict[str, Any], policy: EvalPolicy, rows: str | None, ok_only: bool) -> tuple:
    """(settings, early termination, backend, trial numbers, table success by trial) of an evaluation's rows."""
    import pandas as pd

    manifest = folder / "eval.json"
    if not manifest.is_file():
        raise InputError(folder, "eval.json", "missing", "an evaluation folder written by `wristmimic evaluate`")
    try:
        ev = json.loads(manifest.read_text())
        settings = TrialSettings(
            int(ev["base_seed"]),
            str(ev["noise"]),
            float(ev["max_object_position_error_m"]),
            float(ev["min_contact_ratio"]),
            InitialStateNoise(**ev.get("initial_state_noise", {})),
        )
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise InputError(manifest, None, f"cannot be read ({type(exc).__name__})", "an evaluation's settings") from None
    if ev.get("scene") != meta["scene"] or ev.get("checkpoint_sha256") != meta.get("checkpoint_sha256"):
        raise InputError(
            manifest, "checkpoint_sha256", "is an evaluation of another policy or scene", "an evaluation of this run"
        )
    if settings.noise == "actions" and not math.isclose(
        float(ev.get("action_sigma", math.nan)), float(policy.sigma.mean()), rel_tol=1e-6
    ):
        raise InputError(
            manifest,
            "action_sigma",
            f"{ev.get('action_sigma')} but the policy deploys {float(policy.sigma.mean()):g}",
            "--deploy-std as the evaluation used it",
        )
    table = folder / f"{meta['scene']}.parquet"
    if not table.is_file():
        raise InputError(table, None, "missing", "the per-trial table of a finished evaluation")
    df = pd.read_parquet(table, columns=["trial", "seed", "success"])
    if not (
        df["seed"].to_numpy() == trial_seeds(settings.base_seed, torch.tensor(df["trial"].to_numpy(np.int64))).numpy()
    ).all():
        raise InputError(table, "seed", "does not match the trial numbers and eval.json's base_seed", "an intact table")
    if rows is not None:
        want = parse_rows(rows)
        missing = sorted(set(want) - set(df["trial"].tolist()))
        if missing:
            raise InputError(table, "--rows", f"no trial {missing[0]}", f"trials 0-{int(df['trial'].max())}")
        df = df[df["trial"].isin(want)]
    if ok_only:
        df = df[df["success"]]
    if df.empty:
        raise InputError(table, "--rows", "selects no trial" + (" that succeeded" if ok_only else ""), "some rows")
    success = dict(zip(df["trial"].astype(int).tolist(), df["success"].astype(bool).tolist(), strict=True))
    return settings, str(ev.get("early_termination", "run")), ev.get("backend", "cpu"), df["trial"].to_numpy(), success


def _plan(
    policy: EvalPolicy,
    protocol: Protocol,
    trials: int | None,
    noise: str | None,
    seed: int | None,
    from_eval: Path | None,
    rows: str | None,
    ok_only: bool,
    backend: str | None,
) -> _Plan:
    meta = policy.metadata
    if noise is not None and noise not in NOISE_MODES:
        raise InputError(None, "--noise", f"{noise!r}", f"one of {', '.join(NOISE_MODES)}")
    if seed is not None and not 0 <= seed < 2**63:
        raise InputError(None, "--seed", f"{seed}", "an integer in [0, 2^63)")
    if trials is not None and trials < 1:
        raise InputError(None, "--trials", f"{trials}", "an integer >= 1")
    if from_eval is not None:
        if noise is not None or seed is not None:
            raise InputError(None, "--noise/--seed", "given with --from-eval", "the evaluation's own (leave them out)")
        settings, term, ev_backend, ids, success = _from_eval(Path(from_eval), meta, policy, rows, ok_only)
        if backend is not None and backend != ev_backend:
            raise InputError(None, "--backend", f"{backend} but the evaluation ran on {ev_backend}", ev_backend)
        ids = ids[:trials] if trials is not None else ids
        src = {"from_eval": str(Path(from_eval).resolve())}
        return _Plan(settings, term, len(ids), ids, "from-eval", ev_backend, src, success)
    if rows is not None:
        raise InputError(None, "--rows", "without --from-eval", "--from-eval EVAL_DIR")
    base = TrialSettings.from_protocol(protocol)
    base = replace(base, base_seed=protocol.base_seed if seed is None else int(seed))
    if trials is None:  # the policy mean from frame 0: an initial-state trial with zero perturbation
        if noise is not None:
            raise InputError(None, "--noise", "without --trials", "--trials N (the default is the policy mean)")
        mean = replace(base, noise="initial-state", initial_state_noise=InitialStateNoise(0.0, 0.0))
        src = {"protocol": protocol.name}
        return _Plan(mean, protocol.early_termination, 1, None, "mean", backend or "cpu", src, {})
    settings = replace(base, noise=noise or protocol.noise)
    src = {"protocol": protocol.name}
    return _Plan(settings, protocol.early_termination, int(trials), None, "trials", backend or "cpu", src, {})


def _provenance(meta: dict[str, Any], plan: _Plan, ds_path: Path, env: WristMimicEnv, policy: EvalPolicy) -> dict:
    from wristmimic.rl.config import to_jsonable

    s = plan.settings
    actions = {
        "mean": "policy mean (no noise)",
        "actions": "policy mean + sigma * normal(seed, step, index)",
        "initial-state": "policy mean from a seeded perturbation of the frame-0 state",
    }["mean" if plan.mode == "mean" else s.noise]
    return {
        "run": meta.get("run_dir", ""),
        "checkpoint": meta.get("checkpoint", ""),
        "checkpoint_sha256": meta.get("checkpoint_sha256", ""),
        "dataset": str(ds_path.resolve()),
        "dataset_sha256": meta.get("dataset_sha256", ""),
        "scene": meta["scene"],
        "variant": meta.get("variant", ""),
        "iteration": meta.get("iteration"),
        "train_seed": meta.get("train_seed"),
        "ref_frames": meta.get("ref_frames"),
        "mode": plan.mode,
        **plan.source,
        "actions": actions,
        "noise": "none" if plan.mode == "mean" else s.noise,
        "base_seed": s.base_seed,
        **({"action_sigma": float(policy.sigma.mean())} if plan.mode != "mean" and s.noise == "actions" else {}),
        **(
            {"initial_state_noise": to_jsonable(s.initial_state_noise)}
            if plan.mode != "mean" and s.noise == "initial-state"
            else {}
        ),
        "max_object_position_error_m": s.max_obj_pos_err_m,
        "min_contact_ratio": s.min_contact_ratio,
        "early_termination": plan.early_termination,
        "backend": plan.backend,
        "physics": to_jsonable(env.scene.config),
        "env": _env_dict(meta.get("env")),
    }


# -- the export --------------------------------------------------------------------------------------------
def export_rollouts(
    policy: EvalPolicy,
    out: Path,
    *,
    trials: int | None = None,
    successful_only: bool = False,
    from_eval: Path | None = None,
    rows: str | None = None,
    protocol: Protocol | None = None,
    noise: str | None = None,
    seed: int | None = None,
    num_envs: int = 256,
    nthread: int | None = None,
    dataset: Path | None = None,
    backend: str | None = None,
    backend_options: dict | None = None,
    force: bool = False,
    progress: bool = True,
) -> ExportResult:
    """Run the chosen trials of ``policy`` and write them to ``out`` as canonical sequences (atomically: on any
    error or Ctrl-C nothing is left). Default: one trial, the policy mean from frame 0; ``trials``: trials
    0..n-1 as ``evaluate`` runs them (``protocol``, ``noise``, ``seed``); ``from_eval``: rows (``rows``: trial
    numbers, default all) of an evaluation's table, by their seeds. ``successful_only`` keeps the successes."""
    from wristmimic.format.reader import open_dataset
    from wristmimic.format.writer import DatasetWriter

    meta = policy.metadata
    out = Path(out)
    if out.exists() and not force:
        raise InputError(out, "--out", "already exists", "a new file name, or --force to replace it")
    check_output_file(out)
    if num_envs < 1:
        raise InputError(None, "--num-envs", f"{num_envs}", "an integer >= 1")
    if backend is not None and backend not in BACKENDS:
        raise InputError(None, "--backend", f"{backend!r}", f"one of {', '.join(BACKENDS)}")
    plan = _plan(
        policy, protocol or load_protocol("paper"), trials, noise, seed, from_eval, rows, successful_only, backend
    )
    ds_path = Path(dataset or meta["dataset"])
    _check_dataset(meta, ds_path)  # moved or changed: one line, before anything is written
    with open_dataset(ds_path) as ds:
        seq = ds.sequence(meta["scene"])
        humanoid = ds.humanoid(seq.humanoid_id)
        objects = {oid: ds.object(oid) for oid in seq.object_ids}
        params = _contact_params(seq.contact_meta)
        source_dataset = str(ds.attrs.get("source_dataset", ""))
    t0 = time.perf_counter()
    env = make_env(meta, min(num_envs, plan.n), plan.early_termination, nthread, ds_path, plan.backend, backend_options)
    written: list[str] = []
    successes, frames = 0, 0
    try:
        if hasattr(policy, "to"):
            policy.to(env.device)  # type: ignore[attr-defined]
        prov = _provenance(meta, plan, ds_path, env, policy)
        build = _SequenceBuilder(env, seq, humanoid.roles, params)
        inputs = {ds_path.name: meta.get("dataset_sha256") or sha256_file(ds_path)}
        if meta.get("checkpoint"):
            inputs[Path(meta["checkpoint"]).name] = meta.get("checkpoint_sha256", "")
        writer = DatasetWriter(
            out,
            source_dataset=source_dataset,
            source_format=SOURCE_FORMAT,
            converter=CONVERTER,
            input_sha256=inputs,
            extra_attrs={"export": prov},
            link_repeats=True,  # source_body_pos is body_pos, contacts/geometric is contacts/labels: written once
        )
        with writer as w, _progress(f"export {meta['scene']}", 0, plan.n, progress) as advance:
            w.add_humanoid(seq.humanoid_id, humanoid)
            for oid, rec in objects.items():
                w.add_object(oid, rec)

            def emit(r: Records, j: int, arrays: dict[str, np.ndarray]) -> None:
                nonlocal successes
                ok = bool(r["success"][j])
                successes += ok
                if successful_only and not ok:
                    return
                n_ok = _finite_frames(arrays)
                if n_ok < 2:
                    return  # blew up at once: nothing to export
                arrays = {k: v[:n_ok] for k, v in arrays.items()}
                trial, trial_seed = int(r["trial"][j]), int(r["seed"][j])
                reason = str(r["termination_reason"][j])
                if n_ok < int(r["frames_completed"][j]) + 1:
                    ended = "non-finite state"
                elif bool(r["terminated"][j]):
                    ended = f"terminated ({reason})"
                else:
                    ended = "end of the reference"
                extra = {
                    **prov,
                    "trial": trial,
                    "seed": None if plan.mode == "mean" else trial_seed,
                    "success": ok,
                    "terminated": bool(r["terminated"][j]),
                    "termination_reason": reason,
                    "ended": ended,
                    "frames": n_ok,
                    "frames_completed": int(r["frames_completed"][j]),
                    "frames_total": int(r["frames_total"][j]),
                    **{
                        k: float(r[k][j])
                        for k in ("obj_pos_err_cm", "obj_rot_err_deg", "wrist_pos_err_cm", "wrist_rot_err_deg")
                    },
                    "contact_ratio": float(r["contact_ratio"][j]),
                }
                if trial in plan.eval_success:
                    extra["eval_success"] = plan.eval_success[trial]
                sid = f"{meta['scene']}__sim_{'mean' if plan.mode == 'mean' else trial_seed}"
                w.add_sequence(sid, build(arrays, extra))
                written.append(sid)

            recorder = StateRecorder(env, emit)
            frames = run_trials(
                env,
                policy,
                plan.settings,
                0,
                plan.n,
                lambda r: advance(len(r["trial"])),
                recorder=recorder,
                trial_ids=plan.trial_ids,
            )
            if not written:
                what = "succeeded" if successful_only else "stayed finite for 2 frames"
                raise InputError(out, None, f"none of the {plan.n} trials {what}; nothing written", "a better policy")
            summary = {**prov, "trials": plan.n, "successes": successes, "sequences": len(written)}
            w.set_attr("export", summary)
    finally:
        env.on_step = None
        env.close()
    return ExportResult(out, sorted(written), plan.n, successes, time.perf_counter() - t0, frames)


# -- replay (round trip) -----------------------------------------------------------------------------------
@dataclass
class ReplayError:
    """How far a PD replay of an exported sequence strays from its recorded poses (max over frames, m)."""

    body_pos_m: float
    object_pos_m: float
    body_pos_mean_m: float
    object_pos_mean_m: float


def replay_sequence(
    path: str | Path, sequence_id: str, *, targets: str = "joint_angles", scene_config: Any = None
) -> ReplayError:
    """Replay ``sequence_id`` of an exported file in its own scene: start from its frame 0 (velocities by finite
    differences, as the environment resets) and drive the PD controller with its ``joint_angles`` of the next
    frame (with the environment's velocity feed-forward) or its recorded ``sim/pd_targets``; compare body and
    dynamic-object positions with the recorded ones."""
    from wristmimic.env.config import EnvConfig

    if targets not in ("joint_angles", "pd_targets"):
        raise ValueError(f"targets: {targets!r}")
    env = WristMimicEnv.from_file(path, sequence_id, 1, config=EnvConfig(), scene_config=scene_config, nthread=1)
    try:
        r = env.ref
        T = r.num_frames
        pd = None
        if targets == "pd_targets":
            from wristmimic.format.reader import open_dataset

            with open_dataset(path) as ds:
                pd = torch.as_tensor(ds.sequence(sequence_id).array("sim/pd_targets"))
        env.reset(start_frames=torch.zeros(1, dtype=torch.long))
        ctrl = env._ctrl.clone()
        body, obj = [env.sim_state().body_pos[0]], [env.sim_state().obj_pos[0]]
        for t in range(T - 1):
            if pd is None:
                target = r.joint_angles[t + 1] + env._ff_time * r.joint_vel[t + 1]
            else:
                target = pd[t]
            ctrl[0, env._act_cols] = torch.maximum(torch.minimum(target, env._hi), env._lo)
            env.backend.step(ctrl, env.scene.config.substeps)
            s = env.sim_state()
            body.append(s.body_pos[0])
            obj.append(s.obj_pos[0])
        db = torch.linalg.vector_norm(torch.stack(body) - r.body_pos, dim=-1)
        do = torch.linalg.vector_norm(torch.stack(obj) - r.obj_pos, dim=-1)
        return ReplayError(float(db.max()), float(do.max()) if do.numel() else 0.0, float(db.mean()),
                           float(do.mean()) if do.numel() else 0.0)  # fmt: skip
    finally:
        env.close()
