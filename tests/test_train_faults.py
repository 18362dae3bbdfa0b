"""Training faults: non-finite values, kill -9, a full disk, bad budgets and scenes that do not build.

Each test asserts the exit code, a one-line ``error:`` message without a traceback, that no partial file is left
and that no finished iteration is lost. Runs use a ``tiny`` preset (2 worlds, horizon 4, 16-unit MLPs: 8 frames an
iteration) registered for the test: in this process, or in the ``wristmimic train`` subprocesses through ``BOOT``.
"""

from __future__ import annotations

import csv
import json
import math
import os
import resource
import shutil
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import h5py
import pytest
import torch
from typer.testing import CliRunner

from wristmimic.cli.main import app
from wristmimic.env.vec_env import WristMimicEnv
from wristmimic.errors import InputError
from wristmimic.rl import TrainSpec, preset, resume_run, start_run
from wristmimic.rl import checkpoint as rl_checkpoint
from wristmimic.rl import config as rl_config
from wristmimic.rl import runner as rl_runner
from wristmimic.rl.checkpoint import load_checkpoint
from wristmimic.rl.config import PPOConfig, from_jsonable
from wristmimic.rl.logger import TIME_COLUMNS, MetricsCsv
from wristmimic.rl.networks import ActorCritic
from wristmimic.rl.ppo import PPO
from wristmimic.rl.runner import Runner, TrainingError

from synthetic import converted_intermimic

SID = "sub1_box_000"
TINY = dict(num_envs=2, horizon=4, minibatch_size=8, epochs=1, actor_hidden=(16,), critic_hidden=(16,), eval_every=0)
FRAMES = 8
"""Frames per iteration of the tiny preset."""
ITERATIONS = 10
"""Length of the uninterrupted reference run."""
REPO = Path(__file__).resolve().parents[1]
BOOT = (
    "from wristmimic.rl import config\n"
    f"config.PRESETS['tiny'] = config.preset('cpu', **{TINY!r})\n"
    "from wristmimic.cli.main import app\n"
    "app(prog_name='wristmimic')\n"
)
"""``python -c BOOT train ...`` is ``wristmimic train ...`` with the tiny preset available."""
ENV = {**os.environ, "PYTHONPATH": str(REPO), "OMP_NUM_THREADS": "1"}


@pytest.fixture(scope="module")
def dataset(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return converted_intermimic(tmp_path_factory.mktemp("faults"), T=40)


def _train_args(dataset: Path, out: Path, frames: int) -> list[str]:
    return [str(dataset), "--scene", SID, "--preset", "tiny", "--max-frames", str(frames), "--out", str(out)]


def _common() -> list[str]:
    return ["--nthread", "1", "-q"]


def _subprocess(*args: str, **kw) -> subprocess.CompletedProcess:
    cmd = [sys.executable, "-c", BOOT, "train", *args, *_common()]
    return subprocess.run(cmd, capture_output=True, text=True, env=ENV, timeout=120, **kw)


@pytest.fixture(scope="module")
def reference(dataset: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """An uninterrupted ``wristmimic train`` subprocess of ``ITERATIONS`` iterations (checkpointing each one, the
    default)."""
    out = tmp_path_factory.mktemp("reference")
    r = _subprocess(*_train_args(dataset, out, ITERATIONS * FRAMES))
    assert r.returncode == 0 and f"finished at iteration {ITERATIONS}" in r.stdout, r.stdout + r.stderr
    (run,) = out.iterdir()
    return run


@pytest.fixture
def tiny(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(rl_config.PRESETS, "tiny", preset("cpu", **TINY))


def _rows(run_dir: Path) -> list[dict[str, str]]:
    with open(run_dir / "metrics.csv", newline="") as f:
        return [{k: v for k, v in r.items() if k not in TIME_COLUMNS} for r in csv.DictReader(f)]


def _iterations(run_dir: Path) -> list[int]:
    return [int(r["iteration"]) for r in _rows(run_dir)]


def _complete_rows(path: Path) -> int:
    """Rows of a ``metrics.csv`` being written (complete lines only, header excluded)."""
    try:
        return max(path.read_bytes().count(b"\n") - 1, 0)
    except FileNotFoundError:
        return 0


def _temporaries(folder: Path) -> list[Path]:
    return [p for p in folder.rglob("*") if p.name.endswith(".tmp")]


def _assert_one_line_error(stderr: str, *fragments: str) -> str:
    err = stderr.strip()
    assert err.startswith("error: ") and "\n" not in err and "Traceback" not in err, err
    for f in fragments:
        assert f in err, (f, err)
    return err


def _assert_finite_checkpoint(run_dir: Path) -> dict:
    state = load_checkpoint(run_dir)
    tensors = [*state["policy"].values(), state["obs"]]
    tensors += [v for st in state["optimizer"]["state"].values() for v in st.values() if torch.is_tensor(v)]
    assert all(bool(t.isfinite().all()) for t in tensors if t.is_floating_point())
    return state


def _same_params(a: Path, b: Path) -> bool:
    pa, pb = load_checkpoint(a)["policy"], load_checkpoint(b)["policy"]
    return pa.keys() == pb.keys() and all(torch.equal(pa[k], pb[k]) for k in pa)


# ------------------------------------------------------------------------------------------ kill -9


def test_kill_9_loses_at_most_one_iteration_and_resume_matches_an_uninterrupted_run(
    dataset: Path, reference: Path, tmp_path: Path
) -> None:
    """Default settings (a checkpoint after every iteration, written in the background)."""
    out = tmp_path / "runs"
    args = _train_args(dataset, out, 1000 * FRAMES)
    cmd = [sys.executable, "-c", BOOT, "train", *args, *_common()]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, env=ENV)
    deadline = time.monotonic() + 90
    while not any(_complete_rows(p) >= 3 for p in out.glob("*/metrics.csv")):
        assert proc.poll() is None, proc.stderr.read().decode() if proc.stderr else ""
        assert time.monotonic() < deadline, "no third iteration within 90 s"
        time.sleep(0.01)
    proc.kill()  # SIGKILL: no handler, no cleanup
    proc.wait(timeout=30)
    assert proc.returncode == -signal.SIGKILL
    (run,) = out.iterdir()
    done = _complete_rows(run / "metrics.csv")
    saved = load_checkpoint(run)["iteration"]
    assert 3 <= done and done - 1 <= saved <= done < ITERATIONS  # at most one finished iteration not checkpointed

    r = _subprocess("--resume", str(run), "--max-frames", str(ITERATIONS * FRAMES))
    assert r.returncode == 0 and f"finished at iteration {ITERATIONS}" in r.stdout, r.stdout + r.stderr
    assert _iterations(run) == list(range(1, ITERATIONS + 1))  # each iteration exactly once
    assert _rows(run) == _rows(reference)  # and the same bits as without the kill
    assert _same_params(run, reference)
    assert not _temporaries(run)


SLOW_WRITE = (
    "import os, pathlib, time, torch\n"
    "_save = torch.save\n"
    "def _slow_save(obj, f, *args, **kw):\n"
    "    _save(obj, f, *args, **kw)\n"
    "    if obj.get('iteration') == 3:  # the checkpoint's temporary file is written, not yet synced and renamed\n"
    "        pathlib.Path(os.environ['WRITING']).touch()\n"
    "        time.sleep(60)\n"
    "torch.save = _slow_save\n"
)
"""Prepended to ``BOOT``: the background write of iteration 3 stops inside its temporary file."""


def test_kill_9_during_a_background_write_loses_only_that_iteration(
    dataset: Path, reference: Path, tmp_path: Path
) -> None:
    """SIGKILL while the checkpoint of iteration 3 is being written and iteration 4 waits for it: checkpoint.pt is
    still the one of iteration 2 (the temporary file is dropped on resume), metrics.csv holds rows 1-3 (row 4 waits
    for the write) and the resume repeats iteration 3 bit-for-bit."""
    out, writing = tmp_path / "runs", tmp_path / "writing"
    cmd = [sys.executable, "-c", SLOW_WRITE + BOOT, "train", *_train_args(dataset, out, 1000 * FRAMES), *_common()]
    env = {**ENV, "WRITING": str(writing)}
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, env=env)
    deadline = time.monotonic() + 90
    while not writing.exists():
        assert proc.poll() is None, proc.stderr.read().decode() if proc.stderr else ""
        assert time.monotonic() < deadline, "no write of iteration 3 within 90 s"
        time.sleep(0.01)
    time.sleep(0.5)  # iteration 4 runs meanwhile and waits for the write
    proc.kill()
    proc.wait(timeout=30)
    assert proc.returncode == -signal.SIGKILL
    (run,) = out.iterdir()
    assert _temporaries(run)  # killed inside the write
    assert load_checkpoint(run)["iteration"] == 2 and _complete_rows(run / "metrics.csv") == 3

    r = _subprocess("--resume", str(run), "--max-frames", str(ITERATIONS * FRAMES))
    assert r.returncode == 0 and f"finished at iteration {ITERATIONS}" in r.stdout, r.stdout + r.stderr
    assert _rows(run) == _rows(reference) and _same_params(run, reference)
    assert not _temporaries(run)


# ------------------------------------------------------------------------------------------ full disk


@pytest.mark.parametrize("iterations", [ITERATIONS, 3], ids=["next-iteration", "at-the-end"])
def test_a_checkpoint_write_on_a_full_disk_fails_in_one_line_and_keeps_the_previous_one(
    dataset: Path, reference: Path, tmp_path: Path, iterations: int
) -> None:
    """The background write of iteration 3 fails; the error surfaces in iteration 4, or in the final wait for the
    writer when iteration 3 is the last."""
    out = tmp_path / "runs"
    r = _subprocess(*_train_args(dataset, out, 2 * FRAMES))
    assert r.returncode == 0 and "finished at iteration 2" in r.stdout, r.stderr
    (run,) = out.iterdir()
    before = (run / "checkpoint.pt").read_bytes()
    limit = len(before) // 2  # a checkpoint no longer fits; metrics.csv rows (< 1 kB each) still do
    assert (run / "metrics.csv").stat().st_size * 4 < limit

    def small_files() -> None:
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # EFBIG from write(), as on a full disk, not a core dump

    r = _subprocess("--resume", str(run), "--max-frames", str(iterations * FRAMES), preexec_fn=small_files)
    assert r.returncode == 1, r.stdout + r.stderr
    _assert_one_line_error(
        r.stderr, str(run), "iteration 3: checkpoint.pt not written", "last good checkpoint kept at iteration 2"
    )
    assert (run / "checkpoint.pt").read_bytes() == before
    assert not _temporaries(run)
    assert _rows(run) == _rows(reference)[:2]  # the row of iteration 3 went with its checkpoint
    assert _assert_finite_checkpoint(run)["iteration"] == 2  # a resume continues from here (as after a kill)


def test_a_warm_start_whose_source_copy_does_not_fit_fails_in_one_line_and_leaves_no_folder(
    dataset: Path, reference: Path, tmp_path: Path
) -> None:
    """``--init-from`` keeps a copy of the source checkpoint as the run's ``init.pt``; on a full disk the start stops
    with one line naming the source and leaves no run folder, and with room the same start keeps the copy."""
    limit = (reference / "checkpoint.pt").stat().st_size // 2  # config.json fits, a checkpoint copy does not

    def small_files() -> None:
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)

    out = tmp_path / "runs"
    args = [*_train_args(dataset, out, FRAMES), "--init-from", str(reference), "--init-weights", "latest"]
    r = _subprocess(*args, preexec_fn=small_files)
    assert r.returncode == 1, r.stdout + r.stderr
    err = _assert_one_line_error(r.stderr, "checkpoint.pt")
    assert "cannot be copied" in err or "not written" in err, err
    assert not out.exists() or not any(out.iterdir())
    r = _subprocess(*args)
    assert r.returncode == 0, r.stderr
    (run,) = out.iterdir()
    assert (run / "init.pt").read_bytes() == (reference / "checkpoint.pt").read_bytes()


def test_a_metrics_row_that_does_not_fit_is_cut_off(tmp_path: Path) -> None:
    """A real file-size limit in a subprocess: rows are appended until one does not fit; the file ends with the
    last complete row and the error is one line."""
    path = tmp_path / "metrics.csv"
    code = (
        "import sys\nfrom pathlib import Path\nfrom wristmimic.errors import InputError\n"
        "from wristmimic.rl.logger import MetricsCsv\n"
        f"m = MetricsCsv(Path({str(path)!r}))\n"
        "for i in range(1, 1000):\n"
        "    try:\n"
        "        m.write({'iteration': i, 'frames': 8 * i, 'reward_mean': 0.123456789 * i, 'pad': 'x' * 50})\n"
        "    except InputError as exc:\n"
        "        print(exc, file=sys.stderr); sys.exit(1)\n"
    )

    def small_files() -> None:
        resource.setrlimit(resource.RLIMIT_FSIZE, (2000, 2000))
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)

    r = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, env=ENV, preexec_fn=small_files, timeout=60
    )
    assert r.returncode == 1 and "\n" not in r.stderr.strip() and "Traceback" not in r.stderr, r.stderr
    assert "not written (File too large)" in r.stderr
    data = path.read_bytes()
    assert 0 < len(data) <= 2000 and data.endswith(b"\r\n")
    rows = list(csv.reader(data.decode().splitlines()))
    assert all(len(row) == 4 for row in rows) and [int(row[0]) for row in rows[1:]] == list(range(1, len(rows)))
    assert f"row of iteration {len(rows)} not written" in r.stderr


# ------------------------------------------------------------------------------------------ non-finite values


def _inject(monkeypatch: pytest.MonkeyPatch, what: str, iteration: int) -> None:
    """Make ``what`` non-finite in world 0 (or 1) during ``iteration`` (1-based) of a tiny run."""
    horizon = TINY["horizon"]
    calls = {"step": 0, "act": 0}

    def in_iteration(kind: str) -> bool:
        calls[kind] += 1
        return (calls[kind] - 1) // horizon == iteration - 1

    if what in ("reward", "observation"):
        step = WristMimicEnv.step

        def bad_step(self: WristMimicEnv, action: torch.Tensor):
            obs, reward, terminated, truncated, info = step(self, action)
            if in_iteration("step"):
                if what == "reward":
                    reward = reward.clone()
                    reward[0] = math.nan
                else:
                    obs = obs.clone()
                    obs[1, 5] = math.inf
            return obs, reward, terminated, truncated, info

        monkeypatch.setattr(WristMimicEnv, "step", bad_step)
    elif what == "action":
        act = ActorCritic.act

        def bad_act(self: ActorCritic, obs_n: torch.Tensor, *args, **kw):
            actions, log_probs, mu, values = act(self, obs_n, *args, **kw)
            if in_iteration("act"):
                actions = actions.clone()
                actions[0, 3] = math.nan
            return actions, log_probs, mu, values

        monkeypatch.setattr(ActorCritic, "act", bad_act)
    else:  # a loss, or the parameters after the update
        update = PPO.update
        done = {"n": 0}

        def bad_update(self: PPO, storage, generator):
            out = update(self, storage, generator)
            done["n"] += 1
            if done["n"] == iteration:
                if what == "loss":
                    out["loss/value"] = math.nan
                else:
                    with torch.no_grad():
                        self.policy.actor[0].weight[0, 0] = math.inf
            return out

        monkeypatch.setattr(PPO, "update", bad_update)


@pytest.mark.parametrize(
    ("what", "iteration", "message"),
    [
        ("observation", 2, "observation is non-finite in 1 of 2 worlds"),
        ("action", 3, "action is non-finite in 1 of 2 worlds"),
        ("reward", 2, "reward is non-finite in 1 of 2 worlds"),
        ("loss", 2, "loss/value is non-finite"),
        ("parameter", 3, "policy parameter actor.0.weight is non-finite after the update"),
    ],
)
def test_non_finite_values_stop_training_with_the_last_good_checkpoint(
    dataset: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, tiny: None, what: str, iteration: int, message: str
) -> None:
    _inject(monkeypatch, what, iteration)
    out = tmp_path / "runs"
    args = ["train", *_train_args(dataset, out, 6 * FRAMES), *_common()]
    r = CliRunner().invoke(app, args)
    assert r.exit_code == 1, r.output
    (run,) = out.iterdir()
    good = iteration - 1
    _assert_one_line_error(
        r.stderr, f"{run}: iteration {iteration}: {message}", f"(last good checkpoint kept at iteration {good})"
    )
    assert _assert_finite_checkpoint(run)["iteration"] == good
    assert _iterations(run) == list(range(1, good + 1))
    assert not _temporaries(run)


def test_after_a_non_finite_reward_metrics_match_the_checkpoint_and_resume_loses_nothing(
    dataset: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Checkpoints only after iteration 1 (60 s, every 20, as configs from before asynchronous checkpoints): a NaN
    in iteration 4 cuts metrics.csv back to row 1, and a resume without the fault gives the rows of a clean run."""
    spec = TrainSpec(dataset, SID, ppo=preset("cpu", **TINY, max_frames=5 * FRAMES, checkpoint_seconds=60.0))
    start_run(spec, tmp_path / "clean", nthread=1, progress=False)
    with monkeypatch.context() as m:
        _inject(m, "reward", 4)
        with pytest.raises(TrainingError) as info:
            start_run(spec, tmp_path / "nan", nthread=1, progress=False)
    assert str(info.value) == (
        f"{tmp_path / 'nan'}: iteration 4: reward is non-finite in 1 of 2 worlds "
        "(last good checkpoint kept at iteration 1)"
    )
    assert _assert_finite_checkpoint(tmp_path / "nan")["iteration"] == 1 and _iterations(tmp_path / "nan") == [1]
    assert resume_run(tmp_path / "nan", nthread=1, progress=False).iteration == 5
    assert _rows(tmp_path / "nan") == _rows(tmp_path / "clean")
    assert _same_params(tmp_path / "nan", tmp_path / "clean")


def test_a_failure_in_the_first_iteration_leaves_no_run_folder(
    dataset: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, tiny: None
) -> None:
    _inject(monkeypatch, "observation", 1)
    out = tmp_path / "out" / "runs"
    r = CliRunner().invoke(app, ["train", *_train_args(dataset, out, 4 * FRAMES), *_common()])
    assert r.exit_code == 1, r.output
    _assert_one_line_error(
        r.stderr, "iteration 1: observation is non-finite in 1 of 2 worlds", "(no checkpoint yet: run folder removed)"
    )
    assert not (tmp_path / "out").exists()


def test_save_refuses_a_non_finite_state(dataset: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Even past the per-iteration check, nothing non-finite reaches checkpoint.pt."""
    spec = TrainSpec(dataset, SID, ppo=preset("cpu", **TINY, max_frames=3 * FRAMES))
    monkeypatch.setattr(Runner, "check_finite", lambda self, iteration, losses: None)
    _inject(monkeypatch, "parameter", 2)
    with pytest.raises(TrainingError, match=r"iteration 2: policy parameter actor.0.weight is non-finite: checkpoint"):
        start_run(spec, tmp_path / "run", nthread=1, progress=False)
    assert _assert_finite_checkpoint(tmp_path / "run")["iteration"] == 1 and _iterations(tmp_path / "run") == [1]


# ------------------------------------------------------------------------------------------ checkpoint cadence


@pytest.mark.parametrize(
    ("settings", "expected"),
    [
        ({}, [1, 2, 3, 4, 5, 6, 7, 8, 9]),  # the default: after every iteration (once at the end)
        ({"checkpoint_every": 4, "checkpoint_seconds": 60.0}, [1, 4, 7, 8, 9]),  # 1: first; 4, 8: every 4; 7: 75 s
    ],  # after the one at 4; 9: the end
    ids=["default", "every-4-or-60s"],
)
def test_checkpoints_after_the_first_iteration_then_by_time_and_by_count(
    dataset: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, settings: dict, expected: list[int]
) -> None:
    now = {"t": 0.0}
    monkeypatch.setattr(rl_runner, "_clock", lambda: now["t"])
    collect, save = Runner.collect, Runner.save
    saved: list[int] = []

    def slow_collect(self: Runner) -> dict:
        now["t"] += 25.0  # every iteration takes 25 s
        return collect(self)

    def record_save(self: Runner, wait: bool = True) -> Path:
        saved.append(self.iteration)
        return save(self, wait)

    monkeypatch.setattr(Runner, "collect", slow_collect)
    monkeypatch.setattr(Runner, "save", record_save)
    ppo = preset("cpu", **TINY, max_frames=9 * FRAMES, **settings)
    start_run(TrainSpec(dataset, SID, ppo=ppo), tmp_path / "run", nthread=1, progress=False)
    assert saved == expected
    assert load_checkpoint(tmp_path / "run")["iteration"] == 9


def test_checkpoints_are_written_in_the_background_one_at_a_time(
    dataset: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A slow write (0.5 s) of iteration k runs in another thread while iteration k + 1 collects; the next write
    starts only after it; when it lands, metrics.csv holds exactly the rows up to k (row k + 1 waits for it)."""
    run = tmp_path / "run"
    events: list[tuple[str, int]] = []
    writes = {"in_flight": 0, "most": 0, "main_thread": 0}
    write, collect = rl_checkpoint.save_checkpoint, Runner.collect

    def slow_write(path: Path, state: dict) -> None:
        k = state["iteration"]
        writes["in_flight"] += 1
        writes["most"] = max(writes["most"], writes["in_flight"])
        writes["main_thread"] += threading.current_thread() is threading.main_thread()
        time.sleep(0.5)
        write(path, state)
        events.append(("written", k))
        assert _complete_rows(run / "metrics.csv") == k
        writes["in_flight"] -= 1

    def recording_collect(self: Runner) -> dict:
        events.append(("collect", self.iteration + 1))
        return collect(self)

    monkeypatch.setattr(rl_checkpoint, "save_checkpoint", slow_write)
    monkeypatch.setattr(Runner, "collect", recording_collect)
    ppo = preset("cpu", **TINY, max_frames=4 * FRAMES)
    assert start_run(TrainSpec(dataset, SID, ppo=ppo), run, nthread=1, progress=False).iteration == 4
    assert events == [("collect", 1)] + [e for k in (1, 2, 3) for e in (("collect", k + 1), ("written", k))] + [
        ("written", 4)
    ]
    assert writes == {"in_flight": 0, "most": 1, "main_thread": 0}
    assert load_checkpoint(run)["iteration"] == 4 and _iterations(run) == [1, 2, 3, 4] and not _temporaries(run)


def test_configs_from_before_asynchronous_checkpoints_still_load() -> None:
    """Runs recorded checkpoint_every and checkpoint_seconds = 60 (kept: a resume keeps their cadence); older
    ones recorded neither (the default: every iteration)."""
    fields = {k: v for k, v in rl_config.to_jsonable(preset("cpu")).items() if not k.startswith("checkpoint_")}
    old = from_jsonable(PPOConfig, {**fields, "checkpoint_every": 20, "checkpoint_seconds": 60.0})
    assert (old.checkpoint_every, old.checkpoint_seconds) == (20, 60.0)
    assert from_jsonable(PPOConfig, fields).checkpoint_seconds == 0.0 == preset("cpu").checkpoint_seconds
    assert preset("paper").checkpoint_seconds == 0.0


# ------------------------------------------------------------------------------------------ bad budgets and scenes


@pytest.mark.parametrize("frames", ["0", "-5"])
def test_a_non_positive_budget_is_refused_before_anything_is_written(
    dataset: Path, tmp_path: Path, frames: str
) -> None:
    out = tmp_path / "runs"
    r = CliRunner().invoke(app, ["train", str(dataset), "--scene", SID, "--max-frames", frames, "-o", str(out), "-q"])
    assert r.exit_code == 1
    _assert_one_line_error(r.stderr, f"--max-frames: {frames}", "positive")
    assert not out.exists()
    spec = TrainSpec(dataset, SID, ppo=preset("cpu", **TINY, max_frames=int(frames)))
    with pytest.raises(InputError, match="max_frames"):
        start_run(spec, out / "run", progress=False)
    assert not out.exists()


def test_resume_with_a_non_positive_budget_is_refused(reference: Path, tmp_path: Path) -> None:
    run = tmp_path / "run"
    shutil.copytree(reference, run)
    before = {p.name: p.read_bytes() for p in run.iterdir()}
    r = CliRunner().invoke(app, ["train", "--resume", str(run), "--max-frames", "0", "-q"])
    assert r.exit_code == 1
    _assert_one_line_error(r.stderr, "--max-frames: 0")
    assert {p.name: p.read_bytes() for p in run.iterdir()} == before


def test_a_scene_that_does_not_build_leaves_no_run_folder(dataset: Path, tmp_path: Path) -> None:
    broken = tmp_path / "broken.h5"
    shutil.copy(dataset, broken)
    with h5py.File(broken, "a") as f:
        for g in f["humanoids"].values():
            del g["mjcf"]
            g.create_dataset("mjcf", data="<mujoco><worldbody><geom type='bogus'/></worldbody></mujoco>")
    out = tmp_path / "runs"
    r = CliRunner().invoke(app, ["train", str(broken), "--scene", SID, "--max-frames", "64", "-o", str(out), "-q"])
    assert r.exit_code == 1, r.output
    _assert_one_line_error(r.stderr, "broken.h5", "mjcf")
    assert not out.exists()


def test_a_failure_before_the_first_iteration_removes_the_folder_it_created(
    dataset: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, tiny: None
) -> None:
    def fail(self: Runner, progress: bool = False) -> None:
        raise InputError(self.run_dir, "feedforward", "search failed")

    monkeypatch.setattr(Runner, "optimise_feedforward", fail)
    out = tmp_path / "runs"
    r = CliRunner().invoke(app, ["train", *_train_args(dataset, out, 4 * FRAMES), *_common()])
    assert r.exit_code == 1
    _assert_one_line_error(r.stderr, "feedforward: search failed")
    assert not out.exists()


@pytest.mark.parametrize(
    ("change", "fragments"),
    [
        ("network", ("policy.actor.0.weight: shape [16, ", "(expected shape [32, ", "actor [32]")),
        ("obs", ("obs: shape [3, 7] (expected a tensor of shape [2, ",)),
    ],
)
def test_resume_with_a_checkpoint_that_does_not_fit_fails_in_one_line(
    reference: Path, tmp_path: Path, change: str, fragments: tuple[str, ...]
) -> None:
    """Weights of another network size (the checkpoint's config says 32 units, its weights have 16), or saved
    observations of another shape: one line naming the file and the entry, and the run folder is left as it was."""
    run = tmp_path / "run"
    shutil.copytree(reference, run)
    state = torch.load(run / "checkpoint.pt", weights_only=True, map_location="cpu")
    if change == "network":
        config = json.loads(state["config"])
        config["ppo"]["actor_hidden"] = [32]
        state["config"] = json.dumps(config)
    else:
        state["obs"] = torch.zeros(3, 7)
    torch.save(state, run / "checkpoint.pt")
    before = {p.name: p.read_bytes() for p in run.iterdir()}
    r = CliRunner().invoke(app, ["train", "--resume", str(run), "--max-frames", str(12 * FRAMES), *_common()])
    assert r.exit_code == 1, r.output
    _assert_one_line_error(r.stderr, f"{run / 'checkpoint.pt'}: ", *fragments)
    assert {p.name: p.read_bytes() for p in run.iterdir()} == before


# ------------------------------------------------------------------------------------------ left-overs of a kill


def test_a_run_killed_in_its_first_iteration_is_started_again_not_resumed(dataset: Path, tmp_path: Path) -> None:
    """A folder with config.json, a partial metrics.csv and an atomic write's temporary file but no checkpoint."""
    spec = TrainSpec(dataset, SID, ppo=preset("cpu", **TINY, max_frames=2 * FRAMES))
    run = tmp_path / "run"
    start_run(spec, run, nthread=1, progress=False)
    (run / "checkpoint.pt").unlink()
    (run / ".checkpoint.pt.x1y2.pt.tmp").write_bytes(b"half a checkpoint")
    with open(run / "metrics.csv", "ab") as f:
        f.write(b"3,24,0.5")
    r = CliRunner().invoke(app, ["train", "--resume", str(run), "-q"])
    assert r.exit_code == 1
    _assert_one_line_error(r.stderr, str(run), "no checkpoint: the run stopped in its first iteration", "start it")
    assert start_run(spec, run, nthread=1, progress=False).iteration == 2
    assert _iterations(run) == [1, 2] and not _temporaries(run)
    with pytest.raises(InputError, match="already holds a run"):
        start_run(spec, run, nthread=1, progress=False)


def test_resume_drops_rows_after_the_checkpoint_and_a_half_written_row(tmp_path: Path) -> None:
    path = tmp_path / "metrics.csv"
    m = MetricsCsv(path)
    for i in range(1, 5):
        m.write({"iteration": i, "frames": 8 * i, "reward_mean": 0.5})
    with open(path, "ab") as f:
        f.write(b"1")  # a kill while writing iteration 5 (its first byte parses as iteration 1)
    MetricsCsv(path, keep_until=4)
    assert [r["iteration"] for r in csv.DictReader(path.read_text().splitlines())] == ["1", "2", "3", "4"]
    m = MetricsCsv(path, keep_until=2)
    m.write({"iteration": 3, "frames": 24, "reward_mean": 0.25})
    rows = list(csv.DictReader(path.read_text().splitlines()))
    assert [(r["iteration"], r["reward_mean"]) for r in rows] == [("1", "0.5"), ("2", "0.5"), ("3", "0.25")]
