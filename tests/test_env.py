"""The batched environment on both humanoid families and every variant: shapes, NaNs, reference resets,
batched vs one-world-at-a-time equality, truncation and auto-reset."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

from wristmimic.convert.common import ConvertOptions
from wristmimic.convert.intermimic import convert_intermimic
from wristmimic.convert.skillmimic_parahome import convert_skillmimic_parahome
from wristmimic.env import window as W
from wristmimic.env.config import VARIANTS, EnvConfig, TerminationConfig, variant_config
from wristmimic.env.vec_env import WristMimicEnv
from wristmimic.scene import SceneConfig

from synthetic import write_intermimic_folder, write_parahome_folder


@pytest.fixture(scope="module")
def files(tmp_path_factory: pytest.TempPathFactory) -> dict[str, tuple[Path, str]]:
    tmp = tmp_path_factory.mktemp("env")
    opts = ConvertOptions(hull_cache_dir=tmp / "c", show_progress=False)
    convert_intermimic(write_intermimic_folder(tmp / "im", T=50), tmp / "im.h5", options=opts)
    convert_skillmimic_parahome(write_parahome_folder(tmp / "ph", T=50), tmp / "ph.h5", options=opts)
    return {"smplx": (tmp / "im.h5", "sub1_box_000"), "parahome": (tmp / "ph.h5", "s1_move_box")}


@pytest.mark.parametrize("family", ["smplx", "parahome"])
@pytest.mark.parametrize("variant", VARIANTS)
def test_reset_and_step_every_variant_and_humanoid(files, family: str, variant: str) -> None:
    path, sid = files[family]
    env = WristMimicEnv.from_file(path, sid, num_worlds=3, config=variant_config(variant), seed=1, nthread=1)
    obs, _ = env.reset()
    assert obs.shape == (3, env.observation_size) and obs.dtype == torch.float32
    assert env.action_size == 3 * (env.scene.skeleton.num_bodies - 1)
    gen = torch.Generator().manual_seed(0)
    for _ in range(5):
        obs, rew, term, trunc, info = env.step(torch.rand(3, env.action_size, generator=gen) * 2 - 1)
        assert torch.isfinite(obs).all() and torch.isfinite(rew).all()
        assert rew.shape == term.shape == trunc.shape == (3,)
        assert ((rew >= 0) & (rew <= 1)).all()
    finger_goal = env.cfg.finger_targets
    n_track = len(env.tracked)
    assert n_track == len(env.scene.humanoid.roles["key_bodies"]) + (
        len(env.scene.humanoid.roles["fingers"]) if finger_goal else 0
    )
    env.close()


@pytest.mark.parametrize("family", ["smplx", "parahome"])
def test_fingertip_guidance_reads_each_hands_tips_against_the_object_points(
    files, family: str, request: pytest.FixtureRequest
) -> None:
    """On the synthetic SMPL-X clip and the real kettle (the synthetic ParaHome clip has no hand contact)."""
    from dataclasses import replace

    from wristmimic.env.config import RewardWeights

    if family == "smplx":
        path, sid = files[family]
    else:
        path, sid = request.getfixturevalue("parahome_h5"), "s110_move_kettle"
    cfg = variant_config("wristmimic", weights=RewardWeights(fingertip=20.0))
    env = WristMimicEnv.from_file(path, sid, num_worlds=3, config=cfg, seed=1, nthread=1)
    touching = torch.nonzero(env.ref.hand.any(-1)).flatten()
    assert touching.numel() > 2
    env.reset(start_frames=(touching[[0, touching.numel() // 2, -1]] - 1).clamp(0, env.ref.num_frames - 3))
    assert (
        env.sets.fingertips.shape == (2, len(env.scene.humanoid.roles["left_fingertips"]))
        and env.sets.fingertips.numel() >= 2
    )
    _, _, _, _, info = env.step(torch.zeros(3, env.action_size))
    s, rf = env.sim_state(), env.ref_frame(env.frame)
    tips = s.body_pos[:, env.sets.fingertips]  # (N, 2, nt, 3)
    d = (tips[:, :, :, None] - s.points[:, None, None]).norm(dim=-1).amin(-1).mean(-1)  # (N, 2)
    want = (d * rf.hand).sum(-1)
    assert rf.hand.any() and torch.equal(want > 0, rf.hand.any(-1))  # only hands in reference contact count
    torch.testing.assert_close(info["terms"]["error/fingertip"], want, rtol=1e-4, atol=1e-5)
    plain = WristMimicEnv.from_file(path, sid, 1, config=replace(cfg, weights=RewardWeights()), seed=1, nthread=1)
    plain.reset()
    assert "error/fingertip" not in plain.step(torch.zeros(1, plain.action_size))[4]["terms"]


def test_velocity_factors_read_the_simulated_velocities_against_central_differences(files) -> None:
    from wristmimic.env.config import RewardWeights

    path, sid = files["smplx"]
    cfg = variant_config("wristmimic", weights=RewardWeights(root_vel=2.0, body_vel=1.0))
    env = WristMimicEnv.from_file(path, sid, num_worlds=3, config=cfg, seed=1, nthread=1)
    env.reset(start_frames=torch.tensor([0, 10, 30]))
    _, _, _, _, info = env.step(torch.zeros(3, env.action_size))
    s, f = env.sim_state(), env.frame
    p = env.ref.body_pos  # the reference velocity at frame f: (p[f+1] - p[f-1]) / 2 at 30 fps
    v_ref = (p.index_select(0, f + 1) - p.index_select(0, f - 1)) * 15.0
    e = (v_ref - s.body_linvel).square().sum(-1)
    assert (e[:, 0] > 0).all() and torch.isfinite(e).all()
    torch.testing.assert_close(info["terms"]["error/root_vel"], e[:, 0], rtol=1e-4, atol=1e-5)
    torch.testing.assert_close(info["terms"]["error/body_vel"], e.mean(-1), rtol=1e-4, atol=1e-5)
    torch.testing.assert_close(info["terms"]["reward/root_vel"], torch.exp(-2.0 * e[:, 0]), rtol=1e-4, atol=1e-6)


def test_feet_contact_schedule_follows_the_reference_feet_and_the_simulated_contacts(files) -> None:
    from wristmimic.env.config import RewardWeights
    from wristmimic.env.grounding import foot_floor_contact

    path, sid = files["smplx"]
    cfg = variant_config("wristmimic", weights=RewardWeights(feet_contact=2.0))
    env = WristMimicEnv.from_file(path, sid, num_worlds=3, config=cfg, seed=1, nthread=1)
    r, feet = env.ref, env.sets.feet.numpy()
    assert len(feet) == 4
    args = (r.root_pos.double().numpy(), r.root_quat.double().numpy(), r.joint_angles.double().numpy())
    table = foot_floor_contact(env.scene, *args, feet)
    assert torch.equal(env._ref_feet_contact, torch.from_numpy(table))
    assert table.any(), "the synthetic humanoid stands on a foot"
    # a reference floating 3 cm higher throughout stands the same (heights count from the standing height) ...
    up = args[0] + [0.0, 0.0, 0.03]
    np.testing.assert_array_equal(foot_floor_contact(env.scene, up, *args[1:], feet), table)
    # ... and one lifted 30 cm for its last fifth has no foot on the floor there
    T = len(up)
    up[: T - T // 5, 2] -= 0.03
    up[T - T // 5 :, 2] += 0.27
    assert not foot_floor_contact(env.scene, up, *args[1:], feet)[T - T // 5 :].any()
    env.reset(start_frames=torch.tensor([0, 10, 30]))
    _, _, _, _, info = env.step(torch.zeros(3, env.action_size))
    s, f = env.sim_state(), env.frame
    want = (s.contact.index_select(1, env.sets.feet) != env._ref_feet_contact.index_select(0, f)).float().mean(-1)
    torch.testing.assert_close(info["terms"]["error/feet_contact"], want)
    assert s.contact.index_select(1, env.sets.feet).any()  # simulated feet touch the floor


def test_goal_differences_are_zero_after_a_reference_reset(files) -> None:
    path, sid = files["smplx"]
    env = WristMimicEnv.from_file(path, sid, num_worlds=4, config=EnvConfig(goal_horizons=(0,)), nthread=1)
    obs, _ = env.reset(start_frames=torch.tensor([0, 7, 20, 33]))
    for name in ("dpos", "drot", "obj_dpos", "obj_drot", "dig"):
        block = obs[:, env.obs_layout[f"goal0/{name}"]]
        assert block.abs().max() < 2e-3, (name, block.abs().max())
    # a horizon ahead is not zero: the motion moves
    env2 = WristMimicEnv.from_file(path, sid, num_worlds=1, config=EnvConfig(goal_horizons=(5,)), nthread=1)
    obs2, _ = env2.reset(start_frames=torch.tensor([7]))
    assert obs2[:, env2.obs_layout["goal5/dpos"]].abs().max() > 1e-2


NO_END = TerminationConfig(fall_height=-1.0, body_error=1e9, object_error=1e9, contact_lost_frames=10**6)


def test_batched_equals_one_world_at_a_time(files) -> None:
    """Same start frames and actions: 3 worlds stepped together (2 threads) equal 3 single-world envs.
    Terminations are off so that no auto-reset draws a random start frame."""
    path, sid = files["smplx"]
    cfg = EnvConfig(wrist_resets=False, termination=NO_END)
    frames = torch.tensor([0, 5, 11])
    actions = torch.rand(6, 3, 153, generator=torch.Generator().manual_seed(3)) * 2 - 1
    batched = WristMimicEnv.from_file(path, sid, num_worlds=3, config=cfg, nthread=2)
    obs_b, _ = batched.reset(start_frames=frames)
    out_b = [batched.step(a) for a in actions]
    for w in range(3):
        single = WristMimicEnv.from_file(path, sid, num_worlds=1, config=cfg, nthread=1)
        obs_s, _ = single.reset(start_frames=frames[w : w + 1])
        assert torch.allclose(obs_s[0], obs_b[w], atol=1e-5)
        for k, a in enumerate(actions):
            o, r, te, tr, _ = single.step(a[w : w + 1])
            assert torch.allclose(o[0], out_b[k][0][w], atol=1e-4), (w, k)
            assert torch.allclose(r[0], out_b[k][1][w], atol=1e-5)
            assert te[0] == out_b[k][2][w] and tr[0] == out_b[k][3][w]


def test_prepare_and_finish_step_on_a_worker_thread_equal_step(files) -> None:
    """benchmarks/async_overlap.py's schedule: two environments in alternation, one's physics on a worker thread
    while the main thread finishes the other's step, give bit for bit what plain ``step`` gives (auto-resets
    included: episodes end on the default terminations under large actions)."""
    from concurrent.futures import ThreadPoolExecutor

    path, sid = files["smplx"]
    actions = torch.rand(12, 2, 4, 153, generator=torch.Generator().manual_seed(5)) * 2 - 1

    def pair() -> list[WristMimicEnv]:
        envs = [WristMimicEnv.from_file(path, sid, num_worlds=4, seed=k, nthread=2) for k in range(2)]
        for e in envs:
            e.reset()
        return envs

    plain = pair()
    ref = [[plain[k].step(a[k]) for k in range(2)] for a in actions]
    split = pair()
    sub = split[0].scene.config.substeps
    with ThreadPoolExecutor(1) as pool:
        for t, a in enumerate(actions):
            ja = pool.submit(split[0].backend.step, split[0].prepare_step(a[0]), sub)
            ja.result()
            jb = pool.submit(split[1].backend.step, split[1].prepare_step(a[1]), sub)
            got_a = split[0].finish_step(a[0])  # runs while b's physics runs
            jb.result()
            got_b = split[1].finish_step(a[1])
            for k, got in enumerate((got_a, got_b)):
                for x, y in zip(got[:4], ref[t][k][:4], strict=True):
                    assert torch.equal(x, y), (t, k)
                assert torch.equal(got[4]["termination_reason"], ref[t][k][4]["termination_reason"])
    ends = sum(int(ref[t][k][2].sum()) for t in range(len(actions)) for k in range(2))
    assert ends > 0  # the schedule went through auto-resets


def test_truncation_at_sequence_end_and_auto_reset(files) -> None:
    path, sid = files["smplx"]
    env = WristMimicEnv.from_file(
        path, sid, num_worlds=2, config=EnvConfig(wrist_resets=False, termination=NO_END), nthread=1
    )
    T = env.ref.num_frames
    env.reset(start_frames=torch.tensor([T - 3, 0]))
    for _ in range(2):
        _, _, term, trunc, info = env.step(torch.zeros(2, env.action_size))
    assert trunc.tolist() == [True, False] and not term.any()
    assert info["time_outs"][0] and env.frame[0] < T - 1  # world 0 was reset to a new start frame


def test_window_phase_follows_t_c(files) -> None:
    path, sid = files["smplx"]
    env = WristMimicEnv.from_file(path, sid, num_worlds=1, nthread=1)
    t_c = env.ref.t_c
    assert t_c == int(env.ref.first_contact[env.ref.first_contact >= 0].min())
    for f, expected in ((t_c - 2, W.GRASP), (t_c + 13, W.STABILIZE), (t_c + 16, W.OUTSIDE)):
        if 0 <= f < env.ref.num_frames:
            env.frame[:] = f
            assert env._window()[1].item() == expected


@pytest.mark.shared_data
@pytest.mark.parametrize("which", ["omomo", "parahome"])
def test_real_scenes_step(which: str, omomo_h5: Path, parahome_h5: Path) -> None:
    """The real OMOMO (52 bodies) and ParaHome (61 bodies) scenes reset at frame 0 with zero goal at t+0 and
    step without NaN; the reference PD targets keep the reward high over the first frames."""
    path, sid = (omomo_h5, "sub2_largetable_000") if which == "omomo" else (parahome_h5, "s110_move_kettle")
    env = WristMimicEnv.from_file(path, sid, num_worlds=2, config=EnvConfig(goal_horizons=(0, 1)), nthread=2)
    obs, _ = env.reset(start_frames=torch.tensor([0, 0]))
    assert obs[:, env.obs_layout["goal0/dpos"]].abs().max() < 2e-3
    # actions that command the reference joint angles of the next frame
    rewards = []
    for t in range(1, 8):
        target = env.ref.joint_angles[t].expand(2, -1)
        a = ((target - env._offset) / env._scale).clamp(-1, 1)
        obs, r, term, trunc, info = env.step(a)
        assert torch.isfinite(obs).all()
        rewards.append(r.mean().item())
    assert min(rewards) > 0.05, rewards
    env.close()


@pytest.mark.shared_data
@pytest.mark.parametrize("which", ["omomo", "parahome"])
def test_real_training_scenes_build_with_every_training_only_actuator(
    which: str, omomo_h5: Path, parahome_h5: Path
) -> None:
    """The object controller's and root assist's motors and the hands' adhesion actuators compile on both real
    humanoids (ParaHome's MJCF gives actuators a negative default control range, which adhesion refuses)."""
    path, sid = (omomo_h5, "sub2_largetable_000") if which == "omomo" else (parahome_h5, "s110_move_kettle")
    sc = SceneConfig(object_actuators=True, root_actuators=True, hand_adhesion=True)
    env = WristMimicEnv.from_file(path, sid, num_worlds=1, config=EnvConfig(), scene_config=sc, nthread=1)
    hands = [b for k in ("left_hand", "right_hand") for b in env.scene.humanoid.roles[k]]
    assert env.has_object_controller and env.has_root_assist and env._adh_cols.numel() == len(hands) > 2
    assert (env.scene.model.actuator_ctrlrange[env._adh_cols.numpy()] == [0.0, 1000.0]).all()
    env.close()


def test_state_dict_round_trip_continues_identically(files) -> None:
    path, sid = files["smplx"]
    gen = torch.Generator().manual_seed(5)
    actions = [torch.rand(3, 153, generator=gen) * 2 - 1 for _ in range(8)]
    a = WristMimicEnv.from_file(path, sid, num_worlds=3, seed=2, nthread=1)
    a.reset()
    for act in actions[:4]:
        a.step(act)
    saved = a.state_dict()
    rest_a = [a.step(act) for act in actions[4:]]
    b = WristMimicEnv.from_file(path, sid, num_worlds=3, seed=99, nthread=1)
    b.reset()
    b.load_state_dict(saved)
    for act, ra in zip(actions[4:], rest_a, strict=True):
        rb = b.step(act)
        assert torch.equal(ra[0], rb[0]) and torch.equal(ra[1], rb[1]) and torch.equal(ra[2], rb[2])


def test_state_bank_restores_states_the_policy_reached_and_survives_a_checkpoint(files) -> None:
    """Mid-clip training starts restore banked states (reached from frame 0); evaluation never uses the bank;
    a checkpoint round trip continues identically with the bank on."""
    from dataclasses import replace

    from wristmimic.evaluate.trials import eval_env_config

    path, sid = files["smplx"]
    base = EnvConfig()
    cfg = replace(base, reset_frame0_prob=0.0, starts=replace(base.starts, bank=1.0, bank_size=2))
    env = WristMimicEnv.from_file(path, sid, num_worlds=3, config=cfg, seed=0, nthread=1)
    env.reset(start_frames=torch.tensor([0, 0, 10]))  # worlds 0, 1 descend from frame 0, world 2 does not
    zero = torch.zeros(3, env.action_size)
    reached = []
    for _ in range(6):
        env.step(zero)
        reached.append(env.backend.qpos.clone())
    f = 3
    banked = env.bank.qpos[f][env.bank.filled[f]]
    assert len(banked) >= 1
    assert all(any(torch.equal(b, reached[f - 1][i]) for i in (0, 1)) for b in banked)  # only frame-0 lineages
    assert not env.bank.filled[13:].any()  # world 2 (from frame 10, a reference start) recorded nothing
    env.sample_start_frames = lambda n: torch.full((n,), f)  # type: ignore[method-assign]
    env._reset_worlds(torch.tensor([True, False, False]))
    del env.sample_start_frames
    assert any(torch.equal(env.backend.qpos[0], b) for b in banked) and bool(env._lineage[0])
    # the reference's state at frame 3 is not what the policy reached (else this test could not fail)
    assert not torch.equal(env.reference_state(torch.tensor([f]))[0][0], env.backend.qpos[0])
    assert eval_env_config(cfg).starts.bank == 0.0
    # checkpoint round trip with a bank
    gen = torch.Generator().manual_seed(1)
    actions = [torch.rand(3, env.action_size, generator=gen) * 2 - 1 for _ in range(6)]
    saved = env.state_dict()
    rest = [env.step(a) for a in actions]
    other = WristMimicEnv.from_file(path, sid, num_worlds=3, config=cfg, seed=7, nthread=1)
    other.reset()
    other.load_state_dict(saved)
    for a, ra in zip(actions, rest, strict=True):
        rb = other.step(a)
        assert torch.equal(ra[0], rb[0]) and torch.equal(ra[1], rb[1])


def test_reference_until_folds_late_reference_starts_back_and_keeps_banked_ones(files) -> None:
    """With ``starts.reference_until`` u, sampled training starts after u restore a banked state or start at
    f mod (u + 1) from the reference; reference starts up to u bank what they reach; given frames (evaluation)
    and the default (-1) are untouched."""
    from dataclasses import replace

    path, sid = files["smplx"]
    base = EnvConfig()
    until = 4
    cfg = replace(base, reset_frame0_prob=0.0, starts=replace(base.starts, adaptive=False, reference_until=until))
    env = WristMimicEnv.from_file(path, sid, num_worlds=64, config=cfg, seed=0, nthread=1)
    sampled = env.sample_start_frames(64)
    assert int(sampled.max()) > until  # else this test could not fail
    env.sample_start_frames = lambda n: sampled  # type: ignore[method-assign]
    env._reset_worlds(torch.ones(64, dtype=torch.bool))
    torch.testing.assert_close(env.frame, torch.where(sampled > until, sampled % (until + 1), sampled))
    assert bool(env._lineage.all())  # every start is a trusted reference state
    ref = env.reference_state(env.frame)[0]
    assert torch.equal(env.backend.qpos, ref)
    env.reset(start_frames=torch.full((64,), 9))  # given frames: as asked
    assert bool((env.frame == 9).all()) and not env._lineage.any()
    # with the bank: a late start restores a state reached from a trusted start where one is banked
    until = 2
    cfg = replace(cfg, starts=replace(cfg.starts, bank=1.0, bank_size=2, reference_until=until))
    env = WristMimicEnv.from_file(path, sid, num_worlds=2, config=cfg, seed=0, nthread=1)
    env.reset(start_frames=torch.tensor([1, 1]))
    for _ in range(3):
        env.step(torch.zeros(2, env.action_size))
    assert bool((env.frame == 4).all())  # no episode ended
    assert env.bank.filled[4].any() and not env.bank.filled[5:].any()  # reached 4 from the reference at 1
    env.sample_start_frames = lambda n: torch.tensor([4, 11])  # type: ignore[method-assign]
    env._reset_worlds(torch.ones(2, dtype=torch.bool))
    banked = env.bank.qpos[4][env.bank.filled[4]]
    assert int(env.frame[0]) == 4 and any(torch.equal(env.backend.qpos[0], b) for b in banked)
    assert int(env.frame[1]) == 11 % (until + 1)  # nothing banked at 11: folded back


def test_ground_reference_lowers_the_humanoid_onto_the_floor(files) -> None:
    from dataclasses import replace

    from wristmimic.env.grounding import floor_clearance

    path, sid = files["smplx"]
    plain = WristMimicEnv.from_file(path, sid, num_worlds=1, nthread=1)
    env = WristMimicEnv.from_file(
        path, sid, num_worlds=1, config=replace(EnvConfig(), ground_reference=True), nthread=1
    )
    r0, r1, dz = plain.ref, env.ref, env.ref.grounded_by
    assert r0.grounded_by is None and dz is not None
    args = lambda r, up=0.0: (  # noqa: E731
        r.root_pos.double().numpy() + [0.0, 0.0, up],
        r.root_quat.double().numpy(),
        r.joint_angles.double().numpy(),
    )
    assert floor_clearance(env.scene, *args(r0)) == pytest.approx(dz, abs=1e-5)
    assert floor_clearance(env.scene, *args(r0, 0.05)) == pytest.approx(dz + 0.05, abs=1e-5)  # it measures height
    assert floor_clearance(env.scene, *args(r1)) == pytest.approx(0.0, abs=1e-5)  # grounded: feet on the floor
    torch.testing.assert_close(r1.body_pos[..., 2], r0.body_pos[..., 2] - dz)
    torch.testing.assert_close(r1.body_pos[..., :2], r0.body_pos[..., :2])
    assert torch.equal(r1.obj_pos, r0.obj_pos) and torch.equal(r1.joint_angles, r0.joint_angles)  # objects stay
    with pytest.raises(ValueError, match="ground_reference"):
        WristMimicEnv(plain.scene, plain.ref, 1, replace(EnvConfig(), ground_reference=True), nthread=1)


def test_sub2_reference_floats_above_the_floor_and_grounding_measures_it(omomo_h5: Path) -> None:
    """The fitted OMOMO humanoid's reference stands 1-2 cm above the floor (sub2: 1.4 cm median)."""
    from dataclasses import replace

    cfg = replace(EnvConfig(), ground_reference=True)
    env = WristMimicEnv.from_file(omomo_h5, "sub2_largetable_000", num_worlds=1, config=cfg, nthread=1)
    assert 0.005 < env.ref.grounded_by < 0.03


def _foot_heights(scene, root_pos, root_quat, angles):
    """(T, sides) lowest height of each side's foot geoms above the floor."""
    import mujoco
    import numpy as np

    from wristmimic.env.grounding import _foot_chains

    m = scene.model
    d = mujoco.MjData(m)
    floor = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, "floor")
    chains = _foot_chains(scene)
    qadr, ft = scene.hinge_qposadr.reshape(-1), np.zeros(6)
    out = np.empty((len(angles), len(chains)))
    for t in range(len(angles)):
        d.qpos[:] = m.qpos0
        d.qpos[0:3], d.qpos[3:7], d.qpos[qadr] = root_pos[t], root_quat[t], angles[t]
        mujoco.mj_kinematics(m, d)
        for k, (geoms, _, _, _) in enumerate(chains):
            out[t, k] = min(mujoco.mj_geomDistance(m, d, g, floor, 1.0, ft) for g in geoms)
    return out


def test_lift_feet_clears_swinging_feet_and_unsinks_standing_ones(files) -> None:
    """A reference sunk 1 cm into the floor that stands for 12 frames, then glides at 0.6 m/s: lift_feet bends
    only the legs so that standing feet are on (not in) the floor and gliding ones 2 cm above it."""
    import numpy as np

    from wristmimic.env.grounding import _foot_chains, floor_clearance, lift_feet

    path, sid = files["smplx"]
    env = WristMimicEnv.from_file(path, sid, num_worlds=1, nthread=1)
    r, sc = env.ref, env.scene
    T = 30
    rq = np.repeat(r.root_quat[:1].double().numpy(), T, 0)
    ang = np.repeat(r.joint_angles[:1].double().numpy(), T, 0)
    legs = np.unique(np.concatenate([q for _, q, _, _ in _foot_chains(sc)]))
    cols = np.isin(sc.hinge_qposadr.reshape(-1), legs)
    ang[:, cols] = 0.0  # straight legs: both feet at one height
    rp = np.repeat(r.root_pos[:1].double().numpy(), T, 0)
    rp[:, 2] -= floor_clearance(sc, rp[:1], rq[:1], ang[:1]) + 0.01  # feet 1 cm into the floor
    rp[12:, 0] += 0.02 * np.arange(1, T - 11)  # 2 cm per frame at 30 fps from frame 12 on
    before = _foot_heights(sc, rp, rq, ang)
    assert len(_foot_chains(sc)) == 2 and before.max() < -0.009
    out, changed = lift_feet(sc, rp, rq, ang, 0.02, 30.0)
    after = _foot_heights(sc, rp, rq, out)
    assert changed == 2 * T
    assert (after[:8] > -1e-3).all() and (after[:8] < 0.005).all()  # standing: on the floor
    assert (after[16:] > 0.02 - 1e-3).all()  # swinging (the 7-frame ramp done): 2 cm clear
    assert np.array_equal(out[:, ~cols], ang[:, ~cols]) and not np.array_equal(out[:, cols], ang[:, cols])


def test_foot_clearance_reference_stays_consistent_and_must_match_the_config(files) -> None:
    from dataclasses import replace

    import mujoco
    import numpy as np

    path, sid = files["smplx"]
    cfg = replace(EnvConfig(), ground_reference=True, foot_clearance=0.02)
    env = WristMimicEnv.from_file(path, sid, num_worlds=1, config=cfg, nthread=1)
    assert env.ref.foot_clearance == 0.02
    m, d = env.scene.model, mujoco.MjData(env.scene.model)
    qadr = env.scene.hinge_qposadr.reshape(-1)
    for t in range(0, env.ref.num_frames, 7):  # bodies = forward kinematics of the (bent) joint angles
        d.qpos[0:3], d.qpos[3:7] = env.ref.root_pos[t].numpy(), env.ref.root_quat[t].numpy()
        d.qpos[qadr] = env.ref.joint_angles[t].numpy()
        mujoco.mj_kinematics(m, d)
        np.testing.assert_allclose(d.xpos[env.scene.body_ids], env.ref.body_pos[t].numpy(), atol=2e-3)
    plain = WristMimicEnv.from_file(path, sid, num_worlds=1, config=replace(cfg, foot_clearance=0.0), nthread=1)
    with pytest.raises(ValueError, match="foot_clearance"):
        WristMimicEnv(plain.scene, plain.ref, 1, cfg, nthread=1)
    with pytest.raises(ValueError, match="foot_clearance"):
        WristMimicEnv(plain.scene, plain.ref, 1, replace(cfg, foot_clearance=0.5), nthread=1)


def test_sub2_swing_toe_clears_the_floor_with_foot_clearance(omomo_h5: Path) -> None:
    """sub2's first backward step (frames 45-54) drags the right toe 0-7 mm above the floor; 2 cm with the lever."""
    from dataclasses import replace

    cfg = replace(EnvConfig(), ground_reference=True)
    ref = {}
    for c in (0.0, 0.02):
        env = WristMimicEnv.from_file(
            omomo_h5, "sub2_largetable_000", num_worlds=1, config=replace(cfg, foot_clearance=c), nthread=1
        )
        r = env.ref
        ref[c] = _foot_heights(
            env.scene, r.root_pos.double().numpy(), r.root_quat.double().numpy(), r.joint_angles.double().numpy()
        )
    right = 1  # chains are (left, right)
    assert ref[0.0][45:55, right].min() < 0.008
    assert ref[0.02][47:53, right].min() > 0.019 and ref[0.02][:, right].min() > -1e-3


def test_object_frame_wrist_targets_ride_with_the_simulated_object_only_for_touching_hands(files) -> None:
    """``wrist_frame=object``: a hand the reference shows touching the object gets its reference wrist pose carried
    by the simulated object (rigidly: translation and rotation), the other hand the world reference; the wrist reset
    and the wrist factors read these targets, so a wrist that moves with a displaced object stays inside them."""
    from dataclasses import replace

    from wristmimic.env.terminations import WRIST
    from wristmimic.env.torch_math import quat_angle, quat_mul, quat_rotate

    path, sid = files["smplx"]
    cfg = variant_config("wristmimic", wrist_frame="object")
    env = WristMimicEnv.from_file(path, sid, num_worlds=2, config=cfg, seed=0, nthread=1)
    f = env.ref.num_frames // 2
    env.reset(start_frames=torch.tensor([f, f]))
    s, rf = env.sim_state(), env.ref_frame(env.frame)
    rf = replace(rf, hand=torch.ones_like(rf.hand))  # both hands touching in both worlds
    w = env.sets.wrists
    pos, quat = env.wrist_targets(s, rf)
    torch.testing.assert_close(pos, rf.body_pos[:, w], atol=2e-5, rtol=0)  # object on its reference: no change
    assert quat_angle(quat, rf.body_quat[:, w]).max() < 1e-3
    # world 1: the simulated box 10 cm off and turned 0.4 rad about z; world 0's reference hand not touching
    turn = torch.tensor([np.cos(0.2), 0.0, 0.0, np.sin(0.2)], dtype=torch.float32)
    moved = replace(
        s,
        obj_pos=s.obj_pos + torch.tensor([[[0.0, 0.0, 0.0]], [[0.1, -0.05, 0.02]]]),
        obj_quat=torch.stack([s.obj_quat[0], quat_mul(turn.expand_as(s.obj_quat[1]), s.obj_quat[1])]),
    )
    rf0 = replace(rf, hand=torch.tensor([[False, False], [True, True]]))
    pos, quat = env.wrist_targets(moved, rf0)
    torch.testing.assert_close(pos[0], rf.body_pos[0, w], rtol=0, atol=0)  # not touching: the world reference
    rel = rf.body_pos[1, w] - rf.obj_pos[1, :1]
    want = quat_rotate(turn.expand(2, 4), rel) + moved.obj_pos[1, :1]
    torch.testing.assert_close(pos[1], want, atol=1e-5, rtol=0)
    assert torch.allclose(quat_angle(quat[1], rf.body_quat[1, w]), torch.tensor(0.4), atol=1e-4)
    # the wrist reset reads them: wrists carried with the object stay inside its thresholds
    body_pos = moved.body_pos.index_copy(1, w, pos)
    body_quat = moved.body_quat.index_copy(1, w, quat)
    carried = replace(moved, body_pos=body_pos, body_quat=body_quat)
    env._grasp = torch.ones_like(env._grasp)
    env.steps = torch.full_like(env.steps, 5)
    phase = torch.full((2,), W.GRASP, dtype=torch.long)
    _, reason = env._terminations(carried, rf0, rf0.hand, phase)
    assert (reason != WRIST).all()
    world = WristMimicEnv.from_file(path, sid, num_worlds=2, config=variant_config("wristmimic"), seed=0, nthread=1)
    world.reset(start_frames=torch.tensor([f, f]))
    world._grasp, world.steps = env._grasp.clone(), env.steps.clone()
    _, reason = world._terminations(carried, rf0, rf0.hand, phase)
    assert reason[1] == WRIST and reason[0] != WRIST  # the world rule resets the carried wrists
    _, terms = env._reward(carried, rf0, rf0.hand, phase)
    _, world_terms = world._reward(carried, rf0, rf0.hand, phase)
    assert terms["error/wrist_pos"][1] < 1e-8 < 1e-3 < world_terms["error/wrist_pos"][1]  # the factors read them too
    with pytest.raises(ValueError, match="wrist_frame"):
        WristMimicEnv.from_file(path, sid, num_worlds=1, config=variant_config("wristmimic", wrist_frame="hand"))
