"""``wristmimic run --ray``: a 2-scene pipeline on a local Ray (2 CPUs) writes the same run and evaluation folders
and the same report as the serial run; a second run dispatches nothing; the export stage's files validate; a
failing job is reported with its error and the others are kept; bad addresses and a missing Ray fail with one
line; ray is imported only for --ray."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pandas as pd
import pytest
import torch
from typer.testing import CliRunner

from wristmimic.cli.main import app
from wristmimic.convert.common import ConvertOptions
from wristmimic.convert.intermimic import convert_intermimic
from wristmimic.distributed import RayOptions
from wristmimic.errors import InputError
from wristmimic.safe_io import sha256_file

from synthetic import tiny_ppo_toml, write_intermimic_folder

ray = pytest.importorskip("ray")
REPO = Path(__file__).resolve().parents[1]
SCENES = ("sub1_box_000", "sub2_box_001")
LOCAL = ["--ray", "local", "--ray-local-cpus", "2", "-q"]


@pytest.fixture(scope="module")
def tiny_h5(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Two synthetic InterMimic sequences converted once (so every pipeline here trains the same file)."""
    tmp = tmp_path_factory.mktemp("ray_data")
    src = write_intermimic_folder(tmp / "src", SCENES, T=30)
    out = tmp / "tiny.h5"
    convert_intermimic(src, out, options=ConvertOptions(hull_cache_dir=tmp / "hulls", show_progress=False))
    return out


@pytest.fixture(autouse=True)
def _ray_cleanup(tmp_path: Path, monkeypatch: pytest.MonkeyPatch):
    """Workers keep their dataset copies under the test's folder; no Ray is left running after a test."""
    monkeypatch.setenv("WRISTMIMIC_CACHE_DIR", str(tmp_path / "cache"))
    yield
    if ray.is_initialized():
        ray.shutdown()


def _spec(tmp: Path, h5: Path, scenes: str = '"all"') -> Path:
    spec = tmp / "tiny.toml"
    spec.write_text(
        f"""
[pipeline]
name = "tiny"
work_dir = "{tmp / "work"}"
[train]
dataset = "{h5}"
scenes = {scenes}
seed = 3
{tiny_ppo_toml(64)}
[evaluate]
protocol = "quick"
trials = 4
num_envs = 2
[report]
output = "{tmp / "report"}"
"""
    )
    return spec


def _run(*args: str) -> tuple[int, str]:
    r = CliRunner().invoke(app, ["run", *args])
    return r.exit_code, r.output


def _files(root: Path) -> set[str]:
    return {p.relative_to(root).as_posix() for p in root.rglob("*") if p.is_file()}


def _same(x: object, y: object, where: str = "") -> None:
    if isinstance(x, dict):
        assert isinstance(y, dict) and set(x) == set(y), where
        for k in x:
            _same(x[k], y[k], f"{where}/{k}")
    elif isinstance(x, torch.Tensor):
        assert isinstance(y, torch.Tensor) and torch.equal(x, y), where
    else:
        assert x == y, where


def _same_checkpoint(a: Path, b: Path) -> None:
    """Equal except the wall-clock fields and numpy's global RNG state (seeded from the OS by each process and
    not used by training)."""
    x, y = (torch.load(p, weights_only=True) for p in (a, b))
    cx, cy = (json.loads(c.pop("config")) for c in (x, y))
    assert cx.pop("created") and cy.pop("created")
    _same(cx, cy)
    for c in (x, y):
        c.pop("seconds")
        c["rng"] = {k: v for k, v in c["rng"].items() if not k.startswith("numpy")}
    _same(x, y)


def test_ray_local_matches_serial_and_a_second_run_dispatches_nothing(tmp_path: Path, tiny_h5: Path) -> None:
    spec = _spec(tmp_path, tiny_h5)
    work, report = tmp_path / "work", tmp_path / "report"
    code, out = _run(str(spec), "-q", "--nthread", "1")
    assert code == 0 and "5 ran, 0 up to date" in out, out
    serial_work, serial_report = tmp_path / "serial_work", tmp_path / "serial_report"
    work.rename(serial_work), report.rename(serial_report)

    code, out = _run(str(spec), *LOCAL)
    assert code == 0, out
    assert "ray: 2 job(s) dispatched (1 CPU, 0 GPU each)" in out and "5 ran, 0 up to date" in out
    assert "jobs 2 done, 0 running or queued, 0 failed (of 2)" in out
    # the workers read their own copy, fetched from the object store (no shared filesystem assumed)
    assert (tmp_path / "cache" / "datasets" / f"{sha256_file(tiny_h5)}.h5").is_file()

    # the same folders and files; the report byte for byte; the trial tables byte for byte
    assert _files(work) == _files(serial_work)
    runs = sorted(p.name for p in (work / "runs").iterdir())
    assert [r.split("-")[0] for r in runs] == list(SCENES) and all("-seed3-" in r for r in runs)
    assert _files(report) == _files(serial_report) and "summary.md" in _files(report)
    for f in _files(report):
        assert (report / f).read_bytes() == (serial_report / f).read_bytes(), f
    for run in runs:
        ra, rb = work / "runs" / run, serial_work / "runs" / run
        for f in ("eval/quick/summary.csv", *(f"eval/quick/{s}.parquet" for s in SCENES if run.startswith(s))):
            assert (ra / f).read_bytes() == (rb / f).read_bytes(), f
        assert len(pd.read_parquet(ra / "eval" / "quick" / f"{run.split('-')[0]}.parquet")) == 4
        _same_checkpoint(ra / "checkpoint.pt", rb / "checkpoint.pt")
        ma, mb = (pd.read_csv(r / "metrics.csv").drop(columns=["seconds", "frames_per_s"]) for r in (ra, rb))
        pd.testing.assert_frame_equal(ma, mb)
        sa, sb = (json.loads((r / "eval" / "quick" / "summary.json").read_text()) for r in (ra, rb))
        assert sa["policy"]["run_dir"] == str(ra.resolve()) and sa["policy"]["train_seed"] == 3
        for s in (sa, sb):
            s["policy"].pop("run_dir"), s["policy"].pop("checkpoint_sha256"), s["settings"].pop("checkpoint_sha256")
        assert sa == sb

    stamps = {p: p.stat().st_mtime_ns for p in work.rglob("*") if p.is_file()}
    code, out = _run(str(spec), *LOCAL)
    assert code == 0 and "0 ran, 5 up to date" in out and "dispatched" not in out, out
    assert {p: p.stat().st_mtime_ns for p in stamps} == stamps


def test_export_stage_after_ray_jobs_writes_files_that_validate(tmp_path: Path, tiny_h5: Path) -> None:
    """The [export] stage runs on the driver once the Ray jobs have brought their runs and evaluations back: it
    replays the evaluations' first rows, its files validate and name their checkpoints, and the report stage
    adds their plausibility."""
    from wristmimic.format.reader import open_dataset
    from wristmimic.format.validate import validate

    spec = _spec(tmp_path, tiny_h5)
    spec.write_text(spec.read_text().replace("[report]", "[export]\ntrials = 2\nnum_envs = 2\n[report]"))
    code, out = _run(str(spec), *LOCAL)
    assert code == 0, out
    assert "ray: 2 job(s) dispatched" in out and "7 ran, 0 up to date" in out, out
    work = tmp_path / "work"
    for scene in SCENES:
        (run,) = (r for r in (work / "runs").iterdir() if r.name.startswith(scene))
        out_h5 = work / "export" / f"{scene}.h5"
        assert validate(out_h5) == [], scene
        with open_dataset(out_h5) as ds:
            root = json.loads(ds.attrs["export"])
            assert root["mode"] == "from-eval" and root["from_eval"] == str((run / "eval" / "quick").resolve())
            assert root["checkpoint_sha256"] == sha256_file(run / "checkpoint.pt") and root["trials"] == 2
            seeds = pd.read_parquet(run / "eval" / "quick" / f"{scene}.parquet")["seed"].tolist()[:2]
            assert ds.sequence_ids == sorted(f"{scene}__sim_{s}" for s in seeds)
    plaus = pd.read_csv(tmp_path / "report" / "plausibility.csv")
    assert plaus["scene"].tolist() == list(SCENES) and plaus["sim_sequences"].tolist() == [2, 2]
    code, out = _run(str(spec), *LOCAL)
    assert code == 0 and "0 ran, 7 up to date" in out and "dispatched" not in out, out


@pytest.mark.slow  # ~20-40 s on 2 cores; CI runs it with -m slow
def test_a_failing_job_is_reported_and_the_others_kept(tmp_path: Path, tiny_h5: Path) -> None:
    spec = _spec(tmp_path, tiny_h5, scenes='["sub1_box_000", "no_such_scene"]')
    code, out = _run(str(spec), *LOCAL)
    assert code == 1, out
    assert "1 of 2 dispatched job(s) failed" in out and "jobs 1 done, 0 running or queued, 1 failed (of 2)" in out
    assert f"FAILED: {tiny_h5}: sequences/no_such_scene: no such sequence" in out, out  # the driver's path
    (good,) = (tmp_path / "work" / "runs").iterdir()
    assert good.name.startswith("sub1_box_000") and (good / "eval" / "quick" / "sub1_box_000.parquet").is_file()
    state = json.loads((tmp_path / "work" / "pipeline_state.json").read_text())
    assert {"train sub1_box_000", f"evaluate {good.name}"} <= set(state) and "train no_such_scene" not in state
    assert not (tmp_path / "report").exists()

    # the next runs reuse a Ray started here (as a notebook would); the driver leaves it running
    root = str(REPO)
    ray.init(address="local", num_cpus=2, include_dashboard=False, runtime_env={"env_vars": {"PYTHONPATH": root}})
    scenes = f"{list(SCENES)}".replace("'", '"')
    bad = (
        spec.read_text()
        .replace('["sub1_box_000", "no_such_scene"]', scenes)
        .replace("[report]", 'noise = "bogus"\n[report]')
    )
    spec.write_text(bad)
    code, out = _run(str(spec), *LOCAL)  # sub2 trains, then every evaluation fails on the bad noise mode
    assert code == 1 and "ray: using the running Ray (2 CPU)" in out and "2 of 2 dispatched job(s) failed" in out
    assert "--noise: 'bogus'" in out and "train sub2_box_001: ran" in out, out
    assert ray.is_initialized()
    spec.write_text(spec.read_text().replace('noise = "bogus"\n', ""))
    code, out = _run(str(spec), *LOCAL)  # sub1 all up to date; sub2's checkpoint came back: only evaluated
    assert code == 0, out
    assert "ray: 1 job(s) dispatched" in out and "train sub1_box_000: up to date" in out, out
    assert "train sub2_box_001: up to date" in out and "trained" not in out.split("dispatched")[1], out
    assert "2 ran, 3 up to date" in out and (tmp_path / "report" / "summary.md").is_file()


def test_bad_addresses_and_a_missing_ray_fail_with_one_line(
    tmp_path: Path, tiny_h5: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    spec = _spec(tmp_path, tiny_h5)
    code, out = _run(str(spec), "--ray", "nonsense")
    assert code == 1 and "error: --ray nonsense: not an address" in out, out
    code, out = _run(str(spec), "--ray", "127.0.0.1:1", "-q")
    assert code == 1 and "error: --ray 127.0.0.1:1: cannot connect to 127.0.0.1:1" in out, out
    code, out = _run(str(spec), "--ray", "local", "--ray-cpus-per-job", "64", "-q")
    assert code == 1 and "--ray-cpus-per-job: 64 CPUs per job" in out, out
    assert not ray.is_initialized()
    monkeypatch.setitem(sys.modules, "ray", None)  # as if not installed
    code, out = _run(str(spec), "--ray", "local")
    assert code == 1 and "pip install 'wristmimic[ray]'" in out and len(out.strip().splitlines()) == 1, out


def test_ray_is_imported_only_for_ray_runs() -> None:
    code = "import sys, wristmimic.cli.main, wristmimic.pipeline, wristmimic.distributed; print('ray' in sys.modules)"
    r = subprocess.run([sys.executable, "-c", code], cwd=REPO, capture_output=True, text=True, check=True)
    assert r.stdout.strip() == "False"


def test_job_resources_come_from_the_options_then_the_pipeline_file_then_nthread() -> None:
    o = RayOptions("local")
    assert (o.resolved({}, None).cpus_per_job, o.resolved({}, None).gpus_per_job) == (1, 0)
    assert o.resolved({}, 3).cpus_per_job == 3
    assert o.resolved({"ray_cpus_per_job": 2, "ray_gpus_per_job": 0.5}, 3) == RayOptions("local", 2, 0.5)
    assert RayOptions("local", 4, 1).resolved({"ray_cpus_per_job": 2, "ray_gpus_per_job": 0}, 3) == RayOptions(
        "local", 4, 1.0
    )
    for bad in ({"ray_cpus_per_job": 0}, {"ray_cpus_per_job": "2"}, {"ray_gpus_per_job": -1}):
        with pytest.raises(InputError, match="pipeline.ray_"):
            o.resolved(bad, None)


def test_a_node_running_other_code_refuses_the_job(tmp_path: Path, tiny_h5: Path) -> None:
    """The task body run in-process: a worker whose wristmimic sources differ from the driver's fails at once."""
    from wristmimic.distributed import JobWork, code_fingerprint, run_job
    from wristmimic.pipeline import Context, plan_jobs

    (job,) = plan_jobs(
        Context(tmp_path / "p.toml", tmp_path / "work"), {"dataset": str(tiny_h5), "scenes": [SCENES[0]]}
    )
    sha = job.inputs["dataset_sha256"]
    res = run_job(JobWork(job, str(job.run_dir), sha, True, None, None, 1, "0.1.0+000000000000"), [None], None)
    assert not res.ok and res.archive is None and not res.trained
    assert f"runs wristmimic {code_fingerprint()}" in res.error and "install the same code on every node" in res.error


@pytest.mark.slow  # ~20-40 s on 2 cores; CI runs it with -m slow
def test_ctrl_c_stops_jobs_keeping_their_checkpoints_and_a_rerun_resumes(tmp_path: Path, tiny_h5: Path) -> None:
    """Ctrl-C on the driver (SIGINT just after dispatch): the job stops after a training iteration, the driver
    brings back its checkpoint and exits with KeyboardInterrupt; running again resumes it to the end."""
    import os
    import signal
    import threading

    from wristmimic.pipeline import run_pipeline

    spec = _spec(tmp_path, tiny_h5, scenes='["sub1_box_000"]')
    spec.write_text(spec.read_text().replace("max_frames = 64", "max_frames = 400"))  # 50 iterations
    lines: list[str] = []

    def echo(line: str) -> None:
        lines.append(line)
        if "job(s) dispatched" in line:  # Ctrl-C while the driver waits (workers are still starting)
            # 0.05 s: with warm Ray workers a 50-iteration job can end within 0.3 s of dispatch (seen in full
            # suite runs), and then there is nothing left to stop
            threading.Timer(0.05, os.kill, (os.getpid(), signal.SIGINT)).start()

    options = RayOptions("local", 1, 0, 2)
    # Ctrl-C as a terminal delivers it: a shell's background job (`.ci/run &`) starts with SIGINT ignored
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        with pytest.raises(KeyboardInterrupt):
            run_pipeline(spec, progress=False, nthread=1, echo=echo, ray=options)
    finally:
        signal.signal(signal.SIGINT, previous)
    assert any("Ctrl-C: every job stops" in s for s in lines), lines
    assert any("stopped: stopped at iteration" in s for s in lines), lines
    (run,) = (tmp_path / "work" / "runs").iterdir()
    first = torch.load(run / "checkpoint.pt", weights_only=True)["iteration"]
    assert 1 <= first < 50
    state_file = tmp_path / "work" / "pipeline_state.json"
    state = json.loads(state_file.read_text()) if state_file.exists() else {}
    assert "train sub1_box_000" not in state  # not recorded: the next run resumes it

    ray.shutdown()
    lines.clear()
    ctx = run_pipeline(spec, progress=False, nthread=1, echo=lines.append, ray=options)
    assert dict(ctx.summary)["train sub1_box_000"] == "ran", lines
    assert torch.load(run / "checkpoint.pt", weights_only=True)["iteration"] == 50
    assert pd.read_csv(run / "metrics.csv")["iteration"].tolist() == list(range(1, 51))
    assert len(pd.read_parquet(run / "eval" / "quick" / "sub1_box_000.parquet")) == 4
