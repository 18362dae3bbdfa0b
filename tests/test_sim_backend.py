"""Physics backends report the sensors of the state they just reached (no one-physics-step lag)."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest
import torch

from wristmimic.env.vec_env import WristMimicEnv

from synthetic import converted_intermimic


@pytest.fixture(scope="module")
def env(tmp_path_factory: pytest.TempPathFactory) -> WristMimicEnv:
    tmp = tmp_path_factory.mktemp("backend")
    return WristMimicEnv.from_file(converted_intermimic(tmp, 30), "sub1_box_000", 3, seed=0, nthread=2)


def _forward_sensors(model: mujoco.MjModel, qpos: np.ndarray, qvel: np.ndarray, ctrl: np.ndarray) -> np.ndarray:
    d = mujoco.MjData(model)
    d.qpos[:], d.qvel[:], d.ctrl[:] = qpos, qvel, ctrl
    mujoco.mj_forward(model, d)
    return d.sensordata.copy()


def _last_substep_sensors(model: mujoco.MjModel, state: np.ndarray, ctrl: np.ndarray, substeps: int) -> np.ndarray:
    """Sensors evaluated by the last of ``substeps`` plain ``mj_step`` calls (at that substep's start)."""
    d = mujoco.MjData(model)
    mujoco.mj_setState(model, d, state, mujoco.mjtState.mjSTATE_FULLPHYSICS)
    d.ctrl[:] = ctrl
    for _ in range(substeps):
        mujoco.mj_step(model, d)
    return d.sensordata.copy()


def test_the_kinematic_probe_gives_frame_sensors_of_the_new_state_and_contacts_of_the_last_substep(
    env: WristMimicEnv,
) -> None:
    """``exact_contacts=False``: frame sensors are those of the state just reached; contact sensors those of the
    last substep."""
    from wristmimic.sim.backend import CpuRolloutBackend

    m = env.scene.model
    be = CpuRolloutBackend(m, 3, 2, exact_contacts=False)
    qpos, qvel = env.reference_state(torch.tensor([0, 4, 9]))
    be.reset(torch.ones(3, dtype=torch.bool), qpos, qvel)
    gen = torch.Generator().manual_seed(0)
    kin = [s for n, s in env.scene.sensors.items() if n.split(":")[0] in ("pos", "quat", "linvel", "angvel")]
    cols = np.concatenate([np.arange(s.start, s.stop) for s in kin])
    contact = be.contact_columns
    assert len(contact) and not np.isin(contact, cols).any()
    assert len(cols) + len(contact) == m.nsensordata
    touched = 0
    for _ in range(3):
        before = be.state.copy()
        ctrl = env.action_to_ctrl(0.3 * torch.randn(3, env.action_size, generator=gen), torch.tensor([5, 9, 14]))
        full = torch.zeros(3, m.nu, dtype=torch.float64)
        full[:, env._act_cols] = ctrl.double()
        be.step(full, env.scene.config.substeps)
        for w in range(3):
            want = _forward_sensors(m, be.qpos[w].numpy(), be.qvel[w].numpy(), full[w].numpy())
            got = be.sensordata[w].numpy()
            np.testing.assert_allclose(got[cols], want[cols], atol=1e-9)  # poses and velocities at the new state
            last = _last_substep_sensors(m, before[w], full[w].numpy(), env.scene.config.substeps)
            scale = max(1.0, np.abs(last[contact]).max())
            np.testing.assert_allclose(got[contact], last[contact], atol=1e-6 * scale)  # contacts of the last substep
            touched += int(np.abs(last[contact]).sum() > 0)
    assert touched > 0, "no contact in the test: it would not check the contact columns"
    be.close()


def test_sensors_after_a_step_are_those_of_the_new_state(env: WristMimicEnv) -> None:
    """The default backend (the environment's) evaluates every sensor, contacts included, at the new state."""
    m = env.scene.model
    be = env.backend
    assert be.exact_contacts
    qpos, qvel = env.reference_state(torch.tensor([0, 4, 9]))
    be.reset(torch.ones(3, dtype=torch.bool), qpos, qvel)
    ctrl = env.action_to_ctrl(torch.zeros(3, env.action_size), torch.tensor([5, 9, 14]))
    full = torch.zeros(3, m.nu, dtype=torch.float64)
    full[:, env._act_cols] = ctrl.double()
    be.step(full, env.scene.config.substeps)
    assert np.abs(be.sensordata.numpy()[:, be.contact_columns]).sum() > 0  # contacts to compare
    for w in range(3):
        want = _forward_sensors(m, be.qpos[w].numpy(), be.qvel[w].numpy(), full[w].numpy())
        np.testing.assert_allclose(be.sensordata[w].numpy(), want, atol=1e-6 * max(1.0, np.abs(want).max()))


def test_substeps_run_without_sensors_and_reach_the_same_states_as_plain_mj_step(env: WristMimicEnv) -> None:
    """With exact contacts the substeps skip sensor evaluation (the probe after them computes every sensor):
    the states reached are bit-identical to plain ``mj_step`` on the scene's own model, sensors on."""
    m, be = env.scene.model, env.backend
    off = int(mujoco.mjtDisableBit.mjDSBL_SENSOR)
    assert be._step_model.opt.disableflags & off and not m.opt.disableflags & off
    qpos, qvel = env.reference_state(torch.tensor([2, 6, 11]))
    be.reset(torch.ones(3, dtype=torch.bool), qpos, qvel)
    start = be.state.copy()
    ctrl = torch.zeros(3, m.nu, dtype=torch.float64)
    ctrl[:, env._act_cols] = env.action_to_ctrl(
        torch.full((3, env.action_size), 0.3), torch.tensor([3, 7, 12])
    ).double()
    sub = env.scene.config.substeps
    be.step(ctrl, sub)
    d = mujoco.MjData(m)
    for w in range(3):
        mujoco.mj_setState(m, d, start[w], mujoco.mjtState.mjSTATE_FULLPHYSICS)
        mujoco.mj_setState(m, d, np.zeros(m.nv), mujoco.mjtState.mjSTATE_WARMSTART)  # cleared, as every call
        d.ctrl[:] = ctrl[w].numpy()
        for _ in range(sub):
            mujoco.mj_step(m, d)
        want = np.zeros(be.nstate)
        mujoco.mj_getState(m, d, want, mujoco.mjtState.mjSTATE_FULLPHYSICS)
        np.testing.assert_array_equal(be.state[w], want)
