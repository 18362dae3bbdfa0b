"""The on-policy training loop: collect a rollout, update, log, checkpoint (rsl_rl's ``OnPolicyRunner``)."""

from __future__ import annotations

import contextlib
import copy
import dataclasses
import json
import math
import signal
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np
import torch

from wristmimic.env.vec_env import WristMimicEnv
from wristmimic.errors import InputError, WristmimicError
from wristmimic.rl.checkpoint import (
    CHECKPOINT_NAME,
    CheckpointWriter,
    rng_state,
    save_checkpoint,
    set_rng_state,
    snapshot,
)
from wristmimic.rl.config import PPOConfig
from wristmimic.rl.curriculum import ObjectCurriculum, hand_adhesion_gain, root_assist_gain
from wristmimic.rl.logger import EpisodeStats, MetricsCsv, train_progress
from wristmimic.rl.networks import ActorCritic, upgrade_state_dict
from wristmimic.rl.ppo import PPO
from wristmimic.rl.storage import RolloutStorage
from wristmimic.threads import torch_threads

_clock = time.monotonic
"""The clock of time-based checkpoints (a test can replace it)."""


class TrainingError(WristmimicError):
    """Training stopped in an iteration (non-finite values, a write that failed): one line naming the run folder,
    the iteration, what went wrong and which checkpoint the folder keeps."""

    def __init__(self, run_dir: Path, iteration: int, problem: str, saved_iteration: int | None, kept: str = ""):
        self.run_dir, self.iteration, self.problem, self.saved_iteration = run_dir, iteration, problem, saved_iteration
        if not kept:
            kept = (
                "no checkpoint written yet"
                if saved_iteration is None
                else f"last good checkpoint kept at iteration {saved_iteration}"
            )
        self.kept = kept
        super().__init__(f"{run_dir}: iteration {iteration}: {problem} ({kept})")


class Runner:
    """PPO on one :class:`WristMimicEnv`, writing ``metrics.csv`` and ``checkpoint.pt`` into ``run_dir``.

    ``config_text`` (the run's JSON config) and ``metadata`` (scene id, variant, dataset sha256, ...) are stored
    in every checkpoint so that a policy can be loaded from the checkpoint alone.
    """

    def __init__(
        self,
        env: WristMimicEnv,
        cfg: PPOConfig,
        seed: int,
        run_dir: Path,
        config_text: str,
        metadata: dict,
        dataset_file: Path | None = None,
    ):
        self.env, self.cfg, self.run_dir = env, cfg, Path(run_dir)
        self.config_text, self.metadata = config_text, metadata
        self.dataset_file = dataset_file
        torch.manual_seed(seed)  # network initialisation (on the CPU, then moved: the same weights on any device)
        dev = env.device
        self.gen = torch.Generator(device=dev).manual_seed(seed)  # action noise and minibatch order
        self.obs, _ = env.reset(seed=seed)
        self.policy = ActorCritic(
            env.observation_size,
            env.action_size,
            cfg.actor_hidden,
            cfg.critic_hidden,
            cfg.log_std,
            cfg.obs_clip,
            cfg.learn_std,
            cfg.min_log_std,
        ).to(dev)
        if cfg.held_actions == "fingers":
            held = torch.ones(env.action_size, dtype=torch.bool, device=env.finger_actions.device)
            held[: env.num_hinges] = env.finger_actions  # the grasp-synergy actions are finger actions too
            self.policy.active.copy_((~held).to(self.policy.active.dtype))
        self.alg = PPO(self.policy, cfg)
        self.ema_net: ActorCritic | None = None
        """An exponential moving average of ``policy`` (``cfg.deploy_ema`` > 0), else None."""
        if cfg.deploy_ema > 0.0:
            self.ema_net = copy.deepcopy(self.policy).requires_grad_(False)
        self.best: dict[str, Any] | None = None
        """``cfg.deploy_best``: the best periodically evaluated policy so far (``policy`` weights, ``iteration``,
        ``frames``, ``eval_success_rate``), else None."""
        self.storage = RolloutStorage(cfg.horizon, cfg.num_envs, env.observation_size, env.action_size, dev)
        self.noise = torch.zeros(cfg.num_envs, env.action_size, device=dev)
        if cfg.noise_correlation > 0.0:  # the AR(1) process starts from its stationary (standard normal) law
            self.noise = torch.randn(self.noise.shape, generator=self.gen, device=dev)
        """(N, A) the exploration noise of the last step (temporally correlated when ``noise_correlation`` > 0)."""
        self.stats = EpisodeStats(env.ref.num_frames)
        self.iteration, self.frames, self.seconds = 0, 0, 0.0
        self.curriculum = ObjectCurriculum(env.cfg.object_controller, env.ref.num_frames)
        if self.curriculum.gain > 0 and not env.has_object_controller:
            raise ValueError("the object curriculum needs a training scene with SceneConfig(object_actuators=True)")
        env.object_gain = self.curriculum.gain
        self._weight_ramp = env.cfg.object_controller.enabled and env.cfg.object_controller.weight_zero_by_frames > 0
        if self._weight_ramp:
            env.object_weight_gain = self.curriculum.weight_gain(0)
        hold = env.cfg.object_controller.start_hold_frames
        if hold > 0 and not env.has_object_controller:
            raise ValueError("object_controller.start_hold_frames needs a training scene with object actuators")
        env.object_start_hold = hold
        self._root_assist = env.cfg.root_assist.enabled
        if self._root_assist and not env.has_root_assist:
            raise ValueError("the root assist needs a training scene with SceneConfig(root_actuators=True)")
        env.root_gain = root_assist_gain(env.cfg.root_assist, 0)
        self._adhesion = env.cfg.hand_adhesion.enabled
        if self._adhesion and not env.has_hand_adhesion:
            raise ValueError("the hands' adhesion needs a training scene with SceneConfig(hand_adhesion=True)")
        env.adhesion_gain = hand_adhesion_gain(env.cfg.hand_adhesion, 0)
        env.eval_info = False  # evaluation errors are computed by the periodic evaluation's own environment
        self._eval_env: WristMimicEnv | None = None
        self.stop_requested = False
        self.metrics: MetricsCsv | None = None
        self.saved_iteration: int | None = None
        """Iteration of the checkpoint in ``run_dir`` (None: none written or loaded)."""
        self._last_save = _clock()
        self._writer: CheckpointWriter | None = None
        """The background checkpoint writer while :meth:`learn` runs."""
        self._obs_ok = torch.ones(cfg.horizon + 1, cfg.num_envs, dtype=torch.bool, device=dev)
        """(H + 1, N) whether each world's raw observation was finite at each step of the rollout (and after it)."""

    def learn(self, max_frames: int, progress: bool = True, should_stop: Callable[[], bool] | None = None) -> str:
        """Train until ``max_frames`` environment frames, Ctrl-C or ``should_stop()`` (asked after each iteration,
        e.g. a Ray driver's stop request); returns ``"finished"`` / ``"interrupted"`` (a checkpoint is saved).

        A checkpoint is due after the first iteration, then every ``checkpoint_every`` iterations and whenever
        ``checkpoint_seconds`` have passed since the last one (0, the default: after every iteration). It is
        written in the background (:class:`CheckpointWriter`) while the next iteration runs; that iteration
        waits for the write after its update (a failed write raises there), before its ``metrics.csv`` row, so a
        kill loses at most the iteration being written and the one in progress. Every iteration checks that its
        observations, actions, rewards, values, losses, parameters, optimiser state and normaliser are finite; if
        not, or if a write failed, :class:`TrainingError` is raised, ``metrics.csv`` is cut back to the last
        checkpoint (which is kept as it was) and nothing else is written."""
        self.metrics = self.metrics or MetricsCsv(self.run_dir / "metrics.csv")
        desc = f"{self.metadata['scene']} [{self.metadata['variant']}]"
        first = True
        self._last_save = _clock()
        self._writer = CheckpointWriter(self.run_dir / CHECKPOINT_NAME)
        try:
            with stop_on_ctrl_c(self), train_progress(desc, self.frames, max_frames, progress) as bar:
                while self.frames < max_frames and not self.stop_requested:
                    t0 = time.perf_counter()
                    gain, weight_gain, root_gain = self.env.object_gain, self.env.object_weight_gain, self.env.root_gain
                    adhesion_gain = self.env.adhesion_gain
                    starts_before = self.env.start_counts.clone()
                    if self.cfg.final_std > 0.0:  # the sigma schedule (a fixed sigma: a buffer, saved with the policy)
                        self.policy.log_std_param.fill_(self.cfg.log_std_at(self.frames))
                    episode_row = self.collect()
                    losses = self.update()
                    self._average_deployed(self.iteration + 1)
                    self._collect_write()  # the previous iteration's checkpoint: on disk before this one's row
                    self.check_finite(self.iteration + 1, losses)
                    self.storage.clear()
                    dt = time.perf_counter() - t0
                    self.iteration += 1
                    self.frames += self.cfg.batch_size
                    terminations = sum(v for k, v in episode_row.items() if k.startswith("termination/"))
                    self.env.object_gain = self.curriculum.update(
                        terminations, self.cfg.batch_size, self.frames, episodes=int(episode_row["episodes"])
                    )
                    if self._weight_ramp:
                        self.env.object_weight_gain = self.curriculum.weight_gain(self.frames)
                    self.env.root_gain = root_assist_gain(self.env.cfg.root_assist, self.frames)
                    self.env.adhesion_gain = hand_adhesion_gain(self.env.cfg.hand_adhesion, self.frames)
                    evaluation = self.periodic_eval() if self._eval_due() else {}
                    self._keep_best(evaluation)
                    self.seconds += time.perf_counter() - t0
                    row = {"iteration": self.iteration, "frames": self.frames, "seconds": self.seconds}
                    row |= {"frames_per_s": self.cfg.batch_size / dt, **episode_row, **losses}
                    row["curriculum/object_gain"] = gain
                    if self._weight_ramp:
                        row["curriculum/object_weight_gain"] = weight_gain
                    if self._root_assist:
                        row["curriculum/root_gain"] = root_gain
                    if self._adhesion:
                        row["curriculum/adhesion_gain"] = adhesion_gain
                    if self.env.bank is not None:  # share of this iteration's mid-clip starts restored from the bank
                        later, banked = (self.env.start_counts - starts_before).tolist()
                        row["starts/banked"] = banked / later if later else math.nan
                    row |= {k: evaluation.get(k, math.nan) for k in EVAL_COLUMNS}
                    if self.cfg.eval_confirm_trials > 0:
                        row |= {k: evaluation.get(k, math.nan) for k in CONFIRM_COLUMNS}
                    try:
                        self.metrics.write(row)
                    except InputError as exc:
                        raise self._error(f"metrics.csv {exc.problem}") from None
                    bar.update(self.frames, row)
                    if first or self._checkpoint_due():
                        self.save(wait=False)
                    first = False
                    if should_stop is not None and should_stop():
                        self.stop_requested = True
            self._collect_write()
            if self.saved_iteration != self.iteration:
                self.save()
        except BaseException:
            with contextlib.suppress(BaseException):  # a write in flight may still land: keep its rows
                self._collect_write()
            self._rollback_metrics()
            raise
        finally:
            self._writer.close()
            self._writer = None
        return "interrupted" if self.stop_requested else "finished"

    @torch.no_grad()
    def _average_deployed(self, updates: int) -> None:
        """Move the deployed average toward the latest weights (``cfg.deploy_ema``; nothing when off)."""
        if self.ema_net is None:
            return
        w = 1.0 - self.cfg.ema_decay(updates)
        latest = self.policy.state_dict()
        for key, avg in self.ema_net.state_dict().items():
            if avg.is_floating_point():
                avg.lerp_(latest[key], w)
            else:
                avg.copy_(latest[key])

    @property
    def candidate(self) -> ActorCritic:
        """The network the periodic evaluation tries: the moving average when ``cfg.deploy_ema`` > 0, else the
        latest weights."""
        return self.policy if self.ema_net is None else self.ema_net

    def _keep_best(self, evaluation: dict[str, float]) -> None:
        """``cfg.deploy_best``: keep the evaluated candidate if it ranks at least as high as the best so far, by
        strict success rate first (the object kept within 10 cm of its reference in every frame), then by the
        paper's success rate."""
        rate = evaluation.get("eval/success_rate")
        strict = evaluation.get("eval/strict_success_rate", 0.0)
        if not self.cfg.deploy_best or rate is None:
            return
        best = (self.best.get("eval_strict_success_rate", 0.0), self.best["eval_success_rate"]) if self.best else None
        if best is not None and (strict, rate) < best:
            return
        trials, extra = self.cfg.eval_trials, self.cfg.eval_confirm_trials
        if extra > 0 and (strict, rate) != (0.0, 0.0):  # a candidate with no success has nothing to confirm
            more = self._eval_trials(trials, trials + extra)
            strict = (strict * trials + float(more["strict_success"].sum())) / (trials + extra)
            rate = (rate * trials + float(more["success"].sum())) / (trials + extra)
            trials += extra
            evaluation |= {"eval/confirm_success_rate": rate, "eval/confirm_strict_success_rate": strict}
            if best is not None and (strict, rate) < best:
                return
        weights = {k: v.detach().clone() for k, v in self.candidate.state_dict().items()}
        self.best = {"policy": weights, "iteration": self.iteration, "frames": self.frames, "eval_success_rate": rate}
        self.best |= {"eval_strict_success_rate": strict, "eval_trials": trials}

    def deployment(self) -> tuple[dict[str, torch.Tensor] | None, dict[str, Any]]:
        """The weights evaluation, ``view`` and ``export`` load (None: the latest) and what they are: ``weights``
        (``latest``, ``ema`` or ``best``), ``iteration``, ``frames`` (and the best's ``eval_success_rate``)."""
        if self.best is not None:
            return self.best["policy"], {k: v for k, v in self.best.items() if k != "policy"} | {"weights": "best"}
        info = {"iteration": self.iteration, "frames": self.frames}
        if self.ema_net is not None:
            return self.ema_net.state_dict(), info | {"weights": "ema"}
        return None, info | {"weights": "latest"}

    def _checkpoint_due(self) -> bool:
        c = self.cfg
        return self.iteration % c.checkpoint_every == 0 or _clock() - self._last_save >= c.checkpoint_seconds

    def _collect_write(self) -> None:
        """Wait for the background checkpoint write, if one is in flight: on success it is the folder's checkpoint
        (``saved_iteration``); a failed one raises :class:`TrainingError` naming its iteration."""
        done = None if self._writer is None else self._writer.collect()
        if done is None:
            return
        iteration, exc = done
        if exc is None:
            self.saved_iteration = iteration
        elif isinstance(exc, InputError):
            raise self._error(f"{CHECKPOINT_NAME} {exc.problem}", iteration) from None
        else:
            raise exc

    def _error(self, problem: str, iteration: int | None = None) -> TrainingError:
        return TrainingError(
            self.run_dir, self.iteration if iteration is None else iteration, problem, self.saved_iteration
        )

    def _rollback_metrics(self) -> None:
        """After a failure: ``metrics.csv`` keeps exactly the rows of the checkpoint (none without one)."""
        path = self.run_dir / "metrics.csv"
        with contextlib.suppress(OSError, WristmimicError, ValueError):
            if self.saved_iteration is None:
                path.unlink(missing_ok=True)
            else:
                self.metrics = MetricsCsv(path, keep_until=self.saved_iteration)

    # -- non-finite values ---------------------------------------------------------------------------------
    def _state_tensors(self) -> list[tuple[str, torch.Tensor]]:
        """The learned state a checkpoint saves: parameters, normaliser buffers and optimiser moments."""
        out = [(f"policy parameter {k}", v) for k, v in self.policy.state_dict().items() if v.is_floating_point()]
        if self.ema_net is not None:
            avg = self.ema_net.state_dict().items()
            out += [(f"moving average {k}", v) for k, v in avg if v.is_floating_point()]
        if self.best is not None:
            out += [(f"best policy {k}", v) for k, v in self.best["policy"].items() if v.is_floating_point()]
        for i, st in enumerate(self.alg.optimizer.state.values()):
            out += [(f"optimiser state {k} of parameter {i}", v) for k, v in st.items() if torch.is_tensor(v)]
        return out

    def check_finite(self, iteration: int, losses: dict[str, float]) -> None:
        """Raise :class:`TrainingError` if anything of this iteration is non-finite: observations, values, actions,
        rewards, returns, losses or the learned state after the update; the message names what went non-finite
        first (by rollout step) and in how many worlds.

        Cheap: one sum per tensor (NaN and inf propagate into it) and one host sync per iteration; only when a sum
        is not finite are the tensors searched element by element (a sum that merely overflows is no error, except
        for raw observations, checked per step and world by the sum of the row)."""
        s = self.storage
        rollout = [("value", s.values), ("action", s.actions), ("reward", s.rewards)]
        rollout += [("return", s.returns), ("advantage", s.advantages)]
        learned = self._state_tensors()
        sums = torch.stack([t.sum().double() for _, t in rollout + learned])
        ok = torch.cat([self._obs_ok.all()[None], sums.isfinite()])
        bad_losses = [k for k, v in losses.items() if not math.isfinite(v)]
        if bool(ok.all()) and not bad_losses:
            return
        found = []  # (first step, causal order, name, worlds): what went non-finite first, and where
        for order, (name, t) in enumerate([("observation", None), *rollout]):
            bad = ~self._obs_ok if t is None else ~t.isfinite().reshape(t.shape[0], t.shape[1], -1).all(-1)
            if bool(bad.any()):
                step = int(bad.any(1).nonzero()[0]) if order < 4 else len(bad)  # returns run backwards: last
                found.append((step, order, name, int(bad.any(0).sum())))
        if found:
            _, _, name, worlds = min(found)
            raise self._error(f"{name} is non-finite in {worlds} of {self.cfg.num_envs} worlds", iteration)
        if bad_losses:
            raise self._error(f"{bad_losses[0]} is non-finite", iteration)
        for name, t in learned:
            if not bool(t.isfinite().all()):
                raise self._error(f"{name} is non-finite after the update", iteration)

    def collect(self) -> dict[str, float]:
        """One rollout of ``horizon`` steps into the storage, then GAE; returns the iteration's episode stats.

        The policy runs on the environment's ``math_threads`` torch threads (1), as its math does: the physics
        threads hold the cores between the steps, and more OpenMP threads only contend with them."""
        with torch_threads(self.env.cfg.math_threads):
            return self._collect()

    def update(self) -> dict[str, float]:
        """The PPO update of the collected rollout (returns its losses), on as many torch threads as the physics
        has (``--nthread``; they are idle meanwhile). The results do not depend on the thread count."""
        with torch_threads(getattr(self.env.backend, "nthread", None)):
            return self.alg.update(self.storage, self.gen)

    def _collect(self) -> dict[str, float]:
        pi = self.policy
        for t in range(self.cfg.horizon):
            self._obs_ok[t] = self.obs.sum(-1).isfinite()  # a NaN or inf propagates; no host sync here
            pi.normalizer.update(self.obs)
            obs_n = pi.normalizer(self.obs)
            self.noise = self._next_noise()
            actions, log_probs, mu, values = pi.act(obs_n, noise=self.noise)
            self.obs, reward, terminated, _, info = self.env.step(actions)
            self._restart_noise(terminated | info["time_outs"])
            self.storage.add(obs_n, actions, log_probs, mu, values, reward, terminated, info["time_outs"])
            self.stats.record(reward, terminated, info)
        self._obs_ok[-1] = self.obs.sum(-1).isfinite()
        with torch.no_grad():
            last_values = pi.value(pi.normalizer(self.obs))
        self.alg.compute_returns(self.storage, last_values)
        return self.stats.flush()

    def _next_noise(self) -> torch.Tensor:
        """This step's standard-normal exploration noise: fresh draws, or the AR(1) continuation."""
        xi = torch.randn(self.noise.shape, generator=self.gen, device=self.noise.device)
        rho = self.cfg.noise_correlation
        return xi if rho == 0.0 else rho * self.noise + math.sqrt(1.0 - rho * rho) * xi

    def _restart_noise(self, done: torch.Tensor) -> None:
        """Worlds whose episode ended start the next one with an independent draw (correlated noise only)."""
        if self.cfg.noise_correlation > 0.0:
            fresh = torch.randn(self.noise.shape, generator=self.gen, device=self.noise.device)
            self.noise = torch.where(done[:, None], fresh, self.noise)

    # -- feedforward warm start ----------------------------------------------------------------------------
    def optimise_feedforward(self, progress: bool = False) -> None:
        """Search the open-loop PD-target offsets of the run's scene (``env.feedforward``) before the first
        iteration, with ``feedforward.samples`` worlds of the same scene (residual actions only); saved in every
        checkpoint, so evaluation and view apply the same offsets and a resume does not search again."""
        from wristmimic.env.feedforward import optimise_feedforward

        c = self.env.cfg
        if not c.feedforward.enabled or c.action_mode != "residual" or self.iteration > 0:
            return
        nthread = getattr(self.env.backend, "nthread", None)
        opt = WristMimicEnv(self.env.scene, self.env.ref, c.feedforward.samples, c, 0, "cpu", nthread)
        try:
            self.env.feedforward = optimise_feedforward(opt, progress).to(self.env.device)
        finally:
            opt.close()

    # -- periodic evaluation -------------------------------------------------------------------------------
    def _eval_due(self) -> bool:
        """Every ``eval_every`` iterations (not at the end of a call: a run split by a resume logs the same rows)."""
        every = self.cfg.eval_every
        return every > 0 and self.iteration % every == 0

    def periodic_eval(self) -> dict[str, float]:
        """``eval_trials`` frame-0 trials of the quick protocol with the current policy, exactly as
        ``wristmimic evaluate`` runs them (seeded action noise, the run's terminations, no object controller):
        ``eval/success_rate``, ``eval/frames_completed`` (mean), ``eval/obj_pos_err_cm``, ``eval/contact_ratio``,
        ``eval/strict_success_rate`` (see :mod:`wristmimic.evaluate.metrics`)."""
        col = self._eval_trials(0, self.cfg.eval_trials)
        return {
            "eval/success_rate": float(col["success"].mean()),
            "eval/strict_success_rate": float(col["strict_success"].mean()),
            "eval/frames_completed": float(col["frames_completed"].mean()),
            "eval/obj_pos_err_cm": float(np.nanmean(col["obj_pos_err_cm"])),
            "eval/contact_ratio": float(np.nanmean(col["contact_ratio"])),
        }

    def _eval_trials(self, start: int, stop: int) -> dict[str, np.ndarray]:
        """Trials ``start .. stop - 1`` of the periodic evaluation's protocol with :attr:`candidate`: per trial
        ``success``, ``strict_success``, ``frames_completed``, ``obj_pos_err_cm`` and ``contact_ratio``."""
        from wristmimic.evaluate.policy import RunPolicy
        from wristmimic.evaluate.protocol import load_protocol
        from wristmimic.evaluate.trials import TrialSettings, make_env, run_trials
        from wristmimic.rl.policy import Policy

        if self._eval_env is None:
            config = json.loads(self.config_text)
            meta = {k: config.get(k) for k in ("scene", "env", "scene_config", "ref_frames")}
            meta["feedforward"] = self.env.feedforward
            meta["dataset"] = str(self.dataset_file or config["dataset"]["path"])
            n = min(self.cfg.eval_trials, self.env.num_worlds)
            physics = config.get("physics") or {}
            self._eval_env = make_env(
                meta, n, nthread=getattr(self.env.backend, "nthread", None), backend=physics.get("backend", "cpu")
            )
        records: list[dict[str, np.ndarray]] = []
        settings = TrialSettings.from_protocol(load_protocol("quick"))
        m = self.metadata
        seed = int(m.get("seed", 0))
        current = Policy(
            self.candidate,
            m["scene"],
            m["variant"],
            m.get("dataset_sha256", ""),
            seed,
            self.iteration,
            self.frames,
            {},
            deploy_std=self.cfg.deploy_std,
        )
        if self.cfg.eval_base_seed is not None:
            settings = dataclasses.replace(settings, base_seed=self.cfg.eval_base_seed)
        run_trials(self._eval_env, RunPolicy(current, {}), settings, start, stop, records.append)
        return {
            k: np.concatenate([r[k] for r in records])
            for k in ("success", "strict_success", "frames_completed", "obj_pos_err_cm", "contact_ratio")
        }

    # -- checkpoints ---------------------------------------------------------------------------------------
    def state_dict(self) -> dict[str, Any]:
        """Everything a bit-for-bit resume needs; only tensors, plain containers and JSON text.

        ``deploy_policy`` (absent: deploy ``policy``) and ``deploy`` say which weights are deployed."""
        weights, deploy = self.deployment()
        extra: dict[str, Any] = {"deploy": deploy}
        if weights is not None:
            extra["deploy_policy"] = weights
        if self.ema_net is not None:
            extra["ema_policy"] = self.ema_net.state_dict()
        return extra | {
            "iteration": self.iteration,
            "frames": self.frames,
            "seconds": self.seconds,
            "policy": self.policy.state_dict(),
            "optimizer": self.alg.optimizer.state_dict(),
            "rng": rng_state(self.gen),
            "env": self.env.state_dict(),
            "obs": self.obs.clone(),
            "episodes": self.stats.state_dict(),
            "curriculum": self.curriculum.state_dict(),
            "noise": self.noise.clone(),
            "feedforward": self.env.feedforward.clone(),
            "storage_step": self.storage.step,
            "config": self.config_text,
            "metadata": dict(
                self.metadata,
                iteration=self.iteration,
                frames=self.frames,
                object_gain=self.curriculum.gain,
                object_gain_zero_frames=self.curriculum.zero_frames,
            ),
        }

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Restore :meth:`state_dict` (from ``run_dir``'s checkpoint); :class:`InputError` naming the file and the
        entry when the saved state does not fit the network, optimiser or environment built from its config."""
        path = self.run_dir / CHECKPOINT_NAME
        self._check_fits(path, state)
        with _restoring(path, "policy", "the weights of the network in the checkpoint's config"):
            self.policy.load_state_dict(state["policy"])
        if self.ema_net is not None:  # a checkpoint without one (written before the option): start from the latest
            with _restoring(path, "ema_policy", "the weights of the network in the checkpoint's config"):
                self.ema_net.load_state_dict(state.get("ema_policy", state["policy"]))
        deploy = state.get("deploy") or {}
        if self.cfg.deploy_best and deploy.get("weights") == "best":
            self.best = {k: deploy[k] for k in ("iteration", "frames", "eval_success_rate")}
            self.best["eval_strict_success_rate"] = deploy.get("eval_strict_success_rate", 0.0)  # older: none kept
            self.best["eval_trials"] = deploy.get("eval_trials", self.cfg.eval_trials)  # older: eval_trials alone
            self.best["policy"] = {k: v.clone() for k, v in state["deploy_policy"].items()}
        with _restoring(path, "optimizer", "the Adam state of the network in the checkpoint's config"):
            self.alg.optimizer.load_state_dict(state["optimizer"])
        with _restoring(path, "rng", "the random generator states written by `wristmimic train`"):
            set_rng_state(state["rng"], self.gen)
        with _restoring(path, "env", f"the state of {self.cfg.num_envs} worlds of the run's scene"):
            self.env.load_state_dict(state["env"])
        self.iteration, self.frames, self.seconds = int(state["iteration"]), int(state["frames"]), state["seconds"]
        self.obs = state["obs"].to(self.env.device)
        self.stats.load_state_dict(state["episodes"])
        if "noise" in state:
            self.noise = state["noise"].to(self.env.device)
        if "feedforward" in state:
            self.env.feedforward = state["feedforward"].to(self.env.device)
        if "curriculum" in state:  # runs from before the curriculum: none
            self.curriculum.load_state_dict(state["curriculum"])
        else:
            self.curriculum.gain = 0.0
        self.env.object_gain = self.curriculum.gain
        if self._weight_ramp:
            self.env.object_weight_gain = self.curriculum.weight_gain(self.frames)
        self.env.root_gain = root_assist_gain(self.env.cfg.root_assist, self.frames)
        self.env.adhesion_gain = hand_adhesion_gain(self.env.cfg.hand_adhesion, self.frames)
        self.storage.step = int(state["storage_step"])
        self.metrics = MetricsCsv(self.run_dir / "metrics.csv", keep_until=self.iteration)
        self.saved_iteration = self.iteration

    def _network_text(self, whose: str) -> str:
        c = self.cfg
        return (
            f"the network of {whose} ({self.env.observation_size} observations, actor "
            f"{list(c.actor_hidden)}, critic {list(c.critic_hidden)}, {self.env.action_size} actions)"
        )

    def _check_weights(self, path: Path, entry: str, weights: dict[str, torch.Tensor], net: str) -> None:
        """One-line :class:`InputError` for saved policy weights whose names or shapes are not this network's."""
        model = {k: tuple(v.shape) for k, v in self.policy.state_dict().items()}
        saved = upgrade_state_dict(dict(weights), self.env.action_size)
        for key, shape in model.items():
            if key not in saved:
                raise InputError(path, f"{entry}.{key}", "missing", net)
            if tuple(saved[key].shape) != shape:
                raise InputError(
                    path, f"{entry}.{key}", f"shape {list(saved[key].shape)}", f"shape {list(shape)} of {net}"
                )
        extra = sorted(set(saved) - set(model))
        if extra:
            raise InputError(path, f"{entry}.{extra[0]}", "not a weight of this network", net)

    def warm_start(
        self, path: Path, entry: str, weights: dict[str, torch.Tensor], reset_normalizer: bool = True
    ) -> None:
        """Start from another run's policy weights (``entry`` of the checkpoint at ``path``): its actor, critic
        and sigma, with this run's held dimensions and a fresh optimiser. With ``reset_normalizer`` the observation
        statistics are re-estimated from this run's observations (their count is reset), since the other run's
        scene may place objects where this one does not (a body-only copy parks them 20 m away); else they are
        kept, count and all, and updated on as in the source run."""
        self._check_weights(path, entry, weights, self._network_text("this run's config"))
        self.policy.load_state_dict({**weights, "active": self.policy.active.clone()})  # old names: load's hook
        if reset_normalizer:
            self.policy.normalizer.count.zero_()
        if self.ema_net is not None:
            self.ema_net.load_state_dict(self.policy.state_dict())

    def _check_fits(self, path: Path, state: dict[str, Any]) -> None:
        """One-line :class:`InputError` for saved weights, optimiser moments or tensors whose names or shapes are
        not those of the network and environment this run builds (e.g. weights of another network size)."""
        c = self.cfg
        net = self._network_text("the checkpoint's config")
        for entry in ("policy", "deploy_policy", "ema_policy"):
            if entry in state:
                self._check_weights(path, entry, state[entry], net)
        names = {id(p): k for k, p in self.policy.named_parameters()}
        params = [p for g in self.alg.optimizer.param_groups for p in g["params"]]
        opt = state["optimizer"]
        ids = [i for g in opt.get("param_groups", []) for i in g.get("params", [])]
        if len(ids) != len(params):
            raise InputError(path, "optimizer.param_groups", f"{len(ids)} parameters", f"{len(params)} of {net}")
        for i, p in zip(ids, params, strict=True):
            for k, v in opt.get("state", {}).get(i, {}).items():
                if torch.is_tensor(v) and v.dim() > 0 and tuple(v.shape) != tuple(p.shape):
                    raise InputError(
                        path,
                        f"optimizer.state.{i}.{k}",
                        f"shape {list(v.shape)}",
                        f"shape {list(p.shape)} of {names.get(id(p), 'its parameter')}",
                    )
        shapes = {"obs": (c.num_envs, self.env.observation_size), "noise": (c.num_envs, self.env.action_size)}
        shapes["feedforward"] = tuple(self.env.feedforward.shape)
        for key, shape in shapes.items():
            t = state.get(key)
            if t is not None and (not torch.is_tensor(t) or tuple(t.shape) != shape):
                got = f"shape {list(t.shape)}" if torch.is_tensor(t) else f"a {type(t).__name__}"
                raise InputError(path, key, got, f"a tensor of shape {list(shape)} for this run")

    def save(self, wait: bool = True) -> Path:
        """Write ``checkpoint.pt`` atomically; refuses non-finite learned state or observations
        (:class:`TrainingError`, the previous checkpoint kept), as well as a failed write.

        ``wait=False`` (inside :meth:`learn`): snapshot the state into CPU memory and hand it to the background
        writer; its outcome is taken by :meth:`_collect_write` (``saved_iteration`` is set there)."""
        path = self.run_dir / CHECKPOINT_NAME
        self._collect_write()  # at most one write in flight
        tensors = [*self._state_tensors(), ("observation", self.obs)]
        if not bool(torch.stack([t.sum().double() for _, t in tensors]).isfinite().all()):
            for name, t in tensors:
                if not bool(t.isfinite().all()):
                    raise self._error(f"{name} is non-finite: checkpoint not written")
        self._last_save = _clock()
        if self._writer is not None:
            self._writer.submit(snapshot(self.state_dict()), self.iteration)
            if wait:
                self._collect_write()
            return path
        try:
            save_checkpoint(path, self.state_dict())
        except InputError as exc:
            raise self._error(f"{CHECKPOINT_NAME} {exc.problem}") from None
        self.saved_iteration = self.iteration
        return path


@contextlib.contextmanager
def _restoring(path: Path, key: str, expected: str) -> Iterator[None]:
    """Turn an error of a ``load_state_dict`` (torch's many-line report, a shape or key error) into one line."""
    try:
        yield
    except (RuntimeError, ValueError, KeyError, TypeError, IndexError, AttributeError) as exc:
        lines = [ln.strip() for ln in str(exc).splitlines() if ln.strip()]
        detail = lines[-1] if lines else type(exc).__name__
        raise InputError(path, key, f"does not fit this run ({detail[:200]})", expected) from None


EVAL_COLUMNS = (
    "eval/success_rate",
    "eval/frames_completed",
    "eval/obj_pos_err_cm",
    "eval/contact_ratio",
    "eval/strict_success_rate",
)
"""Columns of the periodic evaluation in ``metrics.csv`` (NaN in iterations without one)."""

CONFIRM_COLUMNS = ("eval/confirm_success_rate", "eval/confirm_strict_success_rate")
"""Columns of ``ppo.eval_confirm_trials`` (only in its runs; NaN where no candidate was confirmed): the candidate's
rates over its periodic and confirming trials together."""


@contextlib.contextmanager
def stop_on_ctrl_c(runner: Runner) -> Iterator[None]:
    """First Ctrl-C: finish the current iteration, save and stop; a second one aborts at once."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def handler(signum: int, frame: object) -> None:
        if runner.stop_requested:
            raise KeyboardInterrupt
        runner.stop_requested = True
        print("\nCtrl-C: saving a checkpoint after this iteration (press again to abort without saving)")

    previous = signal.signal(signal.SIGINT, handler)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)
