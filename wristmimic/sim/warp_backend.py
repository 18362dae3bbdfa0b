"""MuJoCo Warp backend: thousands of worlds of one scene stepped on a GPU (or on Warp's CPU device).

The scene's ``MjModel`` is compiled for ``mujoco_warp`` once; the state of every world lives in Warp arrays
and is exposed to the environment as torch tensors that share the memory (``wp.to_torch``), so observation,
reward and termination math runs on the same device with no copies to the host. On CUDA the substep loop is
captured once as a CUDA graph on Warp's own stream (capture is not allowed on the legacy default stream torch
uses), and the two streams wait on each other through events, so torch and Warp work is ordered without
synchronising the host.

Semantics match :class:`wristmimic.sim.backend.CpuRolloutBackend`: sensors after :meth:`step` and :meth:`reset`
are those of the state just reached (a forward pass after the substeps, since ``step`` evaluates sensors before
integrating); each control step starts from a cleared solver warm start. Warp computes in float32
(the CPU backend in float64); ``tests/test_warp_backend.py`` states the tolerances that hold.

Needs the ``warp`` extra: ``pip install 'wristmimic[warp]'`` (``mujoco-warp``, which brings ``warp-lang``).
"""

from __future__ import annotations

import copy
import time
from typing import Any

import mujoco
import numpy as np
import torch

from wristmimic.errors import InputError

STATE_FIELDS = ("qpos", "qvel", "act", "time", "ctrl", "sensordata")
"""Warp Data fields saved by :meth:`WarpBackend.state_dict` (everything else is recomputed by the next step)."""


def import_warp() -> tuple[Any, Any]:
    """``(warp, mujoco_warp)``, or an :class:`InputError` that says how to install them."""
    try:
        import warp as wp

        wp.config.log_level = wp.LOG_WARNING  # before Warp initialises: no banner, no per-module compile lines
        import mujoco_warp as mjw
    except ImportError as exc:
        raise InputError(
            None, "--backend warp", f"needs MuJoCo Warp ({exc.name} is not installed)", "pip install 'wristmimic[warp]'"
        ) from None
    wp.init()
    return wp, mjw


def default_device() -> str:
    """``cuda`` where torch and Warp see a GPU, else Warp's ``cpu`` device."""
    return "cuda" if torch.cuda.is_available() else "cpu"


def contact_capacity(model: mujoco.MjModel) -> tuple[int, int]:
    """Per-world (nconmax, njmax) for a WristMimic scene: a contact for every geom that can move (a humanoid
    lying on the floor, a grasp with every finger segment), at least 128, and 4 constraint rows per contact
    (pyramidal friction cone, condim 3) plus a row per limited joint. Measured with random flailing actions
    (8 worlds x 60 control steps): at most 12 / 28 contacts and 156 / 127 rows per world on
    sub2_largetable_000 / s110_move_kettle, against 128 / 144 contacts and 665 / 756 rows here. Memory grows
    with njmax x nv per world; MuJoCo Warp prints a warning and :meth:`WarpBackend.overflowed` turns true if a
    world runs out."""
    movable = int(np.sum(model.body_rootid[model.geom_bodyid] != 0))  # geoms on bodies that can move
    nconmax = max(128, movable)
    return nconmax, 4 * nconmax + int(np.sum(model.jnt_limited))


def newton_for_pgs(model: mujoco.MjModel) -> mujoco.MjModel:
    """``model``, or a copy stepped by Newton with 100 iterations where it uses PGS (``scene_config.solver``), which
    MuJoCo Warp does not have. ``wristmimic train --backend warp`` records Newton in the run's ``config.json``; a
    CPU PGS run's policy evaluated on Warp meets Newton instead of the PGS it trained with."""
    if model.opt.solver != mujoco.mjtSolver.mjSOL_PGS:
        return model
    m = copy.deepcopy(model)
    m.opt.solver, m.opt.iterations = mujoco.mjtSolver.mjSOL_NEWTON, 100
    return m


class WarpBackend:
    """``num_worlds`` worlds of ``model`` in MuJoCo Warp on ``device`` ("cuda", "cuda:1", "cpu")."""

    def __init__(
        self,
        model: mujoco.MjModel,
        num_worlds: int,
        device: str | None = None,
        nconmax: int | None = None,
        njmax: int | None = None,
        graph: bool | None = None,
    ):
        wp, mjw = import_warp()
        self._wp, self._mjw = wp, mjw
        model = newton_for_pgs(model)
        self.model = model
        self.num_worlds = int(num_worlds)
        self._wpdev = wp.get_device(device or default_device())
        self.device = torch.device("cpu") if self._wpdev.is_cpu else torch.device(f"cuda:{self._wpdev.ordinal}")
        auto_con, auto_j = contact_capacity(model)
        self.nconmax, self.njmax = int(nconmax or auto_con), int(njmax or auto_j)
        self.physics_seconds = 0.0
        with wp.ScopedDevice(self._wpdev):
            self.m = mjw.put_model(model)
            d0 = mujoco.MjData(model)
            mujoco.mj_forward(model, d0)
            self.d = mjw.put_data(model, d0, nworld=self.num_worlds, nconmax=self.nconmax, njmax=self.njmax)
        self._t = {name: wp.to_torch(getattr(self.d, name)) for name in (*STATE_FIELDS, "qacc_warmstart")}
        self._t["overflow"] = wp.to_torch(self.d.overflow) if hasattr(self.d, "overflow") else None
        self._use_graph = (not self._wpdev.is_cpu) if graph is None else bool(graph and not self._wpdev.is_cpu)
        self._graphs: dict[tuple[str, int], Any] = {}

    # -- views ---------------------------------------------------------------------------------------------
    @property
    def qpos(self) -> torch.Tensor:
        return self._t["qpos"]

    @property
    def qvel(self) -> torch.Tensor:
        return self._t["qvel"]

    @property
    def sensordata(self) -> torch.Tensor:
        return self._t["sensordata"]

    # -- state ---------------------------------------------------------------------------------------------
    def state_dict(self) -> dict[str, torch.Tensor]:
        return {f"warp_{k}": self._t[k].detach().cpu().clone() for k in STATE_FIELDS}

    def load_state_dict(self, state: dict[str, torch.Tensor]) -> None:
        for k in STATE_FIELDS:
            src = state.get(f"warp_{k}")
            if src is None or tuple(src.shape) != tuple(self._t[k].shape):
                got = None if src is None else tuple(src.shape)
                raise ValueError(f"saved warp state {k} {got} does not fit {tuple(self._t[k].shape)}")
            self._t[k].copy_(src)
        self._t["qacc_warmstart"].zero_()

    def reset(self, mask: torch.Tensor, qpos: torch.Tensor, qvel: torch.Tensor) -> None:
        t = self._t
        m = mask.to(self.device, torch.bool)
        col = m[:, None]
        dt = t["qpos"].dtype
        t["qpos"].copy_(torch.where(col, qpos.to(self.device, dt), t["qpos"]))
        t["qvel"].copy_(torch.where(col, qvel.to(self.device, dt), t["qvel"]))
        t["time"].masked_fill_(m, 0.0)
        t["qacc_warmstart"].masked_fill_(col, 0.0)
        if t["act"].numel():
            t["act"].masked_fill_(col, 0.0)
        before = t["sensordata"].clone()
        ctrl = t["ctrl"].clone()
        t["ctrl"].masked_fill_(col, 0.0)  # as the CPU probe: sensors of the new state under zero controls
        self._launch("forward", 1)
        t["sensordata"].copy_(torch.where(col, t["sensordata"], before))
        t["ctrl"].copy_(ctrl)

    def step(self, ctrl: torch.Tensor, substeps: int) -> None:
        t = self._t
        t["ctrl"].copy_(ctrl.detach().to(self.device, t["ctrl"].dtype))
        t["qacc_warmstart"].zero_()
        self._launch("step", substeps)
        self._launch("forward", 1)  # sensors of the state just reached (a step evaluates them before integrating)

    def _launch(self, what: str, n: int) -> None:
        """Run ``mjw.step`` n times or ``mjw.forward`` once; on CUDA through a captured graph."""
        wp, mjw = self._wp, self._mjw
        fn = mjw.step if what == "step" else mjw.forward
        t0 = time.perf_counter()
        with wp.ScopedDevice(self._wpdev):
            if self._wpdev.is_cpu:
                for _ in range(n):
                    fn(self.m, self.d)
            else:
                warp_stream = wp.get_stream(self._wpdev)
                torch_stream = wp.stream_from_torch(torch.cuda.current_stream(self.device))
                warp_stream.wait_stream(torch_stream)  # the inputs torch wrote (controls, reset states)
                self._run_graph(fn, what, n)
                torch_stream.wait_stream(warp_stream)  # torch reads the new state after the step
        self.physics_seconds += time.perf_counter() - t0

    def _run_graph(self, fn: Any, what: str, n: int) -> None:
        wp = self._wp
        if not self._use_graph:
            for _ in range(n):
                fn(self.m, self.d)
            return
        key = (what, n)
        if key not in self._graphs:
            with wp.ScopedCapture() as capture:
                for _ in range(n):
                    fn(self.m, self.d)
            self._graphs[key] = capture.graph
        wp.capture_launch(self._graphs[key])

    def overflowed(self) -> bool:
        """True if any world ran out of contact or constraint room since the last reset (synchronises)."""
        o = self._t.get("overflow")
        return bool(o is not None and bool((o != 0).any()))

    def synchronize(self) -> None:
        self._wp.synchronize_device(self._wpdev)

    def close(self) -> None:
        self._graphs.clear()
