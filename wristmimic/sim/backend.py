"""Physics backends: step N worlds of one scene; everything the environment reads comes from sensors.

The interface is small on purpose: :class:`CpuRolloutBackend` (MuJoCo on CPU threads, the default) and
:class:`wristmimic.sim.warp_backend.WarpBackend` (MuJoCo Warp, thousands of worlds on a GPU) implement it.
Arrays cross the interface as torch tensors on the backend's ``device``: on the GPU backend they are views of
the simulator's own memory, so observations, rewards and terminations are computed there without copies to
the host.
"""

from __future__ import annotations

import copy
import os
import time
from typing import Protocol

import mujoco
import numpy as np
import torch
from mujoco import rollout

_STATE = mujoco.mjtState.mjSTATE_FULLPHYSICS

BACKENDS = ("cpu", "warp")
"""Names accepted by :func:`make_backend` (and ``--backend`` on ``train`` / ``evaluate``)."""


class PhysicsBackend(Protocol):
    """N worlds of one model. Tensors are (N, ...) on :attr:`device`; treat them as read-only views."""

    num_worlds: int
    model: mujoco.MjModel
    device: torch.device
    physics_seconds: float
    """Wall time spent inside the simulator so far (benchmarks; on a GPU, launch time unless synchronised)."""

    @property
    def qpos(self) -> torch.Tensor: ...  # (N, nq)

    @property
    def qvel(self) -> torch.Tensor: ...  # (N, nv)

    @property
    def sensordata(self) -> torch.Tensor: ...  # (N, nsensordata)

    def state_dict(self) -> dict[str, torch.Tensor]:
        """The physics state of every world (CPU tensors), enough to continue bit-for-bit on this backend."""

    def load_state_dict(self, state: dict[str, torch.Tensor]) -> None:
        """Restore :meth:`state_dict`."""

    def reset(self, mask: torch.Tensor, qpos: torch.Tensor, qvel: torch.Tensor) -> None:
        """Worlds where ``mask`` (N,) is true get state (``qpos``, ``qvel``) with time, activations and
        solver warm start cleared, and their sensors evaluated there (no time passes); rows of other worlds
        in ``qpos`` / ``qvel`` are ignored and those worlds are left as they are."""

    def step(self, ctrl: torch.Tensor, substeps: int) -> None:
        """Advance every world ``substeps`` physics steps holding ``ctrl`` (N, nu)."""

    def close(self) -> None: ...


def make_backend(name: str, model: mujoco.MjModel, num_worlds: int, nthread: int | None = None, **kw: object):
    """A backend by name: ``cpu`` (default; ``exact_contacts=``) or ``warp`` (``device=`` "cuda" / "cpu",
    ``nconmax=``, ``njmax=``)."""
    if name == "cpu":
        return CpuRolloutBackend(model, num_worlds, nthread, **kw)  # type: ignore[arg-type]
    if name == "warp":
        from wristmimic.sim.warp_backend import WarpBackend

        return WarpBackend(model, num_worlds, **kw)  # type: ignore[arg-type]
    raise ValueError(f"unknown physics backend {name!r}: expected one of {', '.join(BACKENDS)}")


def contact_sensor_columns(model: mujoco.MjModel) -> np.ndarray:
    """sensordata columns of every contact sensor of ``model`` (sorted)."""
    cols = [
        np.arange(model.sensor_adr[i], model.sensor_adr[i] + model.sensor_dim[i])
        for i in range(model.nsensor)
        if model.sensor_type[i] == mujoco.mjtSensor.mjSENS_CONTACT
    ]
    return np.concatenate(cols) if cols else np.zeros(0, dtype=np.int64)


def probe_model(model: mujoco.MjModel, kinematic: bool) -> mujoco.MjModel:
    """A copy of ``model`` whose step does not move time (timestep 1e-12, Euler without implicit damping: the
    integrator's own factorisation is skipped; sensors are computed before integrating, so they do not depend on
    it): stepping it once evaluates the sensors of a state without changing it. ``kinematic``: no contacts,
    constraints or actuation either, so only frame (position, orientation, velocity) sensors are meaningful, at a
    quarter of the cost."""
    probe = copy.deepcopy(model)
    probe.opt.timestep = 1e-12
    probe.opt.integrator = mujoco.mjtIntegrator.mjINT_EULER
    d = mujoco.mjtDisableBit
    probe.opt.disableflags |= int(d.mjDSBL_EULERDAMP)
    if kinematic:
        probe.opt.disableflags |= int(d.mjDSBL_CONTACT | d.mjDSBL_CONSTRAINT | d.mjDSBL_ACTUATION)
    return probe


class CpuRolloutBackend:
    """MuJoCo on CPU threads through ``mujoco.rollout`` (the C++ thread pool releases the GIL).

    Sensor values after :meth:`step` and :meth:`reset` are those of the state just reached: ``mj_step``
    evaluates sensors before it integrates, so after the substeps one more batched zero-length step (the probe
    model: timestep 1e-12, the controls just held) evaluates them at the new state. With
    ``exact_contacts=False`` that pass is kinematics-only (frame sensors of the new state, a quarter of the
    cost) and contact sensors are those of the last substep (the contacts and forces that acted while stepping
    to it). Every control step starts from a cleared solver warm start (the warm start is not part of the saved
    state), which the Warp backend reproduces.
    """

    device = torch.device("cpu")

    def __init__(self, model: mujoco.MjModel, num_worlds: int, nthread: int | None = None, exact_contacts: bool = True):
        self.model = model
        self.num_worlds = int(num_worlds)
        self.nthread = max(1, nthread or os.cpu_count() or 1)
        self.nstate = mujoco.mj_stateSize(model, _STATE)
        self._datas = [mujoco.MjData(model) for _ in range(self.nthread)]
        self._pool = rollout.Rollout(nthread=self.nthread)
        # models whose step does not move time: evaluate sensors of given states in batch
        self._probe = probe_model(model, kinematic=False)
        self.exact_contacts = bool(exact_contacts)
        """Evaluate every sensor, contacts included, at the state just reached with a full zero-length step after
        the substeps (default). False: frame sensors from the kinematic probe (a quarter of its cost) and contact
        sensors of the last substep; measured on synth_default this stalled learning (no policy reached the
        contact phase by 410k frames where the default did at ~240k), so it is a benchmark option only."""
        self._after_step_probe = self._probe if self.exact_contacts else probe_model(model, kinematic=True)
        self._step_model = model
        """The model the substeps run: with exact contacts a copy with sensors disabled (the probe after the
        substeps evaluates every sensor; sensors never act on the dynamics, so the states are bit-identical)."""
        if self.exact_contacts:
            self._step_model = copy.deepcopy(model)
            self._step_model.opt.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_SENSOR)
        self.contact_columns = contact_sensor_columns(model)
        """sensordata columns of contact sensors: after :meth:`step` these come from the last substep."""
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
        self._out_sensor: np.ndarray | None = None
        self.physics_seconds = 0.0

    @property
    def qpos(self) -> torch.Tensor:
        return torch.from_numpy(self._state[:, self._qpos])

    @property
    def qvel(self) -> torch.Tensor:
        return torch.from_numpy(self._state[:, self._qvel])

    @property
    def sensordata(self) -> torch.Tensor:
        return torch.from_numpy(self._sensor)

    @property
    def state(self) -> np.ndarray:
        """(N, nstate) MuJoCo full-physics state of every world (numpy view; benchmarks compare raw rollouts)."""
        return self._state

    def state_dict(self) -> dict[str, torch.Tensor]:
        return {"physics": torch.from_numpy(self._state.copy()), "sensordata": torch.from_numpy(self._sensor.copy())}

    def load_state_dict(self, state: dict[str, torch.Tensor]) -> None:
        phys, sens = state["physics"].numpy(), state["sensordata"].numpy()
        if phys.shape != self._state.shape or sens.shape != self._sensor.shape:
            raise ValueError(f"saved physics state {phys.shape} does not fit {self._state.shape}")
        self._state[:] = phys
        self._sensor[:] = sens

    def reset(self, mask: torch.Tensor, qpos: torch.Tensor, qvel: torch.Tensor) -> None:
        ids = np.flatnonzero(mask.cpu().numpy())
        if ids.size == 0:
            return
        st = self._state[ids]
        st[:, 0] = 0.0
        st[:, self._qpos] = qpos.cpu().numpy()[ids]
        st[:, self._qvel] = qvel.cpu().numpy()[ids]
        st[:, 1 + self.model.nq + self.model.nv :] = 0.0
        t0 = time.perf_counter()
        self._sensor[ids] = self._sensors_at(self._probe, st, np.zeros((len(ids), 1, self.model.nu)))
        self.physics_seconds += time.perf_counter() - t0
        self._state[ids] = st

    def step(self, ctrl: torch.Tensor, substeps: int) -> None:
        n = self.num_worlds
        if self._out_state is None or self._out_state.shape[1] != substeps:
            self._out_state = np.empty((n, substeps, self.nstate))
            self._out_sensor = np.empty((n, substeps, self.model.nsensordata))  # read only without exact contacts
        c = ctrl.detach().cpu().numpy() if isinstance(ctrl, torch.Tensor) else np.asarray(ctrl)
        c = c.astype(np.float64, copy=False)
        c = np.ascontiguousarray(np.broadcast_to(c[:, None, :], (n, substeps, self.model.nu)))
        t0 = time.perf_counter()
        self._pool.rollout(
            self._step_model,
            self._datas,
            self._state,
            c,
            nstep=substeps,
            state=self._out_state,
            sensordata=self._out_sensor,
        )
        self._state[:] = self._out_state[:, -1]
        # frame sensors of the state just reached; contact sensors of the last substep (evaluated at its start)
        self._sensor[:] = self._sensors_at(self._after_step_probe, self._state, np.ascontiguousarray(c[:, :1]))
        if not self.exact_contacts:
            cols = self.contact_columns
            self._sensor[:, cols] = self._out_sensor[:, -1, cols]
        self.physics_seconds += time.perf_counter() - t0

    def _sensors_at(self, probe: mujoco.MjModel, states: np.ndarray, ctrl: np.ndarray) -> np.ndarray:
        """(n, nsensordata) sensors of full-physics ``states`` (n, nstate) under ``ctrl`` (n, 1, nu), contiguous:
        one zero-length step of a ``probe`` model (no time passes; the states are not changed)."""
        _, sens = self._pool.rollout(probe, self._datas, states, ctrl, nstep=1)
        return sens[:, 0]

    def close(self) -> None:
        self._pool.close()
