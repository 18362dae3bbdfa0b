"""One rollout of a policy in a one-world environment, kept as a :class:`SimTrack` for a recording.

The environment resets a world automatically inside ``step`` when its episode ends, so the state that ended
the episode is gone when ``step`` returns. :class:`KeepStateBeforeReset` wraps the physics backend and keeps
the sensors of the last state before any reset; ``env.sim_state()`` reads them while :meth:`showing` it.
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import torch

from wristmimic.errors import InputError
from wristmimic.threads import torch_threads
from wristmimic.view.tracks import SimTrack

if TYPE_CHECKING:
    from wristmimic.env.observations import SimState
    from wristmimic.env.vec_env import WristMimicEnv
    from wristmimic.evaluate.policy import EvalPolicy
    from wristmimic.sim.backend import PhysicsBackend

Actor = Callable[[torch.Tensor], torch.Tensor]
"""Observations (N, obs) -> actions (N, act), e.g. ``lambda obs: policy.act(obs, deterministic=True)``;
called once per step, in order."""


class KeepStateBeforeReset:
    """A physics backend wrapper that keeps the sensors of every world just before :meth:`reset`."""

    def __init__(self, inner: PhysicsBackend):
        self.inner = inner
        self.num_worlds = inner.num_worlds
        self.model = inner.model
        self.device = inner.device
        self.before_reset: torch.Tensor | None = None
        self._shown: torch.Tensor | None = None

    @property
    def physics_seconds(self) -> float:
        return self.inner.physics_seconds

    @property
    def qpos(self) -> torch.Tensor:
        return self.inner.qpos

    @property
    def qvel(self) -> torch.Tensor:
        return self.inner.qvel

    @property
    def sensordata(self) -> torch.Tensor:
        return self.inner.sensordata if self._shown is None else self._shown

    def state_dict(self) -> dict[str, torch.Tensor]:
        return self.inner.state_dict()

    def load_state_dict(self, state: dict[str, torch.Tensor]) -> None:
        self.inner.load_state_dict(state)

    def reset(self, mask: torch.Tensor, qpos: torch.Tensor, qvel: torch.Tensor) -> None:
        self.before_reset = self.inner.sensordata.clone()
        self.inner.reset(mask, qpos, qvel)

    def step(self, ctrl: torch.Tensor, substeps: int) -> None:
        self.inner.step(ctrl, substeps)

    def close(self) -> None:
        self.inner.close()

    @contextlib.contextmanager
    def showing(self, sensordata: torch.Tensor) -> Iterator[None]:
        """Make ``sensordata`` the backend's sensors for the duration (positions and contacts only: joint
        velocities still come from the current state)."""
        self._shown = sensordata
        try:
            yield
        finally:
            self._shown = None


def run_rollout(env: WristMimicEnv, actor: Actor, start_frame: int = 0, max_steps: int | None = None) -> SimTrack:
    """Reset world 0 to reference frame ``start_frame`` and step ``actor`` until the episode ends (or after
    ``max_steps`` steps). Only world 0 is recorded; other worlds, if any, step along with the same actor."""
    T = env.ref.num_frames
    if not 0 <= start_frame < T - 1:
        raise InputError(None, "start_frame", f"{start_frame}", f"a frame in [0, {T - 2}]")
    wrapper = KeepStateBeforeReset(env.backend)
    env.backend = wrapper  # type: ignore[assignment]
    try:
        with torch_threads(1):  # one world: small batches, where extra threads only wait on each other
            obs, _ = env.reset(start_frames=torch.full((env.num_worlds,), int(start_frame), dtype=torch.long))
            states, frames, rewards = [env.sim_state()], [int(start_frame)], [float("nan")]
            end = "stopped"
            limit = max_steps if max_steps is not None else T + 1
            for _ in range(limit):
                with torch.no_grad():
                    action = actor(obs)
                obs, reward, terminated, truncated, info = env.step(action)
                frames.append(int(info["frame"][0]))
                rewards.append(float(reward[0]))
                if bool(terminated[0] | truncated[0]):
                    assert wrapper.before_reset is not None
                    with wrapper.showing(wrapper.before_reset):
                        states.append(env.sim_state())
                    reason = env.reason_name(int(info["termination_reason"][0]))
                    end = f"terminated: {reason}" if bool(terminated[0]) else "truncated"
                    break
                states.append(env.sim_state())
    finally:
        env.backend = wrapper.inner  # type: ignore[assignment]
    return _stack(states, frames, rewards, end)


def _stack(states: list[SimState], frames: list[int], rewards: list[float], end: str) -> SimTrack:
    def take(name: str) -> np.ndarray:
        return np.stack([getattr(s, name)[0].cpu().numpy() for s in states])

    return SimTrack(
        frames=np.asarray(frames, dtype=np.int64),
        body_pos=take("body_pos"),
        body_quat=take("body_quat"),
        obj_pos=take("obj_pos"),
        obj_quat=take("obj_quat"),
        contact_obj=take("contact_obj").astype(bool),
        reward=np.asarray(rewards, dtype=np.float64),
        end_reason=end,
    )


def evaluation_actor(policy: EvalPolicy, trial_seed: int | None = None) -> Actor:
    """The policy's actions as ``wristmimic.evaluate`` computes them for one trial: the mean (policy batches
    padded to whole row blocks, so the bits do not depend on the batch), plus, with ``trial_seed``,
    ``sigma * normal(trial_seed, step, index)`` on the action-noise stream. ``trial_seed`` is the ``seed``
    column of an evaluation's per-trial table (noise mode ``actions``), so the rollout replays that trial."""
    from wristmimic.evaluate.noise import normal
    from wristmimic.evaluate.policy import act_rows
    from wristmimic.evaluate.trials import NOISE_STREAM_ACTIONS

    step = 0

    def act(obs: torch.Tensor) -> torch.Tensor:
        nonlocal step
        actions = act_rows(policy, obs)
        if trial_seed is not None:
            seeds = torch.full((obs.shape[0],), int(trial_seed), dtype=torch.long)
            noise = normal(seeds, torch.full_like(seeds, step), actions.shape[1], NOISE_STREAM_ACTIONS)
            actions = actions + policy.sigma.to(torch.float32) * noise
        step += 1
        return actions

    return act


def run_dataset(meta: dict[str, Any], dataset: str | Path | None = None) -> Path:
    """The canonical file a policy was trained on (``meta``: ``EvalPolicy.metadata``; ``dataset`` overrides
    the stored path of a moved file); :class:`InputError` if it is missing or not the same file (sha256)."""
    from wristmimic.safe_io import sha256_file

    path = Path(dataset if dataset is not None else meta["dataset"])
    if not path.is_file():
        raise InputError(path, None, "dataset of the run not found", "the file it was trained on (or --dataset)")
    if sha256_file(path) != meta["dataset_sha256"]:
        raise InputError(path, None, "is not the file the policy was trained on (sha256 differs)", "the same file")
    return path


def env_for_policy(policy: EvalPolicy, dataset: str | Path | None = None, nthread: int = 1) -> WristMimicEnv:
    """A one-world environment of the policy's scene as evaluation builds it: the run's variant, physics and
    reference frames, every reset at frame 0 and no truncation before the end of the reference
    (``wristmimic.evaluate.trials.make_env``); ``dataset`` as in :func:`run_dataset`."""
    from wristmimic.evaluate.trials import make_env

    return make_env(policy.metadata, 1, "run", nthread, run_dataset(policy.metadata, dataset))
