"""Write faults, for real: ``convert``, ``synth`` and ``evaluate`` run in a subprocess whose file size limit
(``RLIMIT_FSIZE``) makes their output writes fail with EFBIG, as a full disk fails them with ENOSPC, and
``convert`` is killed with SIGKILL. Each case asserts the exit code, the one-line ``error:`` message (no
traceback, no segfault), that no temporary or partial file is left, and that nothing completed is lost.

The child keeps Python's start-up disposition of SIGXFSZ (ignored), so a write past the limit returns EFBIG instead
of killing the process: exactly what a user's shell with ``ulimit -f`` gets.
"""

from __future__ import annotations

import json
import os
import resource
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pandas as pd
import pytest

from wristmimic.safe_io import _HOST, STALE_AFTER_S, remove_stale_temporaries

from conftest import REPO, same_h5, temporaries
from synthetic import converted_intermimic, write_intermimic_folder

SID = "sub1_box_000"
TOO_LARGE = "could not write (File too large)"


def _wristmimic(*args: str | Path, fsize: int | None = None, timeout: float = 180) -> subprocess.CompletedProcess:
    """``wristmimic ARGS`` in a fresh interpreter, with the file size limit ``fsize`` (bytes) if given."""
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(p for p in (str(REPO), os.environ.get("PYTHONPATH")) if p)}

    def limit() -> None:
        resource.setrlimit(resource.RLIMIT_FSIZE, (fsize, fsize))

    return subprocess.run(
        [sys.executable, "-m", "wristmimic.cli.main", *map(str, args)],
        env=env,
        capture_output=True,
        text=True,
        timeout=timeout,
        preexec_fn=limit if fsize is not None else None,
    )


def _assert_write_error(r: subprocess.CompletedProcess, path: Path) -> None:
    """Exit 1 (not a signal: -11 segfault, -25 SIGXFSZ), one ``error:`` line naming ``path``, no traceback."""
    out = r.stdout + r.stderr
    assert r.returncode == 1, (r.returncode, out[-3000:])
    assert "Traceback" not in out and "Exception ignored" not in out, out[-3000:]
    err = r.stderr.strip()
    assert err.startswith("error: ") and "\n" not in err, err
    assert f"{path}: {TOO_LARGE}" in err, err


# ------------------------------------------------------------------------------------------------- convert


@pytest.fixture(scope="module")
def im(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path, Path]:
    """(source folder, warm hull cache, reference output): the only file a conversion then writes is its output."""
    tmp = tmp_path_factory.mktemp("im")
    src = write_intermimic_folder(tmp / "src", sequences=("sub1_box_000", "sub1_box_001"), T=60)
    r = _wristmimic("convert", "intermimic", src, "-o", tmp / "ref.h5", "--hull-cache", tmp / "cache", "-q")
    assert r.returncode == 0, r.stderr
    return src, tmp / "cache", tmp / "ref.h5"


@pytest.mark.parametrize("fsize", [0, 64 * 1024], ids=["first-write", "mid-file"])
def test_convert_on_a_full_disk_is_one_line_and_leaves_nothing(im, tmp_path: Path, fsize: int) -> None:
    src, cache, ref = im
    assert ref.stat().st_size > 2 * fsize  # the limit falls inside the file
    out = tmp_path / "o.h5"
    r = _wristmimic("convert", "intermimic", src, "-o", out, "--hull-cache", cache, "-q", fsize=fsize)
    _assert_write_error(r, out)
    assert list(tmp_path.iterdir()) == []  # no output, no temporary file


def test_synth_on_a_full_disk_is_one_line_and_leaves_nothing(tmp_path: Path) -> None:
    out = tmp_path / "s.h5"
    r = _wristmimic("synth", "-o", out, "-v", "default", fsize=64 * 1024)
    _assert_write_error(r, out)
    assert list(tmp_path.iterdir()) == []


def test_convert_killed_then_rerun_removes_the_stale_temporary(im, tmp_path: Path) -> None:
    src, cache, ref = im
    out = tmp_path / "o.h5"
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(p for p in (str(REPO), os.environ.get("PYTHONPATH")) if p)}
    cmd = [sys.executable, "-m", "wristmimic.cli.main", "convert", "intermimic", str(src), "-o", str(out)]
    proc = subprocess.Popen([*cmd, "--hull-cache", str(cache), "-q"], env=env, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 120
    while not temporaries(tmp_path) and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.005)
    proc.kill()  # SIGKILL while the output is being written
    proc.wait(timeout=30)
    assert proc.returncode == -signal.SIGKILL
    (stale,) = temporaries(tmp_path)
    assert not out.exists() and stale.name.startswith(f".o.h5.{_HOST}-{proc.pid}.")

    r = _wristmimic("convert", "intermimic", src, "-o", out, "--hull-cache", cache, "-q")
    assert r.returncode == 0, r.stderr
    lines = [ln for ln in r.stderr.splitlines() if "stale" in ln]
    assert lines == [f"removed stale temporary file {stale} (left by process {proc.pid}, which is no longer running)"]
    assert sorted(tmp_path.iterdir()) == [out] and "Traceback" not in r.stderr
    same_h5(out, ref)


def test_only_temporaries_of_dead_writers_are_removed(tmp_path: Path) -> None:
    out = tmp_path / "o.h5"
    dead = subprocess.Popen(["true"])
    dead.wait()
    old = time.time() - STALE_AFTER_S - 60
    names = {
        "dead": f".o.h5.{_HOST}-{dead.pid}.abcd1234.tmp",
        "alive": f".o.h5.{_HOST}-{os.getpid()}.abcd1234.tmp",  # this very process
        "other_host_fresh": f".o.h5.elsewhere-{dead.pid}.abcd1234.tmp",
        "other_host_old": f".o.h5.elsewhere-{dead.pid}.efgh5678.parquet.tmp",
        "legacy_fresh": ".o.h5.k2j4h5g6.tmp",
        "legacy_old": ".o.h5.x9y8z7w6.tmp",
        "other_output": f".o.h5.bak.{_HOST}-{dead.pid}.abcd1234.tmp",  # the temporary of o.h5.bak
        "not_a_temporary": ".o.h5.notes",
    }
    for key, name in names.items():
        (tmp_path / name).write_text(key)
        if key.endswith("_old"):
            os.utime(tmp_path / name, (old, old))
    said: list[str] = []
    removed = remove_stale_temporaries(out, said.append)
    assert sorted(p.name for p in removed) == sorted(names[k] for k in ("dead", "other_host_old", "legacy_old"))
    assert len(said) == 3 and all(s.startswith("removed stale temporary file ") and "\n" not in s for s in said)
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(
        names[k] for k in ("alive", "other_host_fresh", "legacy_fresh", "other_output", "not_a_temporary")
    )


# ------------------------------------------------------------------------------------------------ evaluate

EVAL_ARGS = ("-p", "quick", "-n", "6", "--num-envs", "3", "--nthread", "1", "-q")  # the CLI's
EVAL_KW = dict(trials=6, num_envs=3, nthread=1, progress=False)  # the same in-process


def _evaluate(run: Path, out: Path, **kw):  # noqa: ANN202
    from wristmimic.evaluate import evaluate_policy, load_eval_policy, load_protocol

    return evaluate_policy(load_eval_policy(run), load_protocol("quick"), out, **(EVAL_KW | kw))


@pytest.fixture(scope="module")
def trained(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """(run folder of a tiny training run, its reference evaluation without faults)."""
    from wristmimic.rl import TrainSpec, preset, start_run

    tmp = tmp_path_factory.mktemp("run")
    dataset = converted_intermimic(tmp, T=30)
    tiny = dict(num_envs=4, horizon=8, minibatch_size=16, epochs=1, actor_hidden=(32,), critic_hidden=(32,))
    spec = TrainSpec(dataset, SID, "wristmimic", 0, "cpu", preset("cpu", **tiny, max_frames=64), ref_frames=20)
    run = start_run(spec, tmp / "run", nthread=1, progress=False).run_dir
    assert _evaluate(run, tmp / "ref").trials_run == 6
    return run, tmp / "ref"


def _final_files(out: Path) -> list[str]:
    names = (f"{SID}.parquet", "summary.json", "summary.csv", "timing.json")
    return [n for n in names if (out / n).exists()]


def test_evaluate_cannot_write_its_settings(trained, tmp_path: Path) -> None:
    run, _ = trained
    out = tmp_path / "eval"
    r = _wristmimic("evaluate", run, *EVAL_ARGS, "-o", out, fsize=0)
    _assert_write_error(r, out / "eval.json")
    assert list(tmp_path.iterdir()) == []  # not even the folder it made


def test_evaluate_cannot_write_a_part(trained, tmp_path: Path) -> None:
    run, ref = trained
    part = Path("parts", SID, "trials-00000000-00000006.parquet")
    fsize = 4096
    assert (ref / "eval.json").stat().st_size < fsize < (ref / part).stat().st_size
    r = _wristmimic("evaluate", run, *EVAL_ARGS, "-o", tmp_path, fsize=fsize)
    _assert_write_error(r, tmp_path / part)
    assert temporaries(tmp_path) == [] and _final_files(tmp_path) == []
    assert not (tmp_path / part).exists()
    assert json.loads((tmp_path / "eval.json").read_text()) == json.loads((ref / "eval.json").read_text())


def test_evaluate_cannot_write_its_table_then_a_rerun_runs_no_trial_again(trained, tmp_path: Path) -> None:
    """All trials saved in parts (as when killed just before the end): the final files fail together; a rerun
    writes them from the parts without running a trial."""
    run, ref = trained
    out = tmp_path / "eval"
    shutil.copytree(ref, out, ignore=shutil.ignore_patterns(*_final_files(ref)))
    parts = {p: p.read_bytes() for p in (out / "parts").rglob("*.parquet")}
    r = _wristmimic("evaluate", run, *EVAL_ARGS, "-o", out, fsize=0)
    _assert_write_error(r, out / f"{SID}.parquet")
    assert temporaries(out) == [] and _final_files(out) == []
    assert {p: p.read_bytes() for p in (out / "parts").rglob("*.parquet")} == parts  # nothing lost

    assert _evaluate(run, out).trials_run == 0
    assert json.loads((out / "timing.json").read_text())["trials_run"] == 0
    for name in (f"{SID}.parquet", "summary.json", "summary.csv"):
        assert (out / name).read_bytes() == (ref / name).read_bytes(), name


@pytest.mark.parametrize("damage", ["truncated", "empty"])
def test_a_damaged_part_is_said_and_recomputed_alone(trained, tmp_path: Path, capsys, damage: str) -> None:
    run, ref = trained
    assert _evaluate(run, tmp_path, chunk=2).trials_run == 6
    parts = sorted((tmp_path / "parts" / SID).glob("trials-*.parquet"))
    assert [p.name for p in parts] == [f"trials-{a:08d}-{a + 2:08d}.parquet" for a in (0, 2, 4)]
    bad = parts[1]
    data = bad.read_bytes()
    bad.write_bytes(data[: len(data) // 2] if damage == "truncated" else b"")  # e.g. a power cut without fsync
    kept = {p: (p.stat().st_ino, p.stat().st_mtime_ns) for p in (parts[0], parts[2])}
    capsys.readouterr()

    again = _evaluate(run, tmp_path, chunk=2)
    err = capsys.readouterr().err
    said = [ln for ln in err.splitlines() if str(bad) in ln]
    assert len(said) == 1 and "trials 2-3 will be run again" in said[0], err
    assert again.trials_run == 2  # only the damaged part's trials
    assert {p: (p.stat().st_ino, p.stat().st_mtime_ns) for p in kept} == kept  # intact parts untouched
    a, b = pd.read_parquet(ref / f"{SID}.parquet"), pd.read_parquet(again.parquet)
    pd.testing.assert_frame_equal(a, b, check_exact=True)
    assert again.parquet.read_bytes() == (ref / f"{SID}.parquet").read_bytes()
    assert temporaries(tmp_path) == []
