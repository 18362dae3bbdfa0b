"""The training-only curricula: the virtual object controller's wrench, its gain schedule down to exactly zero, its
log column, and evaluation that never applies it; the same for the root assist and the hands' adhesion."""

from __future__ import annotations

import csv
import json
import math
from dataclasses import replace
from pathlib import Path

import mujoco
import numpy as np
import pytest
import torch

from wristmimic.env.config import (
    HandAdhesionConfig,
    ObjectControllerConfig,
    RootAssistConfig,
    check_env_config,
    variant_config,
)
from wristmimic.env.vec_env import WristMimicEnv
from wristmimic.evaluate.policy import load_eval_policy
from wristmimic.evaluate.trials import make_env
from wristmimic.rl import TrainSpec, preset, start_run
from wristmimic.rl.checkpoint import load_checkpoint
from wristmimic.rl.curriculum import ObjectCurriculum, hand_adhesion_gain, root_assist_gain
from wristmimic.scene import SceneConfig

from synthetic import converted_intermimic

SID = "sub1_box_000"


@pytest.fixture(scope="module")
def dataset(tmp_path_factory: pytest.TempPathFactory) -> Path:
    tmp = tmp_path_factory.mktemp("curriculum")
    return converted_intermimic(tmp, 40)


def _train_rows(dataset: Path, run: Path, oc: ObjectControllerConfig, num_envs: int, max_frames: int) -> list[dict]:
    """metrics.csv rows of a tiny CPU-recipe run with object controller ``oc``."""
    env_cfg = variant_config("wristmimic", object_controller=oc)
    ppo = preset(
        "cpu", num_envs=num_envs, horizon=8, minibatch_size=16, epochs=1, actor_hidden=(16,), critic_hidden=(16,)
    )
    spec = TrainSpec(dataset, SID, "wristmimic", 0, "cpu", replace(ppo, max_frames=max_frames), env=env_cfg)
    start_run(spec, run, progress=False)
    with open(run / "metrics.csv", newline="") as f:
        return list(csv.DictReader(f))


def _object_error_after(dataset: Path, gain: float, steps: int = 25) -> float:
    """Mean object position error after ``steps`` steps from frame 0 with zero actions (humanoid tracking)."""
    cfg = variant_config("wristmimic", wrist_resets=False)
    cfg = replace(cfg, termination=replace(cfg.termination, body_error=9.0, object_error=9.0, contact_lost_frames=999))
    env = WristMimicEnv.from_file(dataset, SID, 2, cfg, SceneConfig(object_actuators=True), seed=0)
    env.object_gain = gain
    env.reset(start_frames=torch.zeros(2, dtype=torch.long))
    err = 0.0
    for _ in range(steps):
        *_, info = env.step(torch.zeros(2, env.action_size))
        err = float(info["eval"]["obj_pos"].mean())
    return err


def test_the_object_controller_carries_the_object_along_its_reference(dataset: Path) -> None:
    held, free = _object_error_after(dataset, 1.0), _object_error_after(dataset, 0.0)
    assert held < 0.05 and free > 10 * held, (held, free)  # with no hand carrying it the object falls behind


def test_a_positive_gain_needs_the_controller_motors(dataset: Path) -> None:
    env = WristMimicEnv.from_file(dataset, SID, 1, variant_config("wristmimic"), seed=0)
    assert not env.has_object_controller and env.scene.model.nu == env.action_size
    env.reset()
    env.object_gain = 0.5
    with pytest.raises(RuntimeError, match="object_actuators"):
        env.step(torch.zeros(1, env.action_size))


def test_gain_decays_on_survival_and_reaches_exactly_zero_by_the_frame_cap() -> None:
    cfg = ObjectControllerConfig(decay=0.5, survival=0.5, min_gain=0.1, zero_by_frames=500)
    cur = ObjectCurriculum(cfg, num_frames=101)
    assert cur.gain == 1.0
    assert cur.update(terminations=50, world_steps=100, frames=10) == pytest.approx(0.98)  # cap only
    assert cur.update(terminations=0, world_steps=100, frames=20) == pytest.approx(0.5)  # decay
    assert cur.update(terminations=0, world_steps=100, frames=30) == pytest.approx(0.25)
    assert cur.zero_frames is None
    assert cur.update(terminations=0, world_steps=100, frames=40) == pytest.approx(0.125)
    assert cur.update(terminations=0, world_steps=100, frames=50) == 0.0  # 0.0625 < min_gain
    assert cur.zero_frames == 50
    assert cur.update(terminations=100, world_steps=100, frames=60) == 0.0  # zero stays zero
    late = ObjectCurriculum(cfg, 101)
    for frames in range(100, 501, 100):  # never survives: the cap alone takes it to zero by zero_by_frames
        g = late.update(terminations=100, world_steps=100, frames=frames)
    assert g == 0.0 and late.zero_frames is not None and late.zero_frames <= 500
    assert ObjectCurriculum(replace(cfg, enabled=False), 101).gain == 0.0


def test_recover_dials_the_gain_back_when_episodes_stay_short_and_zero_stays_zero() -> None:
    """recover: survival below it divides the gain by decay (up to initial_gain, under the frame cap); between
    recover and survival the gain holds; off (0) the gain only falls, as before; bad thresholds are refused."""
    cfg = ObjectControllerConfig(decay=0.5, survival=0.5, recover=0.2, min_gain=0.1, zero_by_frames=10_000)
    cur = ObjectCurriculum(cfg, num_frames=101)
    survive, short = dict(terminations=0, world_steps=100), dict(terminations=100, world_steps=100)
    assert cur.update(**survive, frames=0) == pytest.approx(0.5)
    assert cur.update(**survive, frames=0) == pytest.approx(0.25)
    assert cur.update(**short, frames=0) == pytest.approx(0.5)  # dialled back
    assert cur.update(**short, frames=0) == pytest.approx(1.0)
    assert cur.update(**short, frames=0) == pytest.approx(1.0)  # never above initial_gain
    assert cur.update(**short, frames=5_000) == pytest.approx(0.5)  # nor above the frame cap
    middle = dict(terminations=1, world_steps=100)  # survival 0.99^100 = 0.37: between recover and survival
    assert 0.2 < cur.projected_survival(**middle) < 0.5
    assert cur.update(**middle, frames=5_000) == pytest.approx(0.5)  # holds
    for _ in range(4):  # 0.5 (its adaptive 1.0 held by the cap) -> 0.5, 0.25, 0.125, 0.0625 < min_gain
        cur.update(**survive, frames=5_000)
    assert cur.gain == 0.0 and cur.zero_frames == 5_000
    assert cur.update(**short, frames=5_000) == 0.0  # zero stays zero
    off = ObjectCurriculum(replace(cfg, recover=0.0), 101)
    off.update(**survive, frames=0)
    assert off.update(**short, frames=0) == pytest.approx(0.5)  # without recover the gain never rises
    for bad in (dict(recover=0.5), dict(recover=-0.1), dict(decay=0.0), dict(decay=1.5)):
        with pytest.raises(ValueError, match="recover|decay"):
            check_env_config(variant_config("wristmimic", object_controller=ObjectControllerConfig(**bad)))


def test_completion_gate_counts_episodes_that_reach_the_end_and_training_feeds_it(
    dataset: Path, tmp_path: Path
) -> None:
    """gate=completion: the statistic is the share of ended episodes that were not terminated (an iteration
    without an ended episode moves nothing); the runner feeds each iteration's episodes and terminations, so the
    logged gains are exactly a replay of the curriculum over metrics.csv's columns."""
    cfg = ObjectControllerConfig(decay=0.5, survival=0.5, recover=0.2, gate="completion", zero_by_frames=10**6)
    cur = ObjectCurriculum(cfg, num_frames=101)
    assert cur.update(terminations=0, world_steps=100, frames=0, episodes=0) == 1.0  # nothing ended: no move
    assert cur.update(terminations=1, world_steps=100, frames=0, episodes=4) == pytest.approx(0.5)  # 3/4 completed
    assert cur.update(terminations=3, world_steps=100, frames=0, episodes=10) == pytest.approx(0.25)  # 0.7
    assert cur.update(terminations=6, world_steps=100, frames=0, episodes=10) == pytest.approx(0.25)  # 0.4: holds
    assert cur.update(terminations=9, world_steps=100, frames=0, episodes=10) == pytest.approx(0.5)  # 0.1: back
    with pytest.raises(ValueError, match="gate"):
        check_env_config(variant_config("wristmimic", object_controller=ObjectControllerConfig(gate="length")))
    oc = ObjectControllerConfig(decay=0.7, survival=0.3, recover=0.1, gate="completion", zero_by_frames=10**6)
    rows = _train_rows(dataset, tmp_path / "run", oc, 8, 64 * 12)
    replay = ObjectCurriculum(oc, num_frames=40)
    for row in rows:
        assert float(row["curriculum/object_gain"]) == pytest.approx(replay.gain, abs=0, rel=1e-12)
        terms = sum(int(v) for k, v in row.items() if k.startswith("termination/"))
        replay.update(terms, 64, int(row["frames"]), episodes=int(row["episodes"]))
    gains = {float(r["curriculum/object_gain"]) for r in rows}
    assert len(gains) > 1  # the gate moved the gain in this run


def test_training_logs_the_gain_records_when_it_reached_zero_and_evaluation_never_applies_it(
    dataset: Path, tmp_path: Path
) -> None:
    oc = ObjectControllerConfig(zero_by_frames=32 * 3)
    gains = [float(r["curriculum/object_gain"]) for r in _train_rows(dataset, tmp_path / "run", oc, 4, 32 * 6)]
    assert gains[0] == 1.0 and gains[-1] == 0.0 and gains == sorted(gains, reverse=True)
    meta = load_checkpoint(tmp_path / "run")["metadata"]
    assert meta["object_gain"] == 0.0 and 0 < meta["object_gain_zero_frames"] <= 32 * 3
    config = json.loads((tmp_path / "run" / "config.json").read_text())
    assert config["env"]["object_controller"]["enabled"] and not config["scene_config"]["object_actuators"]
    env = make_env(load_eval_policy(tmp_path / "run").metadata, 2)
    assert not env.has_object_controller and env.object_gain == 0.0


def test_weight_ramp_keeps_the_weight_after_the_pose_gain_is_gone() -> None:
    cfg = ObjectControllerConfig(zero_by_frames=100, weight_zero_by_frames=400, min_gain=0.05)
    cur = ObjectCurriculum(cfg, num_frames=101)
    assert cur.weight_gain(0) == 1.0
    cur.update(terminations=100, world_steps=100, frames=100)
    assert cur.gain == 0.0 and cur.weight_gain(100) == pytest.approx(0.75)
    assert cur.weight_gain(390) == 0.0 and cur.weight_gain(400) == 0.0  # below min_gain, then the ramp's end
    same = ObjectCurriculum(replace(cfg, weight_zero_by_frames=0), 101)
    same.update(terminations=100, world_steps=100, frames=50)
    assert same.weight_gain(50) == same.gain == pytest.approx(0.5)  # 0: the weight follows the pose gain


def test_weight_support_alone_is_exactly_the_objects_weight(dataset: Path) -> None:
    """Pose gain 0, weight gain 1: the wrench is m g upward and nothing else; with no weight gain, nothing."""
    env = WristMimicEnv.from_file(dataset, SID, 1, variant_config("wristmimic"), SceneConfig(object_actuators=True))
    env.reset(start_frames=torch.full((1,), 5, dtype=torch.long))
    mg = float(env._obj_mass[0, 0]) * 9.81
    env.object_gain, env.object_weight_gain = 0.0, 1.0
    w = env.object_wrench()[0, 0]
    assert w[2] == pytest.approx(mg, rel=1e-3) and torch.all(w[[0, 1, 3, 4, 5]] == 0)
    env.object_gain, env.object_weight_gain = 0.5, 0.0
    pose_only = env.object_wrench()[0, 0]
    env.object_weight_gain = None  # the weight follows the pose gain
    assert env.object_wrench()[0, 0][2] == pytest.approx(float(pose_only[2]) + 0.5 * mg, rel=1e-4, abs=1e-4)


def test_training_logs_the_weight_ramp_and_evaluation_never_applies_it(dataset: Path, tmp_path: Path) -> None:
    oc = ObjectControllerConfig(zero_by_frames=32, weight_zero_by_frames=32 * 5)
    rows = _train_rows(dataset, tmp_path / "run", oc, 4, 32 * 4)
    pose = [float(r["curriculum/object_gain"]) for r in rows]
    weight = [float(r["curriculum/object_weight_gain"]) for r in rows]
    assert pose == [1.0, 0.0, 0.0, 0.0] and weight == pytest.approx([1.0, 0.8, 0.6, 0.4])
    env = make_env(load_eval_policy(tmp_path / "run").metadata, 2)
    assert not env.has_object_controller and env.object_gain == 0.0 and not env.object_weight_gain


def test_start_hold_holds_only_mid_clip_starts_and_only_for_its_frames(dataset: Path) -> None:
    """Start hold: the controller's full wrench on a world reset at a frame > 0, fading to none over
    start_hold_frames; nothing on frame-0 starts, with the curriculum's gain at zero."""
    cfg = variant_config("wristmimic", wrist_resets=False)  # no episode ends during the test
    cfg = replace(cfg, termination=replace(cfg.termination, body_error=9.0, object_error=9.0, contact_lost_frames=999))
    env = WristMimicEnv.from_file(dataset, SID, 2, cfg, SceneConfig(object_actuators=True))
    env.reset(start_frames=torch.tensor([0, 10]))
    env.object_gain = 1.0
    full = env.object_wrench()  # the wrench at gain 1 in this state
    env.object_gain, env.object_start_hold = 0.0, 4
    voc = env._voc_cols.flatten()
    ctrl = env.prepare_step(torch.zeros(2, env.action_size))[:, voc].reshape(full.shape)
    assert torch.all(ctrl[0] == 0) and torch.allclose(ctrl[1], full[1]) and ctrl[1].abs().max() > 0
    gains = []
    for _ in range(6):
        gains.append(env.start_hold_gain().tolist())
        env.step(torch.zeros(2, env.action_size))
    assert gains == [[0.0, g] for g in (1.0, 0.75, 0.5, 0.25, 0.0, 0.0)]
    assert torch.all(env.prepare_step(torch.zeros(2, env.action_size))[:, voc] == 0)
    env.object_gain = 0.5  # the larger of the two gains
    env.reset(start_frames=torch.tensor([0, 10]))
    hold = env.start_hold_gain()
    assert hold.tolist() == [0.0, 1.0] and torch.allclose(env.object_wrench(hold)[1], full[1], atol=1e-5)
    for bad in (dict(start_hold_frames=-1), dict(enabled=False, start_hold_frames=5)):
        with pytest.raises(ValueError, match="start_hold_frames"):
            check_env_config(variant_config("wristmimic", object_controller=ObjectControllerConfig(**bad)))


def test_spread_gives_each_episode_its_own_share_of_the_gain_and_survives_a_resume(dataset: Path) -> None:
    """spread: every world's wrench is the full-gain wrench times its episode's u in [1 - spread, 1], drawn anew
    at its reset, carried by state_dict; spread 0 draws nothing, so other runs keep their random streams."""
    cfg = variant_config("wristmimic", object_controller=ObjectControllerConfig(spread=1.0))
    env = WristMimicEnv.from_file(dataset, SID, 8, cfg, SceneConfig(object_actuators=True), seed=3)
    env.reset(start_frames=torch.full((8,), 5, dtype=torch.long))
    u = env.object_scale.clone()
    assert torch.all((u >= 0.0) & (u <= 1.0)) and u.unique().numel() == 8
    env.object_gain = 0.5
    scaled = env.object_wrench()
    env.object_scale = torch.ones(8)
    full = env.object_wrench()
    assert torch.allclose(scaled, full * u[:, None, None], atol=1e-5) and full.abs().max() > 0
    env.object_scale = u.clone()
    hold = torch.tensor([1.0] + [0.0] * 7)  # a start hold still raises its world to the hold's gain
    assert torch.allclose(env.object_wrench(hold)[0], full[0] / 0.5, atol=1e-4)
    state = env.state_dict()
    env.reset(start_frames=torch.full((8,), 5, dtype=torch.long))
    assert not torch.equal(env.object_scale, u)  # a reset draws new shares
    env.load_state_dict(state)
    assert torch.equal(env.object_scale, u)
    off = WristMimicEnv.from_file(
        dataset, SID, 8, variant_config("wristmimic"), SceneConfig(object_actuators=True), seed=3
    )
    g = off._gen.get_state()
    off.reset(start_frames=torch.full((8,), 5, dtype=torch.long))
    assert torch.equal(off._gen.get_state(), g) and torch.all(off.object_scale == 1.0)
    for bad in (-0.1, 1.5):
        with pytest.raises(ValueError, match="spread"):
            check_env_config(variant_config("wristmimic", object_controller=ObjectControllerConfig(spread=bad)))


def test_training_records_the_start_hold_and_evaluation_never_applies_it(dataset: Path, tmp_path: Path) -> None:
    env_cfg = variant_config("wristmimic", object_controller=ObjectControllerConfig(start_hold_frames=6))
    ppo = preset("cpu", num_envs=4, horizon=8, minibatch_size=16, epochs=1, actor_hidden=(16,), critic_hidden=(16,))
    spec = TrainSpec(dataset, SID, "wristmimic", 0, "cpu", replace(ppo, max_frames=32 * 2), env=env_cfg)
    start_run(spec, tmp_path / "run", progress=False)
    meta = load_eval_policy(tmp_path / "run").metadata
    assert meta["env"]["object_controller"]["start_hold_frames"] == 6
    env = make_env(meta, 2)
    assert not env.has_object_controller and env.object_start_hold == 0 and env.start_hold_gain() is None


def test_training_with_a_state_bank_logs_its_share_and_records_it(dataset: Path, tmp_path: Path) -> None:
    base = variant_config("wristmimic")
    env_cfg = replace(base, reset_frame0_prob=0.5, starts=replace(base.starts, bank=1.0, bank_size=4))
    ppo = preset("cpu", num_envs=4, horizon=8, minibatch_size=16, epochs=1, actor_hidden=(16,), critic_hidden=(16,))
    spec = TrainSpec(dataset, SID, "wristmimic", 0, "cpu", replace(ppo, max_frames=32 * 4), env=env_cfg)
    start_run(spec, tmp_path / "run", progress=False)
    with open(tmp_path / "run" / "metrics.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    shares = [float(r["starts/banked"]) for r in rows]
    assert len(shares) == 4 and all(math.isnan(s) or 0.0 <= s <= 1.0 for s in shares)
    meta = load_eval_policy(tmp_path / "run").metadata
    assert meta["env"]["starts"]["bank"] == 1.0  # recorded in the run ...
    assert make_env(meta, 2).bank is None  # ... and never used by evaluation


def _root_error_after(dataset: Path, gain: float, steps: int = 25) -> float:
    """Largest root position error over ``steps`` zero-action steps from frame 0 (no terminations)."""
    cfg = variant_config("wristmimic", wrist_resets=False, root_assist=RootAssistConfig(enabled=True))
    cfg = replace(cfg, termination=replace(cfg.termination, body_error=9.0, object_error=9.0, contact_lost_frames=999))
    env = WristMimicEnv.from_file(dataset, SID, 1, cfg, SceneConfig(root_actuators=True), seed=0)
    assert env.has_root_assist and env.scene.model.nu == env.action_size + 6
    env.root_gain = gain
    env.reset(start_frames=torch.zeros(1, dtype=torch.long))
    worst = 0.0
    for _ in range(steps):
        env.step(torch.zeros(1, env.action_size))
        s, rf = env.sim_state(), env.ref_frame(env.frame)
        worst = max(worst, float((s.body_pos[0, 0] - rf.body_pos[0, 0]).norm()))
    return worst


def test_the_root_assist_holds_the_root_on_its_reference(dataset: Path) -> None:
    held, free = _root_error_after(dataset, 1.0), _root_error_after(dataset, 0.0)
    assert held < 0.25 * free, (held, free)  # measured: 5.1 cm against 25.8 cm


AIDS = [  # (EnvConfig field, its config, log column, training-scene flag, env attributes: has, gain)
    ("root_assist", RootAssistConfig, "root_gain", "root_actuators", ("has_root_assist", "root_gain")),
    ("hand_adhesion", HandAdhesionConfig, "adhesion_gain", "hand_adhesion", ("has_hand_adhesion", "adhesion_gain")),
]
GAINS = {"root_assist": root_assist_gain, "hand_adhesion": hand_adhesion_gain}


@pytest.mark.parametrize(("field", "config_cls", "column", "scene_flag", "attrs"), AIDS, ids=[a[0] for a in AIDS])
def test_a_ramped_aid_falls_linearly_to_exactly_zero_and_needs_its_actuators(
    dataset: Path, field: str, config_cls: type, column: str, scene_flag: str, attrs: tuple[str, str]
) -> None:
    cfg = config_cls(enabled=True, zero_by_frames=1000, min_gain=0.05)
    gain = GAINS[field]
    assert [gain(cfg, f) for f in (0, 500, 940, 960, 5000)] == pytest.approx([1.0, 0.5, 0.06, 0, 0])
    assert gain(replace(cfg, enabled=False), 0) == 0.0
    env = WristMimicEnv.from_file(dataset, SID, 1, variant_config("wristmimic"), seed=0)
    assert not getattr(env, attrs[0])
    env.reset()
    setattr(env, attrs[1], 0.5)
    with pytest.raises(RuntimeError, match=scene_flag):
        env.step(torch.zeros(1, env.action_size))


@pytest.mark.parametrize(("field", "config_cls", "column", "scene_flag", "attrs"), AIDS, ids=[a[0] for a in AIDS])
def test_training_logs_a_ramped_aid_and_evaluation_never_applies_it(
    dataset: Path, tmp_path: Path, field: str, config_cls: type, column: str, scene_flag: str, attrs: tuple[str, str]
) -> None:
    env_cfg = variant_config("wristmimic", **{field: config_cls(enabled=True, zero_by_frames=32 * 4)})
    ppo = preset("cpu", num_envs=4, horizon=8, minibatch_size=16, epochs=1, actor_hidden=(16,), critic_hidden=(16,))
    spec = TrainSpec(dataset, SID, "wristmimic", 0, "cpu", replace(ppo, max_frames=32 * 5), env=env_cfg)
    start_run(spec, tmp_path / "run", progress=False)
    with open(tmp_path / "run" / "metrics.csv", newline="") as f:
        gains = [float(r[f"curriculum/{column}"]) for r in csv.DictReader(f)]
    assert gains == pytest.approx([1.0, 0.75, 0.5, 0.25, 0.0])  # the gain each iteration collected with
    config = json.loads((tmp_path / "run" / "config.json").read_text())
    assert config["env"][field]["enabled"] and not config["scene_config"][scene_flag]
    env = make_env(load_eval_policy(tmp_path / "run").metadata, 2)
    assert not getattr(env, attrs[0]) and getattr(env, attrs[1]) == 0.0 and not getattr(env.cfg, field).enabled


def _adhesion_env(dataset: Path, n: int = 2) -> WristMimicEnv:
    cfg = variant_config("wristmimic", wrist_resets=False, hand_adhesion=HandAdhesionConfig(enabled=True, force=15.0))
    cfg = replace(cfg, termination=replace(cfg.termination, body_error=9.0, object_error=9.0, contact_lost_frames=999))
    return WristMimicEnv.from_file(dataset, SID, n, cfg, SceneConfig(hand_adhesion=True), seed=0)


def test_hand_adhesion_pulls_each_hand_body_only_while_its_reference_hand_touches(dataset: Path) -> None:
    env = _adhesion_env(dataset)
    m = env.scene.model
    hand_bodies = {int(env.scene.body_ids[b]) for k in ("left_hand", "right_hand") for b in env.scene.humanoid.roles[k]}
    assert env.has_hand_adhesion and {int(m.actuator_trnid[i, 0]) for i in env._adh_cols.tolist()} == hand_bodies
    assert env.scene.model.nu == env.action_size + len(hand_bodies)
    env.ref.hand[6] = torch.tensor([False, True])  # the clip's left hand touches throughout: swap one frame
    touch = env.ref.hand.numpy()
    env.adhesion_gain = 0.5
    env.reset(start_frames=torch.tensor([4, 5]))  # stepping to frames 5 (left touches) and 6 (right only)
    ctrl = env.prepare_step(torch.zeros(2, env.action_size))[:, env._adh_cols]
    side = env._adh_side.numpy()
    assert touch[5].tolist() == [True, False] and set(side.tolist()) == {0, 1}
    expected = 15.0 * 0.5 * torch.tensor(touch[[5, 6]][:, side], dtype=torch.float32)
    assert torch.equal(ctrl, expected) and set(ctrl.flatten().tolist()) == {0.0, 7.5}
    env.adhesion_gain = 0.0  # a finished ramp leaves no pull behind
    assert env.prepare_step(torch.zeros(2, env.action_size))[:, env._adh_cols].abs().sum() == 0
    with pytest.raises(ValueError, match="hand_adhesion"):
        check_env_config(variant_config("wristmimic", hand_adhesion=HandAdhesionConfig(enabled=True, force=-1.0)))


def test_hand_adhesion_acts_through_contact_on_the_object(dataset: Path) -> None:
    """With the hands touching the box, the adhesion actuators put a force on the box's free joint; without it none."""
    env = _adhesion_env(dataset, 1)
    f0 = int(env.ref.hand.numpy().all(-1).argmax())
    env.adhesion_gain = 1.0
    env.reset(start_frames=torch.tensor([f0]))
    m, d = env.scene.model, mujoco.MjData(env.scene.model)
    dof = env.scene.dynamic_objects[0].dofadr + np.arange(6)
    pulls = []
    for _ in range(6):
        env.step(torch.zeros(1, env.action_size))
        d.qpos[:], d.qvel[:] = env.backend.qpos[0].numpy(), env.backend.qvel[0].numpy()
        d.ctrl[:] = env._ctrl[0].double().numpy()
        mujoco.mj_forward(m, d)
        hand = env._sim_hand(env.sim_state())[0]
        pulls.append((bool(hand.any()), float(np.abs(d.qfrc_actuator[dof]).sum())))
        d.ctrl[env._adh_cols.numpy()] = 0.0
        mujoco.mj_forward(m, d)
        assert np.abs(d.qfrc_actuator[dof]).sum() == 0.0  # only the adhesion acts on the box
    assert any(touching and pull > 1.0 for touching, pull in pulls), pulls


def test_horizontal_share_scales_only_the_controllers_sideways_force_while_the_object_moves(dataset: Path) -> None:
    """``horizontal=0`` keeps the vertical force, the weight and the torque of the full controller and drops its
    world x, y force while the reference object moves; 0.5 halves it; at rest the full controller holds."""
    variant = variant_config("wristmimic")

    def wrench(horizontal: float, still: bool = False) -> torch.Tensor:
        cfg = replace(variant, object_controller=replace(variant.object_controller, horizontal=horizontal))
        env = WristMimicEnv.from_file(dataset, SID, 1, cfg, SceneConfig(object_actuators=True))
        assert float(env.ref.obj_linvel[6, 0].norm()) > 0.2  # the synthetic reference moves its box throughout
        if still:
            env.ref.obj_linvel[6] = 0.0  # the reference at rest at the frame aimed at
        env.reset(start_frames=torch.full((1,), 5, dtype=torch.long))  # the wrench aims at frame 5 + 1
        env.backend.qpos[:, env._obj_pos_q] += torch.tensor([0.03, -0.02, 0.01], dtype=env.backend.qpos.dtype)
        env.object_gain = 1.0
        return env.object_wrench()[0, 0]

    full, none, half = wrench(1.0), wrench(0.0), wrench(0.5)
    assert abs(float(full[0])) > 1.0 and abs(float(full[1])) > 1.0  # the offset makes a sideways pull
    assert torch.all(none[:2] == 0) and torch.equal(none[2:], full[2:])
    assert torch.allclose(half[:2], full[:2] / 2, rtol=1e-5) and torch.equal(half[2:], full[2:])
    at_rest = wrench(1.0, still=True)
    assert abs(float(at_rest[0])) > 1.0 and torch.equal(wrench(0.0, still=True), at_rest)
    with pytest.raises(ValueError, match="horizontal"):
        check_env_config(replace(variant, object_controller=replace(variant.object_controller, horizontal=1.5)))
