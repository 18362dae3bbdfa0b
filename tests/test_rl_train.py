"""Training runs on a synthetic scene: run folder contents, determinism, bit-for-bit resume, Ctrl-C, policy
loading, the ``wristmimic train`` command and the learning-curve script."""

from __future__ import annotations

import csv
import json
import math
import os
import runpy
import signal
from pathlib import Path

import numpy as np
import pytest
import torch
from typer.testing import CliRunner

import wristmimic
from wristmimic.cli.main import app
from wristmimic.convert.common import ConvertOptions
from wristmimic.convert.intermimic import convert_intermimic
from wristmimic.env.config import variant_config
from wristmimic.env.terminations import REASONS
from wristmimic.env.vec_env import WristMimicEnv
from wristmimic.errors import InputError
from wristmimic.rl import TrainSpec, load_policy, preset, resume_run, start_run
from wristmimic.rl.checkpoint import load_checkpoint
from wristmimic.rl.config import preset_env
from wristmimic.rl.logger import TIME_COLUMNS
from wristmimic.rl.runner import Runner
from wristmimic.safe_io import sha256_file
from wristmimic.scene import SceneConfig

from synthetic import write_intermimic_folder

SID = "sub1_box_000"
TINY = dict(num_envs=4, horizon=8, minibatch_size=16, epochs=2, actor_hidden=(32,), critic_hidden=(32,))


@pytest.fixture(scope="module")
def dataset(tmp_path_factory: pytest.TempPathFactory) -> Path:
    tmp = tmp_path_factory.mktemp("rl")
    out = tmp / "im.h5"
    opts = ConvertOptions(hull_cache_dir=tmp / "c", show_progress=False)
    convert_intermimic(write_intermimic_folder(tmp / "im", T=40), out, options=opts)
    return out


def _spec(dataset: Path, iterations: int, seed: int = 0, **kw) -> TrainSpec:
    ppo = preset("cpu", **{**TINY, **kw}, max_frames=4 * 8 * iterations, checkpoint_every=2)
    return TrainSpec(dataset, SID, "wristmimic", seed, "cpu", ppo)


def _rows(run_dir: Path) -> list[dict[str, str]]:
    with open(run_dir / "metrics.csv", newline="") as f:
        return [{k: v for k, v in r.items() if k not in TIME_COLUMNS} for r in csv.DictReader(f)]


def _params(run_dir: Path) -> dict[str, torch.Tensor]:
    return load_checkpoint(run_dir)["policy"]


def _same_params(a: dict[str, torch.Tensor], b: dict[str, torch.Tensor]) -> bool:
    return a.keys() == b.keys() and all(torch.equal(a[k], b[k]) for k in a)


def test_run_folder_holds_config_metrics_and_a_safe_checkpoint(dataset: Path, tmp_path: Path) -> None:
    r = start_run(_spec(dataset, 3), tmp_path / "run", nthread=1, progress=False)
    assert (r.status, r.iteration, r.frames) == ("finished", 3, 96)
    cfg = json.loads((tmp_path / "run" / "config.json").read_text())
    assert cfg["dataset"]["sha256"] == sha256_file(dataset) and cfg["seed"] == 0 and cfg["scene"] == SID
    assert cfg["code"]["version"] == wristmimic.__version__ and "git_commit" in cfg["code"]
    assert cfg["ppo"]["num_envs"] == 4 and cfg["env"]["variant"] == "wristmimic" and "timestep" in cfg["scene_config"]
    rows = _rows(tmp_path / "run")
    assert [int(x["iteration"]) for x in rows] == [1, 2, 3] and rows[-1]["frames"] == "96"
    for col in ("reward_mean", "episode_length_mean", "success_rate", "reward/body_pos", "termination/fall"):
        assert col in rows[0]
    assert {"loss/policy", "loss/value", "loss/bounds"} <= set(rows[0])
    state = torch.load(tmp_path / "run" / "checkpoint.pt", weights_only=True, map_location="cpu")
    assert state["iteration"] == 3 and state["storage_step"] == 0
    assert not list((tmp_path / "run").glob("*.tmp"))


def test_same_seed_gives_identical_metrics_and_parameters(dataset: Path, tmp_path: Path) -> None:
    for name, seed in (("a", 0), ("b", 0), ("c", 1)):
        start_run(_spec(dataset, 2, seed), tmp_path / name, nthread=2, progress=False)
    assert _rows(tmp_path / "a") == _rows(tmp_path / "b")
    assert _same_params(_params(tmp_path / "a"), _params(tmp_path / "b"))
    assert not _same_params(_params(tmp_path / "a"), _params(tmp_path / "c"))
    assert _rows(tmp_path / "a") != _rows(tmp_path / "c")


def test_policy_steps_on_one_torch_thread_and_the_update_on_the_physics_threads(
    dataset: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    from wristmimic.rl.networks import ActorCritic
    from wristmimic.rl.ppo import PPO

    seen: dict[str, set[int]] = {"act": set(), "update": set()}

    def spy(name: str, fn):  # type: ignore[no-untyped-def]
        def wrapped(*a, **kw):  # type: ignore[no-untyped-def]
            seen[name].add(torch.get_num_threads())
            return fn(*a, **kw)

        return wrapped

    monkeypatch.setattr(ActorCritic, "act", spy("act", ActorCritic.act))
    monkeypatch.setattr(PPO, "update", spy("update", PPO.update))
    before = torch.get_num_threads()
    torch.set_num_threads(3)
    try:
        start_run(_spec(dataset, 2), tmp_path / "r", nthread=2, progress=False)
        assert torch.get_num_threads() == 3  # the caller's count is restored
    finally:
        torch.set_num_threads(before)
    assert seen == {"act": {1}, "update": {2}}


def test_the_first_rollout_does_not_depend_on_the_thread_counts(dataset: Path, tmp_path: Path) -> None:
    """Physics threads (--nthread) and the process's torch threads (OMP_NUM_THREADS) leave the initial networks and
    the first rollout bit-identical: the orthogonal initialisation of the recipe's widths differed in its last bits
    between 1 and 2 torch threads before it ran on one. The update runs on the physics threads, and its float
    reductions may differ in the last bits between thread counts on some CPUs (measured on an Intel Xeon, 2026-12-08:
    loss/policy -0.08410723 against -0.08410683 in the first update), so config.json records the thread count a run
    repeats with."""
    wide = {"actor_hidden": (512, 256), "critic_hidden": (512, 256)}  # the CPU recipe's widths
    before = torch.get_num_threads()
    try:
        for n in (1, 2):
            torch.set_num_threads(n)
            start_run(_spec(dataset, 1, **wide), tmp_path / str(n), nthread=n, progress=False)
    finally:
        torch.set_num_threads(before)
    one, two = (_rows(tmp_path / n)[0] for n in ("1", "2"))
    collected = [k for k in one if not k.startswith("loss/")]
    assert "reward_mean" in collected and {k: one[k] for k in collected} == {k: two[k] for k in collected}
    assert [json.loads((tmp_path / n / "config.json").read_text())["nthread"] for n in ("1", "2")] == [1, 2]


def test_resume_continues_bit_for_bit(dataset: Path, tmp_path: Path) -> None:
    start_run(_spec(dataset, 4), tmp_path / "once", nthread=1, progress=False)
    half = start_run(_spec(dataset, 2), tmp_path / "split", nthread=1, progress=False)
    assert half.iteration == 2
    r = resume_run(tmp_path / "split", max_frames=4 * 8 * 4, nthread=1, progress=False)
    assert (r.status, r.iteration) == ("finished", 4)
    assert _rows(tmp_path / "once") == _rows(tmp_path / "split")
    a, b = load_checkpoint(tmp_path / "once"), load_checkpoint(tmp_path / "split")
    assert _same_params(a["policy"], b["policy"])
    assert torch.equal(a["env"]["physics"], b["env"]["physics"]) and torch.equal(a["obs"], b["obs"])
    assert resume_run(tmp_path / "split", nthread=1, progress=False).status == "up to date"


def test_resume_of_a_checkpoint_from_before_held_dimensions_continues_bit_for_bit(
    dataset: Path, tmp_path: Path
) -> None:
    start_run(_spec(dataset, 4), tmp_path / "once", nthread=1, progress=False)
    start_run(_spec(dataset, 2), tmp_path / "old", nthread=1, progress=False)
    state = load_checkpoint(tmp_path / "old")
    for entry in ("policy", "deploy_policy", "ema_policy"):  # saved before the 'active' mask existed
        if state.get(entry) is not None:
            state[entry].pop("active")
    torch.save(state, tmp_path / "old" / "checkpoint.pt")
    assert "active" not in load_checkpoint(tmp_path / "old")["policy"]
    r = resume_run(tmp_path / "old", max_frames=4 * 8 * 4, nthread=1, progress=False)
    assert (r.status, r.iteration) == ("finished", 4)
    assert _rows(tmp_path / "once") == _rows(tmp_path / "old")
    assert _same_params(_params(tmp_path / "once"), _params(tmp_path / "old"))


def test_ctrl_c_saves_a_checkpoint_and_resume_matches_an_uninterrupted_run(
    dataset: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    start_run(_spec(dataset, 3), tmp_path / "once", nthread=1, progress=False)
    collect = Runner.collect

    def interrupted_collect(self: Runner) -> dict:
        if self.iteration == 1:
            os.kill(os.getpid(), signal.SIGINT)  # as if the user pressed Ctrl-C during iteration 2
        return collect(self)

    monkeypatch.setattr(Runner, "collect", interrupted_collect)
    r = start_run(_spec(dataset, 3), tmp_path / "cut", nthread=1, progress=False)
    assert (r.status, r.iteration) == ("interrupted", 2)
    assert load_checkpoint(tmp_path / "cut")["iteration"] == 2
    monkeypatch.setattr(Runner, "collect", collect)
    assert resume_run(tmp_path / "cut", nthread=1, progress=False).iteration == 3
    assert _rows(tmp_path / "once") == _rows(tmp_path / "cut")
    assert _same_params(_params(tmp_path / "once"), _params(tmp_path / "cut"))


def test_load_policy_acts_with_its_normaliser_and_metadata(dataset: Path, tmp_path: Path) -> None:
    from wristmimic.env.vec_env import WristMimicEnv

    start_run(_spec(dataset, 1), tmp_path / "run", nthread=1, progress=False)
    policy = load_policy(tmp_path / "run")
    assert (policy.scene_id, policy.variant, policy.dataset_sha256) == (SID, "wristmimic", sha256_file(dataset))
    env = WristMimicEnv.from_file(dataset, SID, num_worlds=3, nthread=1)
    obs, _ = env.reset(seed=0)
    a = policy.act(obs)
    assert a.shape == (3, env.action_size) and torch.equal(a, policy.act(obs))
    torch.testing.assert_close(a, policy.net.actor(policy.net.normalizer(obs)))
    noisy = policy.act(obs, deterministic=False, generator=torch.Generator().manual_seed(0))
    assert 0 < (noisy - a).abs().mean() < 0.2
    with pytest.raises(InputError, match="features"):
        policy.act(obs[:, :5])
    env.close()


def test_bad_runs_fail_with_one_line(dataset: Path, tmp_path: Path) -> None:
    with pytest.raises(InputError, match="no checkpoint"):
        load_policy(tmp_path)
    (tmp_path / "junk.pt").write_bytes(b"not a checkpoint")
    with pytest.raises(InputError, match="not a torch file"):
        load_policy(tmp_path / "junk.pt")
    with pytest.raises(InputError, match="unknown variant"):
        start_run(TrainSpec(dataset, SID, "nope", ppo=preset("cpu", **TINY)), tmp_path / "v", progress=False)
    with pytest.raises(InputError, match="nosuchscene"):
        start_run(TrainSpec(dataset, "nosuchscene", ppo=preset("cpu", **TINY)), tmp_path / "s", progress=False)


def test_resume_refuses_a_changed_dataset(dataset: Path, tmp_path: Path) -> None:
    copy = tmp_path / "copy.h5"
    copy.write_bytes(dataset.read_bytes())
    start_run(TrainSpec(copy, SID, ppo=preset("cpu", **TINY, max_frames=32)), tmp_path / "run", progress=False)
    with open(copy, "ab") as f:
        f.write(b"\0")
    with pytest.raises(InputError, match="changed since the run started"):
        resume_run(tmp_path / "run", max_frames=64, progress=False)


def test_train_command_writes_a_run_and_resumes(dataset: Path, tmp_path: Path) -> None:
    cli = CliRunner()
    one = 2 * preset("cpu").horizon  # frames of one iteration with 2 worlds
    args = ["train", str(dataset), "--scene", SID, "--num-envs", "2", "--max-frames", str(one), "-q"]
    r = cli.invoke(app, [*args, "--out", str(tmp_path), "--seed", "3", "--nthread", "1"])
    assert r.exit_code == 0, r.output
    (run,) = tmp_path.iterdir()
    assert run.name.startswith(f"{SID}-wristmimic-seed3-") and "finished at iteration 1" in r.output
    r = cli.invoke(app, ["train", "--resume", str(run), "--max-frames", str(2 * one), "-q"])
    assert r.exit_code == 0 and "finished at iteration 2" in r.output, r.output
    r = cli.invoke(
        app,
        [
            "train",
            str(dataset),
            "--scenes",
            "all",
            "--num-envs",
            "2",
            "--max-frames",
            str(one),
            "-q",
            "--out",
            str(tmp_path / "all"),
            "--nthread",
            "1",
        ],
    )
    assert r.exit_code == 0 and [p.name.split("-")[0] for p in (tmp_path / "all").iterdir()] == [SID], r.output
    r = cli.invoke(app, [*args, "--out", str(tmp_path / "warm"), "--nthread", "1", "--init-from", str(run)])
    assert r.exit_code == 0, r.output
    (warm,) = (tmp_path / "warm").iterdir()
    init = json.loads((warm / "config.json").read_text())["init"]
    assert init["path"] == str((run / "checkpoint.pt").resolve()) and init["frames"] == 2 * one
    bad = cli.invoke(app, ["train", "--resume", str(warm), "--init-from", str(run), "-q"])
    assert bad.exit_code == 1 and "--resume" in bad.output
    bad = cli.invoke(app, [*args, "--out", str(tmp_path / "x"), "--init-normalizer", "source"])
    assert bad.exit_code == 1 and "--init-from" in bad.output and not (tmp_path / "x").exists()
    bad = cli.invoke(app, ["train", str(dataset), "--scenes", "some", "-q"])
    assert bad.exit_code == 1 and "error:" in bad.output and "'all'" in bad.output
    bad = cli.invoke(app, ["train", str(dataset), "--scene", SID, "--preset", "huge", "-q"])
    assert bad.exit_code == 1 and "unknown preset" in bad.output


def test_learning_curve_script_plots_a_run(dataset: Path, tmp_path: Path) -> None:
    start_run(_spec(dataset, 2), tmp_path / "run", nthread=1, progress=False)
    script = runpy.run_path(str(Path(__file__).parents[1] / "scripts" / "learning_curve.py"))
    out = script["plot"](tmp_path / "run", tmp_path / "reports" / "curve.png", 5)
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_sampling_probe_plans_from_one_broadcast_state_with_and_without_a_policy(dataset: Path, tmp_path: Path) -> None:
    """scripts/sampling_probe.py: every world restarts from world 0's state (same actions, same results), knots
    interpolate linearly, and the receding horizon executes contiguous frames, after ``--start`` with a policy."""
    probe = runpy.run_path(str(Path(__file__).parents[1] / "scripts" / "sampling_probe.py"))
    kn = torch.tensor([[[0.0], [1.0], [3.0]]])
    assert probe["knots_to_sequence"](kn, 6, 2)[0, :, 0].tolist() == [0.0, 0.5, 1.0, 2.0, 3.0, 3.0]
    env = WristMimicEnv.from_file(dataset, SID, num_worlds=3, nthread=1)
    env.reset(start_frames=torch.tensor([0, 7, 13]))
    env.step(torch.zeros(3, env.action_size))
    env.load_state_dict(probe["broadcast"](env.state_dict(), 1, 3))
    assert env.frame.tolist() == [8, 8, 8]
    obs, r, term, trunc, _ = env.step(torch.full((3, env.action_size), 0.2))
    assert not (term | trunc).any()
    q = env.backend.qpos
    assert torch.equal(q[0], q[1]) and torch.equal(q[0], q[2])  # the physics bit for bit
    assert torch.allclose(obs[0], obs[2], atol=1e-6) and torch.allclose(r[0], r[1])  # float32 math per batch row
    args = ["--scene", SID, "--worlds", "4", "--horizon", "4", "--knot", "2", "--iters", "2", "--commit", "2"]
    a = probe["parser"]().parse_args([str(dataset), *args, "--frames", "6", "--nthread", "1"])
    frames = [rec["frame"] for rec in probe["probe"](a, log=lambda _: None)]
    assert frames == list(range(1, frames[-1] + 1)) and frames[-1] <= 6
    start_run(_spec(dataset, 2), tmp_path / "run", nthread=1, progress=False)
    a = probe["parser"]().parse_args(
        [str(dataset), *args, "--frames", "9", "--nthread", "1", "--policy", str(tmp_path / "run"), "--start", "5"]
    )
    frames = [rec["frame"] for rec in probe["probe"](a, log=lambda _: None)]
    assert frames[0] == 6 and frames == list(range(6, frames[-1] + 1))


def test_kinematic_grip_probe_holds_the_body_on_its_reference_and_searches_finger_targets(dataset: Path) -> None:
    """scripts/kinematic_grip_probe.py: the non-finger DoFs replay the reference (the wrists stay on it), the object
    error is measured at every frame after --start, the cross-entropy search never ends worse than its nominal,
    and bad frame ranges stop with a one-line error."""
    probe = runpy.run_path(str(Path(__file__).parents[1] / "scripts" / "kinematic_grip_probe.py"))
    args = probe["parser"]().parse_args([str(dataset), "--scene", SID, "--start", "2", "--stop", "12"])
    env = probe["build"](args)
    replay = probe["KinematicReplay"](env, 2, 12)
    errs = replay.errors(np.zeros(env.num_hinges))
    assert errs.shape == (10,) and np.isfinite(errs).all()
    import mujoco

    d, m = replay.d, replay.m
    wrist = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, env.scene.skeleton.body_names[int(env.sets.wrists[1])])
    ref_wrist = env.ref.body_pos[12, int(env.sets.wrists[1])].numpy()
    assert np.linalg.norm(d.xpos[wrist] - ref_wrist) < 0.01  # the wrist is where the reference puts it
    again = replay.errors(np.zeros(env.num_hinges))
    np.testing.assert_array_equal(errs, again)  # deterministic replays
    dims = {"1": 2, "per": 10, "": int(env.finger_actions.sum())}  # per hand, per finger (5 a hand), per hinge
    for extra in (["--synergy", "1.0"], ["--synergy", "1.0", "--per-finger"], []):
        a = probe["parser"]().parse_args(
            [str(dataset), "--scene", SID, "--start", "2", "--stop", "8", "--samples", "4", "--iters", "2", *extra]
        )
        out = probe["probe"](a, log=lambda _: None)
        assert out["dimensions"] == dims["per" if "--per-finger" in extra else "1" if extra else ""]
        assert len(out["best_errors"]) == 6 and out["best_mean_error"] <= out["iterations"][0]["nominal"]
        grip = np.asarray(out["finger_grip"])  # the best finger targets, as env.finger_grip takes them
        fingers = env.finger_actions.numpy()
        lo, hi = env.scene.ctrl_range[fingers, 0], env.scene.ctrl_range[fingers, 1]
        assert grip.shape == (fingers.sum(),) and (grip >= lo).all() and (grip <= hi).all()
    text = "env.finger_grip=[" + ",".join(f"{v:.6f}" for v in grip) + "]"
    with_grip = probe["build"](
        probe["parser"]().parse_args([str(dataset), "--scene", SID, "--start", "2", "--stop", "8", "--set", text])
    )
    np.testing.assert_allclose(with_grip.cfg.finger_grip, grip, atol=1e-6)  # round trip through --set
    for bad in (["--start", "5", "--stop", "5"], ["--start", "0", "--stop", "999"]):
        with pytest.raises(SystemExit, match="--start"):
            probe["build"](probe["parser"]().parse_args([str(dataset), "--scene", SID, *bad]))


def test_kinematic_grip_probe_moves_wrists_with_the_object_and_holds_the_object(dataset: Path) -> None:
    """The probe's arm offset map moves a touching hand's wrist by the object-frame offset (to first order, with its
    orientation kept), leaves a hand far from contact where it was, and --hold keeps the object on its reference."""
    import mujoco

    from wristmimic.rotations import quat_to_matrix

    probe = runpy.run_path(str(Path(__file__).parents[1] / "scripts" / "kinematic_grip_probe.py"))
    env = probe["build"](probe["parser"]().parse_args([str(dataset), "--scene", SID, "--start", "2", "--stop", "12"]))
    replay = probe["KinematicReplay"](env, 2, 12)
    arms, q, v = replay.arms, replay.qpos, replay.qvel
    touch = env.ref.hand.numpy().astype(bool)
    assert touch.any(), "the test scene needs reference hand contact"
    t = int(np.flatnonzero(touch.any(1))[touch.any(1).sum() // 2])
    assert arms.weight[t][touch[t]].tolist() == [1.0] * int(touch[t].sum()) and arms.weight.min() >= 0.0
    off = np.array([[0.02, 0.0, -0.01], [0.0, 0.015, 0.0]])
    q2, v2 = arms.apply(q, v, off)
    changed = np.flatnonzero(np.any(q2 != q, axis=0))
    assert set(changed) <= set(arms.qpos_index.reshape(-1).tolist())  # arm hinges only
    m, d = replay.m, replay.d
    wrists = [int(env.scene.body_ids[int(env.sets.wrists[h])]) for h in range(2)]

    def pose(qq: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        d.qpos[:] = qq
        mujoco.mj_kinematics(m, d)
        return d.xpos[wrists].copy(), d.xmat[wrists].reshape(2, 3, 3).copy()

    (p0, r0), (p1, r1) = pose(q[t]), pose(q2[t])
    want = arms.weight[t][:, None] * np.einsum("ij,hj->hi", quat_to_matrix(env.ref.obj_quat[t, 0].numpy()), off)
    np.testing.assert_allclose(p1 - p0, want, atol=2e-3)
    assert np.all(np.einsum("hij,hij->h", r0, r1) > 1.0 + 2.0 * np.cos(0.05))  # orientation kept within 0.05 rad
    far = np.flatnonzero(arms.weight.max(1) == 0.0)
    if far.size:
        np.testing.assert_array_equal(q2[far], q[far])
    held = replay.errors(np.zeros(env.num_hinges), off, hold_until=12)
    assert held.max() < 1e-6  # the object sat on its reference for every frame


def test_hold_probe_releases_the_object_to_the_hands_alone(dataset: Path) -> None:
    """scripts/hold_probe.py: with the hands moved 0.5 m away nothing holds the released object (the floor and the
    rest of the humanoid do not collide), so it falls freely: g t^2 / 2 over the frames after release; runs are
    deterministic, the search never reports worse than its nominal, and bad arguments stop with one line."""
    probe = runpy.run_path(str(Path(__file__).parents[1] / "scripts" / "hold_probe.py"))
    base = [str(dataset), "--scene", SID, "--frame", "20", "--closures", "1.0", "--close", "2", "--hold", "3"]
    far = probe["probe"](
        probe["parser"]().parse_args([*base, "--frames", "9", "--offset", "0,0.5,0,0,0,0"]), log=lambda _: None
    )
    n, dt = 6 * 4, 1 / 120  # six frames of four substeps after the release; semi-implicit Euler free fall
    (row,) = far["nominal"]
    assert row["displacement"] == pytest.approx(9.81 * dt * dt * n * (n + 1) / 2, rel=0.01) and row["held"] < 6
    long = [*base, "--frames", "40", "--offset", "0,0.5,0,0,0,0"]  # 37 frames after the release: a 7.5 m free fall
    fall = probe["probe"](probe["parser"]().parse_args(long), log=lambda _: None)["nominal"][0]["displacement"]
    floor = probe["probe"](probe["parser"]().parse_args([*long, "--floor"]), log=lambda _: None)["nominal"][0]
    assert fall > 7.0 and floor["displacement"] < 2.0  # --floor: the floor catches it
    args = probe["parser"]().parse_args([*base, "--frames", "9", "--samples", "4", "--iters", "2"])
    one, two = probe["probe"](args, log=lambda _: None), probe["probe"](args, log=lambda _: None)
    assert one == two
    assert one["search"]["best_displacement"] <= one["nominal"][0]["displacement"]
    syn = probe["HoldProbe"](probe["parser"]().parse_args([*base, "--hands", "right", "--synergy", "1.5"]))
    closed, fingers = syn.closed, syn.fingers  # the synergy's closure: right finger hinges only, at most 1.5 rad
    assert np.abs(closed[~fingers]).max() == 0.0 and 1.0 < np.abs(closed[fingers]).max() <= 1.5 + 1e-9
    with pytest.raises(SystemExit, match="--close"):
        probe["probe"](probe["parser"]().parse_args([*base, "--frames", "3"]), log=lambda _: None)


def test_assisted_rollout_gives_each_world_its_own_share_of_the_controller(dataset: Path, tmp_path: Path) -> None:
    """scripts/assisted_rollout.py: one deterministic frame-0 rollout per gain in the run's training scene; each world's
    wrench is the full-gain wrench times its own gain (0: none), and every rollout ends with a frame and a reason."""
    start_run(_spec(dataset, 1), tmp_path / "run", nthread=1, progress=False)
    script = runpy.run_path(str(Path(__file__).parents[1] / "scripts" / "assisted_rollout.py"))
    gains = [1.0, 0.5, 0.0]
    one = script["rollouts"](tmp_path / "run", gains)
    assert one == script["rollouts"](tmp_path / "run", gains)  # deterministic
    assert [r["gain"] for r in one] == gains
    assert all(1 <= r["frames"] <= 40 and r["reason"] in ("end", *REASONS.values()) for r in one)
    traced = script["rollouts"](tmp_path / "run", gains, trace=True)  # --trace: one row per frame, same rollouts
    assert [{k: v for k, v in r.items() if k != "trace"} for r in traced] == one
    for r in traced:
        assert [row["frame"] for row in r["trace"]] == list(range(1, r["frames"] + 1))
        assert all(row["root_cm"] is not None for row in r["trace"][:-1]) and r["trace"][-1]["root_cm"] is None
        assert abs(r["trace"][0]["root_cm"][2]) < 5.0  # one step from the reference's own start
    err = [np.mean([row["obj_cm"] for row in r["trace"]]) for r in traced]
    assert err[0] < err[2]  # full help holds the object nearer its reference than none (rows not mixed up)
    cfg = variant_config("wristmimic")
    env = WristMimicEnv.from_file(dataset, SID, 3, cfg, SceneConfig(object_actuators=True), seed=0)
    env.reset(start_frames=torch.full((3,), 10, dtype=torch.long))
    env.object_gain, env.object_scale = 1.0, torch.tensor(gains)  # how the script applies each world's gain
    w = env.object_wrench()
    assert torch.allclose(w[1], 0.5 * w[0], atol=1e-5) and torch.all(w[2] == 0) and w[0].abs().max() > 0


def test_assisted_rollout_loads_account_for_every_force_on_the_object(dataset: Path, tmp_path: Path) -> None:
    """scripts/assisted_rollout.py --loads: the sources' forces plus gravity equal the object's mass times its
    acceleration, with and without the controller (no force missed, counted twice or of the wrong sign); the
    controller's row is zero without help; the summary averages the reference's contact frames by source."""
    script = runpy.run_path(str(Path(__file__).parents[1] / "scripts" / "assisted_rollout.py"))
    sources = script["SOURCES"]
    env = WristMimicEnv.from_file(dataset, SID, 2, variant_config("wristmimic"), SceneConfig(object_actuators=True))
    meter = script["LoadMeter"](env)
    m, obj = env.scene.model, env.scene.dynamic_objects[0]
    mass = float(m.body_subtreemass[obj.body_id])
    assert meter.weight == pytest.approx(mass * 9.81, rel=1e-3)
    env.reset(start_frames=torch.zeros(2, dtype=torch.long))
    env.object_gain, env.object_scale = 1.0, torch.tensor([0.0, 1.0])
    for _ in range(3):
        env.step(torch.zeros(2, env.action_size))
    for world in (0, 1):
        f = meter(world)
        acc = meter.data.qacc[obj.dofadr : obj.dofadr + 3]  # the free joint's linear acceleration (world frame)
        np.testing.assert_allclose(f.sum(0) + mass * m.opt.gravity, mass * acc, atol=0.02 * meter.weight)
        assert np.all(f[sources.index("controller")] == 0) == (world == 0)
    # without help the fixture's box, which starts in the hands, is held up by them
    assert meter(0)[sources.index("hands"), 2] > 0.3 * meter.weight
    # the contact sensors' net force of a hand body is the force it exerts on the object (the drive factor's sign)
    st, hands = env.sim_state(), torch.cat(env.hands)
    touch = st.contact_obj[0, hands]
    assert touch.any()
    on_object = (st.contact_force[0, hands] * touch[:, None]).sum(0).numpy()
    np.testing.assert_allclose(on_object, meter(0)[sources.index("hands")], rtol=1e-4, atol=1e-3)
    env.close()
    # the summary: vertical shares over contact frames, drive along the reference's horizontal motion
    ref = env.ref
    frames = np.arange(1, ref.num_frames)
    forces = np.zeros((len(frames), len(sources), 3))
    forces[:, sources.index("hands")] = [0.0, 0.0, meter.weight]
    vel = ref.obj_linvel[frames, 0, :2].numpy()
    moving = ref.hand[frames].any(-1).numpy() & (np.linalg.norm(vel, axis=-1) > 0.05)
    assert moving.any()
    forces[:, sources.index("supports"), :2] = -3.0 * vel / np.linalg.norm(vel, axis=-1, keepdims=True).clip(1e-9)
    out = script["summarize_loads"](forces, frames, ref, meter.weight)
    assert out["lift"]["hands"] == pytest.approx(1.0) and out["lift"]["controller"] == 0.0
    assert out["drive"]["supports"] == pytest.approx(-3.0) and out["drive"]["hands"] == 0.0
    start_run(_spec(dataset, 1), tmp_path / "run", nthread=1, progress=False)
    res = script["rollouts"](tmp_path / "run", [1.0, 0.0], loads=True)
    assert all(set(r["lift"]) == set(sources) and set(r["drive"]) == set(sources) for r in res)


def test_object_force_probe_drives_the_object_alone_and_reports_the_controllers_force(
    dataset: Path, tmp_path: Path
) -> None:
    """scripts/object_force_probe.py: the humanoid cannot touch anything, the controller carries the object along its
    reference (small errors on the synthetic box), its force holds the object up, the output covers every
    frame, two runs agree bit for bit, and a stiffer controller or a bad option is what the flags say."""
    probe = runpy.run_path(str(Path(__file__).parents[1] / "scripts" / "object_force_probe.py"))
    args = probe["parser"]().parse_args([str(dataset), "--scene", SID])
    env = probe["build"](args)
    m = env.scene.model
    humanoid = np.isin(m.geom_bodyid, env.scene.body_ids)
    assert humanoid.any() and not (m.geom_contype[humanoid] | m.geom_conaffinity[humanoid]).any()
    out = probe["probe"](env)
    T = env.ref.num_frames
    assert out["frames"] == list(range(1, T)) and len(out["force_n"]) == T - 1
    F = np.asarray(out["force_n"])
    mass = float(m.body_subtreemass[env.scene.dynamic_objects[0].body_id])
    assert np.isfinite(F).all() and out["weight_n"] == pytest.approx(mass * 9.81)
    assert np.median(F[:, 2]) > 0.5 * out["weight_n"]  # it holds the object up (gravity compensation)
    free = probe["build"](args)
    free.object_gain = 0.0  # the object left to itself: the controller is what keeps it on its reference
    loose = probe["probe"](free)
    assert not np.any(loose["force_n"]) and np.mean(out["pos_err_m"]) < 0.5 * np.mean(loose["pos_err_m"])
    assert probe["probe"](probe["build"](args)) == out  # deterministic
    stiff = probe["build"](probe["parser"]().parse_args([str(dataset), "--scene", SID, "--gain-scale", "4"]))
    oc, base = stiff.cfg.object_controller, env.cfg.object_controller
    assert (oc.kp, oc.kr) == (4 * base.kp, 4 * base.kr) and oc.kd == pytest.approx(2 * base.kd)
    for bad in (["--set", "env.weights.op=1"], ["--gain-scale", "0"]):
        with pytest.raises(SystemExit):
            probe["build"](probe["parser"]().parse_args([str(dataset), "--scene", SID, *bad]))


def test_sigma_schedule_sets_each_rollouts_sigma_and_the_policy_keeps_the_last(dataset: Path, tmp_path: Path) -> None:
    kw = dict(learn_std=False, min_std=0.0, final_std=0.01, std_anneal_start=32, std_anneal_end=96)
    start_run(_spec(dataset, 4, **kw), tmp_path / "run", nthread=1, progress=False)
    cfg = _spec(dataset, 4, **kw).ppo
    logged = [float(r["loss/sigma"]) for r in _rows(tmp_path / "run")]
    # the rollout of iteration k is collected after (k - 1) x 32 frames: 0.1, 0.1, 0.0316, 0.01
    assert logged == pytest.approx([math.exp(cfg.log_std_at(32 * k)) for k in range(4)], rel=1e-5)
    assert logged[-1] == pytest.approx(0.01, rel=1e-5) and logged[1] == pytest.approx(0.1, rel=1e-5)
    assert torch.allclose(load_policy(tmp_path / "run").net.log_std.exp(), torch.full((153,), 0.01), rtol=1e-5)


def test_deployed_sigma_is_used_by_evaluation_but_not_by_training(dataset: Path, tmp_path: Path) -> None:
    from wristmimic.evaluate.policy import load_eval_policy

    start_run(_spec(dataset, 1, deploy_std=0.004), tmp_path / "run", nthread=1, progress=False)
    assert float(_rows(tmp_path / "run")[0]["loss/sigma"]) == pytest.approx(0.1, rel=1e-4)  # training explores
    p = load_eval_policy(tmp_path / "run")
    assert p.policy.sigma.shape == (153,) and torch.allclose(p.sigma, torch.full((153,), 0.004))
    assert torch.allclose(torch.exp(p.policy.net.log_std), torch.full((153,), 0.1), rtol=1e-2)  # training sigma kept


def test_deployed_moving_average_is_what_evaluation_loads_and_resume_keeps(dataset: Path, tmp_path: Path) -> None:
    from wristmimic.evaluate.policy import load_eval_policy

    start_run(_spec(dataset, 3, deploy_ema=0.9), tmp_path / "run", nthread=1, progress=False)
    state = load_checkpoint(tmp_path / "run")
    latest, avg = state["policy"], state["deploy_policy"]
    assert avg.keys() == latest.keys() and state["deploy"] == {"weights": "ema", "iteration": 3, "frames": 96}
    w = "actor.0.weight"
    assert not torch.equal(avg[w], latest[w])  # an average of three updates, not the last one
    p = load_eval_policy(tmp_path / "run")
    assert p.policy.weights == "ema" and p.metadata["policy_weights"] == "ema"
    assert torch.equal(p.policy.net.state_dict()[w], avg[w])
    # training is the same as without the average: identical latest weights and metrics
    start_run(_spec(dataset, 3), tmp_path / "plain", nthread=1, progress=False)
    assert _same_params(_params(tmp_path / "plain"), latest) and _rows(tmp_path / "plain") == _rows(tmp_path / "run")
    assert load_eval_policy(tmp_path / "plain").policy.weights == "latest"
    # the average resumes bit for bit
    start_run(_spec(dataset, 1, deploy_ema=0.9), tmp_path / "split", nthread=1, progress=False)
    resume_run(tmp_path / "split", max_frames=96, nthread=1, progress=False)
    split = load_checkpoint(tmp_path / "split")["deploy_policy"]
    assert _same_params(split, avg)


def test_deployed_average_follows_the_warm_up_decay() -> None:
    cfg = preset("cpu", deploy_ema=0.95)
    assert cfg.ema_decay(1) == pytest.approx(2 / 11) and cfg.ema_decay(1000) == 0.95
    with pytest.raises(InputError, match="deploy_ema"):
        preset("cpu", deploy_ema=1.0)


def test_deployed_best_is_the_best_periodic_evaluation_and_resumes(
    dataset: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    # scripted (paper, strict) rates: iteration 2 is the best, by its strict rate (the paper's alone: iteration 3)
    rates = {1: (1.0, 0.0), 2: (0.5, 0.5), 3: (1.0, 0.25)}
    seeds: list[int] = []

    def fake_eval(self: Runner) -> dict[str, float]:
        seeds.append(self.cfg.eval_base_seed)
        paper, strict = rates[self.iteration]
        return {"eval/success_rate": paper, "eval/strict_success_rate": strict}

    monkeypatch.setattr(Runner, "periodic_eval", fake_eval)
    kw = dict(deploy_best=True, eval_every=1, eval_base_seed=12345)
    start_run(_spec(dataset, 3, **kw), tmp_path / "run", nthread=1, progress=False)
    assert seeds == [12345] * 3
    state = load_checkpoint(tmp_path / "run")
    assert state["deploy"] == {
        "weights": "best", "iteration": 2, "frames": 64, "eval_success_rate": 0.5, "eval_strict_success_rate": 0.5,
        "eval_trials": 32,
    }  # fmt: skip
    start_run(_spec(dataset, 2), tmp_path / "two", nthread=1, progress=False)  # the same training, stopped at 2
    assert _same_params(state["deploy_policy"], _params(tmp_path / "two"))
    assert not _same_params(state["policy"], _params(tmp_path / "two"))  # training went on to iteration 3
    p = load_policy(tmp_path / "run")
    assert (p.weights, p.weights_iteration, p.weights_frames, p.iteration) == ("best", 2, 64, 3)
    # a resume keeps the best found before the interruption
    start_run(_spec(dataset, 2, **kw), tmp_path / "split", nthread=1, progress=False)
    resume_run(tmp_path / "split", max_frames=96, nthread=1, progress=False)
    split = load_checkpoint(tmp_path / "split")
    assert split["deploy"] == state["deploy"] and _same_params(split["deploy_policy"], state["deploy_policy"])


def test_confirming_trials_rank_a_candidate_by_all_its_trials(
    dataset: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    # scripted rates on 4 trials, then successes of the 4 confirming trials (paper rule = strict rule here)
    small = {1: 0.5, 2: 1.0, 3: 0.75, 4: 0.0}
    confirm = {1: 4, 2: 0, 3: 4}
    calls: list[tuple[int, int, int]] = []

    def fake_eval(self: Runner) -> dict[str, float]:
        return {"eval/success_rate": small[self.iteration], "eval/strict_success_rate": small[self.iteration]}

    def fake_trials(self: Runner, start: int, stop: int) -> dict[str, np.ndarray]:
        calls.append((self.iteration, start, stop))
        won = np.arange(stop - start) < confirm[self.iteration]
        return {"success": won, "strict_success": won}

    monkeypatch.setattr(Runner, "periodic_eval", fake_eval)
    monkeypatch.setattr(Runner, "_eval_trials", fake_trials)
    kw = dict(deploy_best=True, eval_every=1, eval_trials=4, eval_confirm_trials=4)
    start_run(_spec(dataset, 4, **kw), tmp_path / "run", nthread=1, progress=False)
    # iteration 2's 4 of 4 falls to 4 of 8 and loses to iteration 1's 6 of 8; iteration 3's 7 of 8 wins;
    # iteration 4 (no success) and nothing below the best runs confirming trials
    assert calls == [(1, 4, 8), (2, 4, 8), (3, 4, 8)]
    state = load_checkpoint(tmp_path / "run")
    assert state["deploy"] == {
        "weights": "best", "iteration": 3, "frames": 96, "eval_success_rate": 0.875, "eval_strict_success_rate": 0.875,
        "eval_trials": 8,
    }  # fmt: skip
    rows = _rows(tmp_path / "run")
    assert [r["eval/confirm_success_rate"] for r in rows][:3] == ["0.75", "0.5", "0.875"]
    assert rows[3]["eval/confirm_strict_success_rate"] == "nan"
    # a resume keeps the confirmed figures: a later 0.75 on 4 trials confirmed to 0.5 does not replace them
    small[5], confirm[5] = 1.0, 0
    resume_run(tmp_path / "run", max_frames=160, nthread=1, progress=False)
    assert load_checkpoint(tmp_path / "run")["deploy"]["iteration"] == 3 and calls[-1] == (5, 4, 8)
    # without confirmation iteration 2's lucky 4 of 4 is deployed, and no confirming column is logged
    calls.clear()
    start_run(_spec(dataset, 4, **{**kw, "eval_confirm_trials": 0}), tmp_path / "plain", nthread=1, progress=False)
    assert calls == [] and load_checkpoint(tmp_path / "plain")["deploy"]["iteration"] == 2
    plain = _rows(tmp_path / "plain")
    assert "eval/confirm_success_rate" not in plain[0]
    train_only = [{k: v for k, v in r.items() if not k.startswith("eval/")} for r in rows]
    assert [{k: v for k, v in r.items() if not k.startswith("eval/")} for r in plain] == train_only  # same training
    with pytest.raises(InputError, match="eval_confirm_trials"):
        preset("cpu", eval_confirm_trials=-1)


def test_confirming_trials_are_the_selection_protocols_next_trials(
    dataset: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    # the periodic evaluation's 4 trials scripted as 2 successes; the 4 confirming ones run for real
    seen: list[dict[str, np.ndarray]] = []

    def half(self: Runner) -> dict[str, float]:
        seen.extend([self._eval_trials(0, 8), self._eval_trials(4, 8)])
        return {"eval/success_rate": 0.5, "eval/strict_success_rate": 0.5}

    monkeypatch.setattr(Runner, "periodic_eval", half)
    kw = dict(deploy_best=True, eval_every=1, eval_trials=4, eval_confirm_trials=4, eval_base_seed=12345)
    start_run(_spec(dataset, 2, **kw), tmp_path / "run", nthread=1, progress=False)
    first8, next4 = seen[:2]
    for key, col in next4.items():  # trials 4..7 of the protocol, seeded as in a run of all eight
        np.testing.assert_array_equal(col, first8[key][4:], err_msg=key)
    row = _rows(tmp_path / "run")[0]
    assert float(row["eval/confirm_success_rate"]) == (2 + next4["success"].sum()) / 8
    assert float(row["eval/confirm_strict_success_rate"]) == (2 + next4["strict_success"].sum()) / 8
    assert load_checkpoint(tmp_path / "run")["deploy"]["eval_trials"] == 8
    # evaluation trials leave training alone: the same rows and weights as a run that evaluates nothing
    start_run(_spec(dataset, 2, eval_every=0), tmp_path / "plain", nthread=1, progress=False)
    assert [{k: v for k, v in r.items() if not k.startswith("eval/")} for r in _rows(tmp_path / "run")] == [
        {k: v for k, v in r.items() if not k.startswith("eval/")} for r in _rows(tmp_path / "plain")
    ]
    assert _same_params(_params(tmp_path / "run"), _params(tmp_path / "plain"))


def test_deploy_best_without_periodic_evaluation_deploys_the_latest(dataset: Path, tmp_path: Path) -> None:
    start_run(_spec(dataset, 2, deploy_best=True, eval_every=0), tmp_path / "run", nthread=1, progress=False)
    state = load_checkpoint(tmp_path / "run")
    assert state["deploy"] == {"weights": "latest", "iteration": 2, "frames": 64} and "deploy_policy" not in state
    assert load_policy(tmp_path / "run").weights == "latest"


def test_evaluate_weights_option_loads_the_latest_or_the_deployed(
    dataset: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(
        Runner, "periodic_eval", lambda self: {"eval/success_rate": 1.0 if self.iteration == 1 else 0.0}
    )
    start_run(_spec(dataset, 2, deploy_best=True, eval_every=1), tmp_path / "run", nthread=1, progress=False)
    state = load_checkpoint(tmp_path / "run")
    best, latest = load_policy(tmp_path / "run"), load_policy(tmp_path / "run", weights="latest")
    assert (best.weights, best.weights_iteration, latest.weights, latest.weights_iteration) == ("best", 1, "latest", 2)
    assert _same_params(latest.net.state_dict(), state["policy"])
    assert _same_params(best.net.state_dict(), state["deploy_policy"])
    with pytest.raises(InputError, match="weights"):
        load_policy(tmp_path / "run", weights="newest")

    def evaluate(out: str, *extra: str) -> dict:
        args = ["evaluate", str(tmp_path / "run"), "-p", "quick", "-n", "2", "--num-envs", "2", "--nthread", "1", "-q"]
        res = CliRunner().invoke(app, [*args, *extra, "-o", str(tmp_path / out)])
        assert res.exit_code == 0, res.output
        return json.loads((tmp_path / out / "eval.json").read_text())

    assert "policy_weights" not in evaluate("ev", "--weights", "latest")
    ev = evaluate("ev2")
    assert (ev["policy_weights"], ev["policy_weights_iteration"]) == ("best", 1)


def test_held_finger_actions_are_zero_in_training_evaluation_and_every_kl(dataset: Path, tmp_path: Path) -> None:
    from wristmimic.evaluate.policy import load_eval_policy

    spec = _spec(dataset, 2, held_actions="fingers")
    scene_cfg = SceneConfig(object_actuators=True)
    env = WristMimicEnv.from_file(dataset, SID, 4, preset_env("cpu", "wristmimic"), scene_cfg, nthread=1, seed=0)
    fingers = env.finger_actions
    assert 0 < int(fingers.sum()) < env.action_size
    runner = Runner(env, spec.ppo, 0, tmp_path / "r", "{}", {"scene": SID, "variant": "wristmimic"})
    assert torch.equal(runner.policy.active, (~fingers).float())
    runner.collect()
    acts = runner.storage.actions.flatten(0, 1)
    assert (acts[:, fingers] == 0).all() and (acts[:, ~fingers] != 0).all()  # held: no mean, no noise
    # a held dimension's value changes no log-probability; the entropy and KL count the active ones only
    net, mu = runner.policy, runner.storage.mu.flatten(0, 1)
    moved = acts.clone()
    moved[:, fingers] += 0.7
    torch.testing.assert_close(net.log_prob(mu, moved), net.log_prob(mu, acts))
    per_dim = net.log_std + 0.5 * math.log(2 * math.pi * math.e)
    torch.testing.assert_close(net.entropy(), per_dim[~fingers].sum())
    runner.alg.update(runner.storage, runner.gen)
    env.close()
    # trained and evaluated: the deployed policy holds them too, deterministic or sampled
    start_run(spec, tmp_path / "run", nthread=1, progress=False)
    p = load_eval_policy(tmp_path / "run")
    obs = torch.randn(5, p.policy.net.obs_size)
    assert (p.policy.act(obs)[:, fingers] == 0).all()
    assert (p.policy.act(obs, deterministic=False, generator=torch.Generator().manual_seed(0))[:, fingers] == 0).all()
    with pytest.raises(InputError, match="held_actions"):
        preset("cpu", held_actions="legs")


def test_warm_start_takes_the_source_policy_resets_its_statistics_and_is_recorded(
    dataset: Path, tmp_path: Path
) -> None:
    from dataclasses import replace

    from wristmimic.rl.train import _build, _config_dict, _init_source

    start_run(_spec(dataset, 2), tmp_path / "src", nthread=1, progress=False)
    source = load_checkpoint(tmp_path / "src")
    spec = replace(_spec(dataset, 2, seed=3, held_actions="fingers"), init_from=tmp_path / "src")
    path, entry, record, weights = _init_source(spec)
    assert entry == ("deploy_policy" if "deploy_policy" in source else "policy")
    assert record["sha256"] == sha256_file(tmp_path / "src" / "checkpoint.pt") and record["frames"] == 64
    config = _config_dict(spec, preset_env("cpu", "wristmimic"), sha256_file(dataset), record)
    runner = _build(config, tmp_path / "new", 1, dataset)
    fresh = {k: v.clone() for k, v in runner.policy.state_dict().items()}
    runner.warm_start(path, entry, weights)
    now = runner.policy.state_dict()
    assert torch.equal(now["actor.0.weight"], source[entry]["actor.0.weight"])
    assert not torch.equal(now["actor.0.weight"], fresh["actor.0.weight"])
    assert torch.equal(now["active"], fresh["active"]) and now["active"].min() == 0  # this run's held fingers
    assert float(now["normalizer.count"]) == 0.0  # re-estimated from this run's observations
    runner.env.close()
    # through start_run: config.json records the source; the same warm start twice gives the same run
    for name in ("a", "b"):
        start_run(spec, tmp_path / name, nthread=1, progress=False)
    assert json.loads((tmp_path / "a" / "config.json").read_text())["init"]["sha256"] == record["sha256"]
    assert _rows(tmp_path / "a") == _rows(tmp_path / "b")
    assert _rows(tmp_path / "a") != _rows(tmp_path / "src")
    # the run keeps the bytes it started from (init.pt), so it starts again the same after the source trained on
    assert sha256_file(tmp_path / "a" / "init.pt") == record["sha256"]
    assert json.loads((tmp_path / "a" / "config.json").read_text())["init"]["copy"] == "init.pt"
    resume_run(tmp_path / "src", max_frames=128, nthread=1, progress=False)
    assert sha256_file(tmp_path / "src" / "checkpoint.pt") != record["sha256"]
    start_run(replace(spec, init_from=tmp_path / "a" / "init.pt"), tmp_path / "again", nthread=1, progress=False)
    assert _rows(tmp_path / "again") == _rows(tmp_path / "a")
    # another network size: one line naming the source's weights, and no folder left behind
    wide = replace(spec, ppo=preset("cpu", **{**TINY, "actor_hidden": (16,)}, max_frames=64))
    with pytest.raises(InputError, match=r"actor\.0\.weight.*shape"):
        start_run(wide, tmp_path / "wide", nthread=1, progress=False)
    assert not (tmp_path / "wide").exists()
    with pytest.raises(InputError, match="init_weights"):
        start_run(replace(spec, init_weights="best"), tmp_path / "bad", nthread=1, progress=False)
    with pytest.raises(InputError, match="init_normalizer"):
        start_run(replace(spec, init_normalizer="mean"), tmp_path / "bad", nthread=1, progress=False)


def test_warm_start_can_keep_the_source_statistics(dataset: Path, tmp_path: Path) -> None:
    """``init_normalizer="source"`` keeps the source's observation statistics (mean, variance and count), so the
    first batches of a run with other starts move them as little as they would have moved the source's; the
    choice is recorded."""
    from dataclasses import replace

    start_run(_spec(dataset, 2), tmp_path / "src", nthread=1, progress=False)
    source = load_checkpoint(tmp_path / "src")
    entry = "deploy_policy" if "deploy_policy" in source else "policy"
    spec = replace(_spec(dataset, 1, seed=3), init_from=tmp_path / "src", init_normalizer="source")
    start_run(spec, tmp_path / "keep", nthread=1, progress=False)
    start_run(replace(spec, init_normalizer="reset"), tmp_path / "reset", nthread=1, progress=False)
    count = float(source[entry]["normalizer.count"])
    assert count > 0
    kept = load_checkpoint(tmp_path / "keep")["policy"]
    reset = load_checkpoint(tmp_path / "reset")["policy"]
    # one more iteration's observations on top of the source's, against this run's alone
    assert float(kept["normalizer.count"]) > count > float(reset["normalizer.count"]) > 0
    old_mean = source[entry]["normalizer.mean"]
    assert (kept["normalizer.mean"] - old_mean).abs().max() < (reset["normalizer.mean"] - old_mean).abs().max()
    assert json.loads((tmp_path / "keep" / "config.json").read_text())["init"]["normalizer"] == "source"
