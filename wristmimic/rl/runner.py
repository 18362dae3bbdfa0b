"""The on-policy training loop: collect a rollout, update, log, checkpoint (rsl_rl's ``OnPolicyRunner``)."""

from __future__ import annotations

import contextlib
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
from wristmimic.rl.checkpoint import CHECKPOINT_NAME, rng_state, save_checkpoint, set_rng_state
from wristmimic.rl.config import PPOConfig
from wristmimic.rl.curriculum import ObjectCurriculum
from wristmimic.rl.logger import EpisodeStats, MetricsCsv, train_progress
from wristmimic.rl.networks import ActorCritic
from wristmimic.rl.ppo import PPO
from wristmimic.rl.storage import RolloutStorage


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
        self.alg = PPO(self.policy, cfg)
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
        env.eval_info = False  # evaluation errors are computed by the periodic evaluation's own environment
        self._eval_env: WristMimicEnv | None = None
        self.stop_requested = False
        self.metrics: MetricsCsv | None = None

    def learn(self, max_frames: int, progress: bool = True, should_stop: Callable[[], bool] | None = None) -> str:
        """Train until ``max_frames`` environment frames, Ctrl-C or ``should_stop()`` (asked after each iteration,
        e.g. a Ray driver's stop request); returns ``"finished"`` / ``"interrupted"`` (a checkpoint is saved)."""
        self.metrics = self.metrics or MetricsCsv(self.run_dir / "metrics.csv")
        desc = f"{self.metadata['scene']} [{self.metadata['variant']}]"
        with stop_on_ctrl_c(self), train_progress(desc, self.frames, max_frames, progress) as bar:
            while self.frames < max_frames and not self.stop_requested:
                t0 = time.perf_counter()
                gain = self.env.object_gain
                if self.cfg.final_std > 0.0:  # the sigma schedule (a fixed sigma: a buffer, saved with the policy)
                    self.policy.log_std_param.fill_(self.cfg.log_std_at(self.frames))
                episode_row = self.collect()
                losses = self.alg.update(self.storage, self.gen)
                self.storage.clear()
                dt = time.perf_counter() - t0
                self.iteration += 1
                self.frames += self.cfg.batch_size
                terminations = sum(v for k, v in episode_row.items() if k.startswith("termination/"))
                self.env.object_gain = self.curriculum.update(terminations, self.cfg.batch_size, self.frames)
                evaluation = self.periodic_eval() if self._eval_due() else {}
                self.seconds += time.perf_counter() - t0
                row = {"iteration": self.iteration, "frames": self.frames, "seconds": self.seconds}
                row |= {"frames_per_s": self.cfg.batch_size / dt, **episode_row, **losses}
                row["curriculum/object_gain"] = gain
                row |= {k: evaluation.get(k, math.nan) for k in EVAL_COLUMNS}
                self.metrics.write(row)
                bar.update(self.frames, row)
                if self.iteration % self.cfg.checkpoint_every == 0:
                    self.save()
                if should_stop is not None and should_stop():
                    self.stop_requested = True
        self.save()
        return "interrupted" if self.stop_requested else "finished"

    def collect(self) -> dict[str, float]:
        """One rollout of ``horizon`` steps into the storage, then GAE; returns the iteration's episode stats."""
        pi = self.policy
        for _ in range(self.cfg.horizon):
            pi.normalizer.update(self.obs)
            obs_n = pi.normalizer(self.obs)
            self.noise = self._next_noise()
            actions, log_probs, mu, values = pi.act(obs_n, noise=self.noise)
            self.obs, reward, terminated, _, info = self.env.step(actions)
            self._restart_noise(terminated | info["time_outs"])
            self.storage.add(obs_n, actions, log_probs, mu, values, reward, terminated, info["time_outs"])
            self.stats.record(reward, terminated, info)
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
        ``eval/success_rate``, ``eval/frames_completed`` (mean), ``eval/obj_pos_err_cm``, ``eval/contact_ratio``."""
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
            self.policy, m["scene"], m["variant"], m.get("dataset_sha256", ""), seed, self.iteration, self.frames, {}
        )
        run_trials(self._eval_env, RunPolicy(current, {}), settings, 0, self.cfg.eval_trials, records.append)
        col = {
            k: np.concatenate([r[k] for r in records])
            for k in ("success", "frames_completed", "obj_pos_err_cm", "contact_ratio")
        }
        return {
            "eval/success_rate": float(col["success"].mean()),
            "eval/frames_completed": float(col["frames_completed"].mean()),
            "eval/obj_pos_err_cm": float(np.nanmean(col["obj_pos_err_cm"])),
            "eval/contact_ratio": float(np.nanmean(col["contact_ratio"])),
        }

    # -- checkpoints ---------------------------------------------------------------------------------------
    def state_dict(self) -> dict[str, Any]:
        """Everything a bit-for-bit resume needs; only tensors, plain containers and JSON text."""
        return {
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
        self.iteration, self.frames, self.seconds = int(state["iteration"]), int(state["frames"]), state["seconds"]
        self.policy.load_state_dict(state["policy"])
        self.alg.optimizer.load_state_dict(state["optimizer"])
        set_rng_state(state["rng"], self.gen)
        self.env.load_state_dict(state["env"])
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
        self.storage.step = int(state["storage_step"])
        self.metrics = MetricsCsv(self.run_dir / "metrics.csv", keep_until=self.iteration)

    def save(self) -> Path:
        path = self.run_dir / CHECKPOINT_NAME
        save_checkpoint(path, self.state_dict())
        return path


EVAL_COLUMNS = ("eval/success_rate", "eval/frames_completed", "eval/obj_pos_err_cm", "eval/contact_ratio")
"""Columns of the periodic evaluation in ``metrics.csv`` (NaN in iterations without one)."""


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
