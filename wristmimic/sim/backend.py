"""Physics backends: step N worlds of one scene; everything the environment reads comes from sensors.

The interface is small on purpose, so a GPU backend (MuJoCo Warp) can slot in beside the CPU one.
"""

from __future__ import annotations

import copy
import os
import time
from typing import Protocol

import mujoco
import numpy as np
from mujoco import rollout

_STATE = mujoco.mjtState.mjSTATE_FULLPHYSICS


class PhysicsBackend(Protocol):
    """N worlds of one model. Arrays are (N, ...) float64 numpy views owned by the backend."""

    num_worlds: int
    model: mujoco.MjModel

    @property
    def qpos(self) -> np.ndarray: ...  # (N, nq)

    @property
    def qvel(self) -> np.ndarray: ...  # (N, nv)

    @property
    def sensordata(self) -> np.ndarray: ...  # (N, nsensordata)

    @property
    def state(self) -> np.ndarray: ...  # (N, nstate) full physics state

    def load(self, state: np.ndarray, sensordata: np.ndarray) -> None:
        """Restore a saved (state, sensordata) pair of every world."""

    def set_state(self, ids: np.ndarray, qpos: np.ndarray, qvel: np.ndarray) -> None:
        """Put worlds ``ids`` in the given state and evaluate their sensors there (no time passes)."""

    def step(self, ctrl: np.ndarray, substeps: int) -> None:
        """Advance every world ``substeps`` physics steps holding ``ctrl`` (N, nu)."""

    def close(self) -> None: ...


class CpuRolloutBackend:
    """MuJoCo on CPU threads through ``mujoco.rollout`` (the C++ thread pool releases the GIL).

    Sensor values after :meth:`step` are those MuJoCo computed at the start of the last physics step
    (``mj_step`` evaluates sensors before integrating), i.e. one physics step (1/120 s) behind ``qpos``;
    after :meth:`set_state` they are exact.
    """

    def __init__(self, model: mujoco.MjModel, num_worlds: int, nthread: int | None = None):
        self.model = model
        self.num_worlds = int(num_worlds)
        self.nthread = max(1, nthread or os.cpu_count() or 1)
        self.nstate = mujoco.mj_stateSize(model, _STATE)
        self._datas = [mujoco.MjData(model) for _ in range(self.nthread)]
        self._pool = rollout.Rollout(nthread=self.nthread)
        # a model whose step does not move time: evaluates sensors of given states in batch
        self._probe = copy.deepcopy(model)
        self._probe.opt.timestep = 1e-12
        d = mujoco.MjData(model)
        mujoco.mj_forward(model, d)
        self._state = np.zeros((self.num_worlds, self.nstate))
        mujoco.mj_getState(model, d, self._state[0], _STATE)
        self._state[:] = self._state[0]
        self._sensor = np.zeros((self.num_worlds, model.nsensordata))
        self._sensor[:] = d.sensordata
        self._qpos = slice(1, 1 + model.nq)
        self._qvel = slice(1 + model.nq, 1 + model.nq + model.nv)
        self._out_state: np.ndarray | None = None
        self.physics_seconds = 0.0
        """Wall time spent inside MuJoCo (rollout calls) so far, for benchmarks."""
        self._out_sensor: np.ndarray | None = None

    @property
    def qpos(self) -> np.ndarray:
        return self._state[:, self._qpos]

    @property
    def qvel(self) -> np.ndarray:
        return self._state[:, self._qvel]

    @property
    def sensordata(self) -> np.ndarray:
        return self._sensor

    @property
    def state(self) -> np.ndarray:
        return self._state

    def load(self, state: np.ndarray, sensordata: np.ndarray) -> None:
        if state.shape != self._state.shape or sensordata.shape != self._sensor.shape:
            raise ValueError(f"saved physics state {state.shape} does not fit {self._state.shape}")
        self._state[:] = state
        self._sensor[:] = sensordata

    def set_state(self, ids: np.ndarray, qpos: np.ndarray, qvel: np.ndarray) -> None:
        ids = np.asarray(ids)
        if ids.size == 0:
            return
        st = self._state[ids]
        st[:, 0] = 0.0
        st[:, self._qpos] = qpos
        st[:, self._qvel] = qvel
        st[:, 1 + self.model.nq + self.model.nv :] = 0.0
        ctrl = np.zeros((len(ids), 1, self.model.nu))
        t0 = time.perf_counter()
        _, sens = self._pool.rollout(self._probe, self._datas, st, ctrl, nstep=1)
        self.physics_seconds += time.perf_counter() - t0
        self._state[ids] = st
        self._sensor[ids] = sens[:, 0]

    def step(self, ctrl: np.ndarray, substeps: int) -> None:
        n = self.num_worlds
        if self._out_state is None or self._out_state.shape[1] != substeps:
            self._out_state = np.empty((n, substeps, self.nstate))
            self._out_sensor = np.empty((n, substeps, self.model.nsensordata))
        ctrl = np.ascontiguousarray(np.broadcast_to(ctrl[:, None, :], (n, substeps, self.model.nu)))
        t0 = time.perf_counter()
        self._pool.rollout(
            self.model,
            self._datas,
            self._state,
            ctrl,
            nstep=substeps,
            state=self._out_state,
            sensordata=self._out_sensor,
        )
        self.physics_seconds += time.perf_counter() - t0
        self._state[:] = self._out_state[:, -1]
        self._sensor[:] = self._out_sensor[:, -1]

    def close(self) -> None:
        self._pool.close()
