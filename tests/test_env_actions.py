"""Action spaces: residual targets around the reference of the frame being stepped to (fingers absolute),
InterMimic's absolute mapping, legacy run configs, and the same mapping in training, evaluation and view."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import torch

from wristmimic.env.config import EnvConfig, env_config_from_dict, variant_config
from wristmimic.env.vec_env import WristMimicEnv
from wristmimic.evaluate.trials import make_env
from wristmimic.rl import TrainSpec, preset, start_run
from wristmimic.rl.config import to_jsonable
from wristmimic.view.rollout import env_for_policy

from synthetic import converted_intermimic

SID = "sub1_box_000"


@pytest.fixture(scope="module")
def dataset(tmp_path_factory: pytest.TempPathFactory) -> Path:
    tmp = tmp_path_factory.mktemp("actions")
    return converted_intermimic(tmp, 30)


def _env(dataset: Path, **kw) -> WristMimicEnv:
    env = WristMimicEnv.from_file(dataset, SID, 3, variant_config("wristmimic", **kw), seed=0)
    env.reset(start_frames=torch.tensor([0, 5, 11]))
    return env


def test_residual_zero_action_targets_the_next_reference_frame_and_fingers_stay_absolute(dataset: Path) -> None:
    env = _env(dataset, velocity_feedforward=False)
    fingers = ~env.residual_hinges.numpy()
    assert fingers.sum() == 3 * len(env.scene.humanoid.roles["fingers"]) > 0
    a = torch.zeros(3, env.action_size)
    ctrl = env.action_to_ctrl(a).numpy()
    ref = env.ref.joint_angles[torch.tensor([1, 6, 12])].numpy()
    lo, hi = env.scene.ctrl_range[:, 0], env.scene.ctrl_range[:, 1]
    np.testing.assert_allclose(ctrl[:, ~fingers], np.clip(ref, lo, hi)[:, ~fingers], atol=1e-6)
    absolute = _env(dataset, action_mode="absolute").action_to_ctrl(a).numpy()
    np.testing.assert_array_equal(ctrl[:, fingers], absolute[:, fingers])  # fingers: the same absolute mapping
    # one unit of action moves a body hinge by residual_scale (inside its range)
    one = env.action_to_ctrl(torch.full((3, env.action_size), 0.1)).numpy() - ctrl
    inside = (ref + 0.1 * env.cfg.residual_scale < hi) & (ref > lo)
    np.testing.assert_allclose(one[:, ~fingers][inside[:, ~fingers]], 0.1 * env.cfg.residual_scale, atol=1e-5)


def test_velocity_feedforward_adds_kv_over_kp_times_the_reference_velocity(dataset: Path) -> None:
    with_ff, without = _env(dataset), _env(dataset, velocity_feedforward=False)
    a = torch.zeros(3, with_ff.action_size)
    diff = (with_ff.action_to_ctrl(a) - without.action_to_ctrl(a)).numpy()
    body = with_ff.residual_hinges.numpy()
    vel = with_ff.ref.joint_vel[torch.tensor([1, 6, 12])].numpy()
    kp, kv = with_ff.scene.gains[:, 0], with_ff.scene.gains[:, 1]
    free = (np.abs(without.action_to_ctrl(a).numpy()) < 1.0) & body  # away from range clipping
    np.testing.assert_allclose(diff[free], (kv / kp * vel)[free], atol=1e-5)


def test_gravity_feedforward_balances_gravity_at_the_reference_pose_on_upper_body_hinges(dataset: Path) -> None:
    """With ``gravity_feedforward`` the PD torque at the reference pose (zero velocity) equals MuJoCo's gravity
    force on every upper-body hinge; legs and fingers keep the plain targets."""
    import mujoco

    from wristmimic.env.gravity import leg_bodies

    env, plain = (
        _env(dataset, velocity_feedforward=False, gravity_feedforward=True),
        _env(dataset, velocity_feedforward=False),
    )
    sc, m = env.scene, env.scene.model
    skel, roles = sc.skeleton, sc.humanoid.roles
    legs = np.repeat(np.isin(skel.joint_bodies, leg_bodies(sc)), 3)
    fingers = np.repeat(np.isin(skel.joint_bodies, roles["fingers"]), 3)
    assert legs.sum() >= 4 * 3 * 2 and not (legs & fingers).any()
    a, frames = torch.zeros(3, env.action_size), torch.tensor([0, 9, 20])
    diff = (env.action_to_ctrl(a, frames) - plain.action_to_ctrl(a, frames)).numpy()
    assert np.all(diff[:, legs | fingers] == 0.0) and np.abs(diff).max() > 1e-3
    d = mujoco.MjData(m)
    ctrl = env.action_to_ctrl(a, frames).numpy()
    lo, hi = sc.ctrl_range[:, 0], sc.ctrl_range[:, 1]
    dof = sc.hinge_dofadr.reshape(-1)
    checked = 0
    for i, f in enumerate(frames.tolist()):
        d.qpos[:] = m.qpos0
        d.qpos[0:3], d.qpos[3:7] = env.ref.root_pos[f].numpy(), env.ref.root_quat[f].numpy()
        d.qpos[sc.hinge_qposadr.reshape(-1)] = env.ref.joint_angles[f].numpy()
        d.qvel[:] = 0.0
        d.ctrl[sc.actuator_ids.reshape(-1)] = ctrl[i]
        mujoco.mj_forward(m, d)
        upper = ~(legs | fingers) & (ctrl[i] > lo + 1e-6) & (ctrl[i] < hi - 1e-6)  # not clipped to the range
        np.testing.assert_allclose(d.qfrc_actuator[dof][upper], d.qfrc_bias[dof][upper], atol=1e-2)
        assert np.abs(d.qfrc_bias[dof][upper]).max() > 1.0  # gravity does load these hinges
        checked += upper.sum()
    assert checked > 0


def test_absolute_mode_is_intermimic_mapping_and_unknown_modes_are_refused(dataset: Path) -> None:
    env = _env(dataset, action_mode="absolute")
    assert not env.residual_hinges.any()
    lo, hi = env.scene.ctrl_range[:, 0], env.scene.ctrl_range[:, 1]
    ctrl = env.action_to_ctrl(torch.zeros(1, env.action_size)).numpy()[0]
    mid = (lo + hi) / 2
    np.testing.assert_allclose(ctrl, np.where(np.abs(mid) > 0.1, 0.0, mid), atol=1e-6)
    with pytest.raises(ValueError, match="action_mode"):
        _env(dataset, action_mode="delta")


def test_range_fingers_span_exactly_each_finger_range_and_leave_the_body_alone(dataset: Path) -> None:
    """``finger_action=range``: a = -1 / 0 / +1 put every finger hinge at its lower limit / mid-range / upper limit
    (``absolute`` puts the off-centre flexing hinges at 0 for a = 0 and saturates them); body hinges unchanged."""
    env, plain = _env(dataset, finger_action="range"), _env(dataset)
    fingers = np.repeat(np.isin(env.scene.skeleton.joint_bodies, env.scene.humanoid.roles["fingers"]), 3)
    lo, hi = env.scene.ctrl_range[:, 0], env.scene.ctrl_range[:, 1]
    off_centre = fingers & (np.abs((lo + hi) / 2) > 0.1)
    assert off_centre.sum() >= 10  # the last segment of each finger flexes one way only
    a = torch.tensor([-1.0, 0.0, 1.0])[:, None].expand(3, env.action_size)
    frames = torch.tensor([0, 5, 9])
    ctrl, base = env.action_to_ctrl(a, frames).numpy(), plain.action_to_ctrl(a, frames).numpy()
    np.testing.assert_allclose(ctrl[:, fingers], np.stack([lo, (lo + hi) / 2, hi])[:, fingers], atol=1e-6)
    np.testing.assert_array_equal(ctrl[:, ~fingers], base[:, ~fingers])
    assert np.abs(base[1, off_centre]).max() < 1e-6  # absolute: a = 0 is 0 rad on those hinges
    half = torch.full((1, env.action_size), 0.5)  # absolute: already at the range's end at a = 0.5
    np.testing.assert_allclose(plain.action_to_ctrl(half).numpy()[0, off_centre], hi[off_centre], atol=1e-6)


def test_runs_recorded_before_action_modes_read_as_absolute() -> None:
    old = to_jsonable(EnvConfig())
    for key in ("action_mode", "velocity_feedforward", "residual_scale", "object_controller", "starts"):
        old.pop(key)
    cfg = env_config_from_dict(old)
    assert cfg.action_mode == "absolute" and not cfg.object_controller.enabled and not cfg.starts.adaptive
    assert env_config_from_dict(to_jsonable(EnvConfig())) == EnvConfig()


def test_delta_fingers_hold_the_start_pose_and_move_by_the_scale_each_step(dataset: Path) -> None:
    env = _env(dataset, finger_action="delta", finger_delta_scale=0.05)
    plain = _env(dataset)
    fingers = env.delta_hinges.numpy()
    assert (
        fingers.sum() == 3 * len(env.scene.humanoid.roles["fingers"])
        and not (fingers & env.residual_hinges.numpy()).any()
    )
    lo, hi = env.scene.ctrl_range[:, 0], env.scene.ctrl_range[:, 1]
    start = np.clip(env.ref.joint_angles[torch.tensor([0, 5, 11])].numpy(), lo, hi)
    a = torch.zeros(3, env.action_size)
    np.testing.assert_allclose(env.action_to_ctrl(a).numpy()[:, fingers], start[:, fingers], atol=1e-6)
    # body hinges map exactly as without delta fingers
    torch.testing.assert_close(env.action_to_ctrl(a)[:, ~fingers], plain.action_to_ctrl(a)[:, ~fingers])
    # the observation carries held target - finger angle (zero right after a reference reset, up to clipping)
    obs = env.observe()
    part = env.obs_layout["finger_hold"]
    assert obs.shape[1] == plain.observe().shape[1] + fingers.sum() and part.stop - part.start == fingers.sum()
    q = env.ref.joint_angles[torch.tensor([0, 5, 11])].numpy()[:, fingers]
    np.testing.assert_allclose(obs[:, part].numpy(), start[:, fingers] - q, atol=1e-6)
    # two steps of +0.5 move the held target by 2 * 0.5 * scale (inside the range), state_dict carries it
    half = torch.where(env.delta_hinges, 0.5, 0.0).expand(3, -1)  # body hinges on the reference: no resets
    for _ in range(2):
        assert not env.step(half)[2].any()
    held = env.action_to_ctrl(a).numpy()[:, fingers]
    want = np.clip(np.clip(start[:, fingers] + 0.025, lo[fingers], hi[fingers]) + 0.025, lo[fingers], hi[fingers])
    np.testing.assert_allclose(held, want, atol=1e-5)
    other = _env(dataset, finger_action="delta", finger_delta_scale=0.05)
    other.load_state_dict(env.state_dict())
    torch.testing.assert_close(other.action_to_ctrl(a), env.action_to_ctrl(a), rtol=0, atol=0)
    with pytest.raises(ValueError, match="finger_action"):
        _env(dataset, finger_action="synergy")


@pytest.mark.parametrize(
    "mode, gravity, fingers, synergy, grip",
    [
        ("residual", False, "absolute", 0.0, False),
        ("residual", True, "absolute", 0.0, False),
        ("absolute", False, "absolute", 0.0, False),
        ("residual", False, "delta", 0.0, False),
        ("residual", False, "range", 0.0, False),
        ("residual", False, "absolute", 1.0, False),
        ("residual", False, "absolute", 0.0, True),
    ],
)
def test_train_evaluate_and_view_map_actions_the_same_way(
    dataset: Path, tmp_path: Path, mode: str, gravity: bool, fingers: str, synergy: float, grip: bool
) -> None:
    from wristmimic.evaluate.policy import load_eval_policy

    env_cfg = variant_config(
        "wristmimic",
        action_mode=mode,
        gravity_feedforward=gravity,
        finger_action=fingers,
        finger_synergy=synergy,
        finger_grip=_grip(dataset) if grip else (),
    )
    ppo = preset("cpu", num_envs=4, horizon=8, minibatch_size=16, epochs=1, actor_hidden=(16,), critic_hidden=(16,))
    spec = TrainSpec(dataset, SID, "wristmimic", 0, "cpu", replace(ppo, max_frames=32), env=env_cfg)
    start_run(spec, tmp_path / "run", progress=False)
    policy = load_eval_policy(tmp_path / "run")
    train_env = WristMimicEnv.from_file(dataset, SID, 2, env_cfg)
    eval_env = make_env(policy.metadata, 2)
    view_env = env_for_policy(policy, None, None)
    a = torch.linspace(-1, 1, 2 * train_env.action_size).reshape(2, -1)
    frames = torch.tensor([3, 17])
    train_env.reset(start_frames=frames)
    want = train_env.action_to_ctrl(a, frames)
    for env in (eval_env, view_env):
        env.reset(start_frames=frames[: env.num_worlds])
        assert env.cfg.action_mode == mode and env.cfg.gravity_feedforward == gravity
        assert env.cfg.finger_action == fingers and env.cfg.finger_synergy == synergy
        assert env.cfg.finger_grip == env_cfg.finger_grip
        assert env.action_size == env.num_hinges + (2 if synergy else 0) == policy.policy.action_size
        assert not env.has_object_controller  # the training-only object controller never reaches them
        n = env.num_worlds
        torch.testing.assert_close(env.action_to_ctrl(a[:n], frames[:n]), want[:n], rtol=0, atol=0)


def _grip(dataset: Path) -> tuple[float, ...]:
    """A grip with a different angle on every finger hinge (0.05 to 0.6 rad)."""
    n = int(_env(dataset).finger_actions.sum())
    return tuple(float(v) for v in np.linspace(0.05, 0.6, n))


def test_finger_grip_centres_a_touching_hands_finger_actions_on_the_grip(dataset: Path) -> None:
    from wristmimic.env.clearance import contact_ramp
    from wristmimic.env.config import check_env_config

    for bad in ({"finger_grip": (4.0,)}, {"finger_grip": (True,)}, {"finger_grip": (0.1,), "finger_action": "delta"}):
        with pytest.raises(ValueError, match="finger_grip"):
            check_env_config(EnvConfig(**bad))
    for bad in (-1, True, 2.5):
        with pytest.raises(ValueError, match="finger_grip_from"):
            check_env_config(EnvConfig(finger_grip_from=bad))
    with pytest.raises(ValueError, match="finger_grip has 3 angles"):
        _env(dataset, finger_grip=(0.1, 0.2, 0.3))
    grip = np.asarray(_grip(dataset))
    plain, env = _env(dataset), _env(dataset, finger_grip=tuple(grip))
    T, H = env.ref.num_frames, env.num_hinges
    fingers = env.finger_actions.numpy()
    skel, roles = env.scene.skeleton, env.scene.humanoid.roles
    lo, hi = env.scene.ctrl_range[:, 0], env.scene.ctrl_range[:, 1]
    weight = 1.0 - contact_ramp(~env.ref.hand.numpy().astype(bool), 10)  # inside each contact, 10-frame ramps
    assert (weight == 1).any() and (weight == 0).any()  # the clip has touching and free frames for the test
    touch = env.ref.hand.numpy().astype(bool)
    assert (weight[~touch] == 0).all() and (weight[touch] > 0).all()  # only while the reference hand touches
    frames = torch.arange(T)
    a = torch.linspace(-0.3, 0.3, T * H).reshape(T, H)
    with_grip, without = env.action_to_ctrl(a, frames).numpy(), plain.action_to_ctrl(a, frames).numpy()
    np.testing.assert_array_equal(with_grip[:, ~fingers], without[:, ~fingers])  # body and wrists untouched
    offset, scale = env._offset.numpy(), env._scale.numpy()
    target = np.zeros(H)
    target[fingers] = grip
    for h, side in enumerate(("left", "right")):
        cols = fingers & np.repeat(np.isin(skel.joint_bodies, roles[f"{side}_hand"]), 3)
        assert cols.sum() == fingers.sum() // 2
        want = offset + weight[:, h : h + 1] * (target - offset) + scale * a.numpy()  # centre moves to the grip
        np.testing.assert_allclose(with_grip[:, cols], np.clip(want, lo, hi)[:, cols], atol=1e-5)
        free = weight[:, h] == 0
        np.testing.assert_array_equal(with_grip[free][:, cols], without[free][:, cols])
    left = fingers & np.repeat(np.isin(skel.joint_bodies, roles["left_hand"]), 3)
    full = weight[:, 0] == 1
    assert full.sum() >= 3
    held = env.action_to_ctrl(torch.zeros(T, H), frames).numpy()  # a = 0 holds the grip while the hand touches
    np.testing.assert_allclose(
        held[full][:, left], np.clip(target, lo, hi)[None, left].repeat(full.sum(), 0), atol=1e-6
    )
    first = int(np.flatnonzero(full)[0])  # from a later frame: off before it, then ramped in over 10 frames
    late = _env(dataset, finger_grip=tuple(grip), finger_grip_from=first + 2).action_to_ctrl(a, frames).numpy()
    np.testing.assert_array_equal(late[: first + 2], without[: first + 2])
    ramp = np.clip((np.arange(T) - first - 1) / 10, 0.0, 1.0)[:, None]
    want = offset + ramp * weight[:, :1] * (target - offset) + scale * a.numpy()
    np.testing.assert_allclose(late[:, left], np.clip(want, lo, hi)[:, left], atol=1e-5)


def test_grasp_synergy_adds_one_action_per_hand_that_curls_only_that_hands_fingers(dataset: Path) -> None:
    from wristmimic.env.config import check_env_config
    from wristmimic.env.synergy import closure_coefficients

    for bad in ({"finger_synergy": -0.1}, {"finger_synergy": 4.0}, {"finger_synergy": 1.0, "finger_action": "delta"}):
        with pytest.raises(ValueError, match="finger_synergy"):
            check_env_config(EnvConfig(**bad))
    plain, env = _env(dataset), _env(dataset, finger_synergy=0.8)
    H = env.num_hinges
    assert plain.action_size == H and env.action_size == H + 2
    a = torch.linspace(-0.5, 0.5, 3 * H).reshape(3, H)
    zero = torch.zeros(3, 2)
    # zero synergy: exactly the targets without it
    torch.testing.assert_close(env.action_to_ctrl(torch.cat([a, zero], 1)), plain.action_to_ctrl(a), rtol=0, atol=0)
    c = closure_coefficients(env.scene)
    fingers = env.finger_actions.numpy()
    assert np.abs(c[:, ~fingers]).max() == 0.0  # body and wrist hinges never move
    assert np.abs(c).max(axis=1).tolist() == [1.0, 1.0]
    roles, skel = env.scene.humanoid.roles, env.scene.skeleton
    for h, side in enumerate(("left", "right")):
        on_hand = np.repeat(np.isin(skel.joint_bodies, roles[f"{side}_hand"]), 3)
        assert (np.abs(c[h]) > 0.5).sum() >= 5 and np.abs(c[h][~on_hand]).max() == 0.0
        g = zero.clone()
        g[:, h] = 0.5
        moved = (env.action_to_ctrl(torch.cat([a, g], 1)) - plain.action_to_ctrl(a)).numpy()
        base = plain.action_to_ctrl(a).numpy()
        lo, hi = env.scene.ctrl_range[:, 0], env.scene.ctrl_range[:, 1]
        free = (base + 0.4 * c[h] < hi) & (base + 0.4 * c[h] > lo)  # targets the joint ranges do not clip
        np.testing.assert_allclose(moved[free], np.broadcast_to(0.4 * c[h], moved.shape)[free], atol=1e-6)
        assert np.abs(moved[:, ~on_hand]).max() == 0.0


@pytest.mark.parametrize("source", ["synthetic", "parahome"])
def test_positive_synergy_moves_every_fingertip_toward_its_palm(dataset: Path, source: str, request) -> None:
    import mujoco

    from wristmimic.env.synergy import closure_coefficients, palm_normal, tip_point

    if source == "parahome":
        from wristmimic.format.reader import open_dataset
        from wristmimic.scene import build_scene

        path = request.getfixturevalue("parahome_h5")
        with open_dataset(path) as ds:
            scene = build_scene(ds, ds.sequence_ids[0])
    else:
        scene = _env(dataset).scene
    m, skel, roles = scene.model, scene.skeleton, scene.humanoid.roles
    c = closure_coefficients(scene)
    ids = np.array([mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, n) for n in skel.body_names])

    def tips_along_normal(amount: float, h: int, side: str) -> np.ndarray:
        d = mujoco.MjData(m)
        d.qpos[:] = m.qpos0
        d.qpos[scene.hinge_qposadr.reshape(-1)] += amount * c[h]
        mujoco.mj_kinematics(m, d)
        wrist = [int(w) for w in roles["wrists"] if w in roles[f"{side}_hand"]][0]
        n = palm_normal(np.array([d.xpos[ids[k]] for k in [*skel.children(wrist), wrist]]), np.array([0, 0, -1.0]))
        tips = [tip_point(m, d, int(ids[t]), int(ids[skel.parents[t]])) for t in roles[f"{side}_fingertips"]]
        return (np.array(tips) - d.xpos[ids[wrist]]) @ n

    for h, side in enumerate(("left", "right")):
        rest, curled = tips_along_normal(0.0, h, side), tips_along_normal(0.3, h, side)
        assert (curled - rest > 0.003).all(), (side, curled - rest)  # every fingertip >= 3 mm toward the palm
