"""The on-policy training loop: collect a rollout, update, log, checkpoint (rsl_rl's ``OnPolicyRunner``)."""

from __future__ import annotations

import contextlib
import signal
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import torch

from wristmimic.env.vec_env import WristMimicEnv
from wristmimic.rl.checkpoint import CHECKPOINT_NAME, rng_state, save_checkpoint, set_rng_state
from wristmimic.rl.config import PPOConfig
from wristmimic.rl.logger import EpisodeStats, MetricsCsv, train_progress
from wristmimic.rl.networks import ActorCritic
from wristmimic.rl.ppo import PPO
from wristmimic.rl.storage import RolloutStorage


class Runner:
    """PPO on one :class:`WristMimicEnv`, writing ``metrics.csv`` and ``checkpoint.pt`` into ``run_dir``.

    ``config_text`` (the run's JSON config) and ``metadata`` (scene id, variant, dataset sha256, ...) are stored
    in every checkpoint so that a policy can be loaded from the checkpoint alone.
    """

    def __init__(self, env: WristMimicEnv, cfg: PPOConfig, seed: int, run_dir: Path, config_text: str, metadata: dict):
        self.env, self.cfg, self.run_dir = env, cfg, Path(run_dir)
        self.config_text, self.metadata = config_text, metadata
        torch.manual_seed(seed)  # network initialisation (on the CPU, then moved: the same weights on any device)
        dev = env.device
        self.gen = torch.Generator(device=dev).manual_seed(seed)  # action noise and minibatch order
        self.obs, _ = env.reset(seed=seed)
        self.policy = ActorCritic(
            env.observation_size, env.action_size, cfg.actor_hidden, cfg.critic_hidden, cfg.log_std, cfg.obs_clip
        ).to(dev)
        self.alg = PPO(self.policy, cfg)
        self.storage = RolloutStorage(cfg.horizon, cfg.num_envs, env.observation_size, env.action_size, dev)
        self.stats = EpisodeStats(env.ref.num_frames)
        self.iteration, self.frames, self.seconds = 0, 0, 0.0
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
                episode_row = self.collect()
                losses = self.alg.update(self.storage, self.gen)
                self.storage.clear()
                dt = time.perf_counter() - t0
                self.iteration += 1
                self.frames += self.cfg.batch_size
                self.seconds += dt
                row = {"iteration": self.iteration, "frames": self.frames, "seconds": self.seconds}
                row |= {"frames_per_s": self.cfg.batch_size / dt, **episode_row, **losses}
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
            actions, log_probs, mu, values = pi.act(obs_n, self.gen)
            self.obs, reward, terminated, _, info = self.env.step(actions)
            self.storage.add(obs_n, actions, log_probs, mu, values, reward, terminated, info["time_outs"])
            self.stats.record(reward, terminated, info)
        with torch.no_grad():
            last_values = pi.value(pi.normalizer(self.obs))
        self.alg.compute_returns(self.storage, last_values)
        return self.stats.flush()

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
            "storage_step": self.storage.step,
            "config": self.config_text,
            "metadata": dict(self.metadata, iteration=self.iteration, frames=self.frames),
        }

    def load_state_dict(self, state: dict[str, Any]) -> None:
        self.iteration, self.frames, self.seconds = int(state["iteration"]), int(state["frames"]), state["seconds"]
        self.policy.load_state_dict(state["policy"])
        self.alg.optimizer.load_state_dict(state["optimizer"])
        set_rng_state(state["rng"], self.gen)
        self.env.load_state_dict(state["env"])
        self.obs = state["obs"].to(self.env.device)
        self.stats.load_state_dict(state["episodes"])
        self.storage.step = int(state["storage_step"])
        self.metrics = MetricsCsv(self.run_dir / "metrics.csv", keep_until=self.iteration)

    def save(self) -> Path:
        path = self.run_dir / CHECKPOINT_NAME
        save_checkpoint(path, self.state_dict())
        return path


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
