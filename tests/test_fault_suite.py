"""The remaining cases of the fault suite (#16): every command refuses bad data and survives faults.

- ``-o`` of the wrong kind (a folder where a file is written, a file where a folder is, a path below a file) for
  ``synth``, ``demo``, ``run``, ``humanoid parahome`` and ``humanoid swap-hands``: one line before any work.
- ``safe_pickle_load``: complete one-line messages (never cut mid-word at a fixed width).
- The hull cache: written through ``atomic_output``; a temporary left by a SIGKILL is removed by the next
  conversion, and a full disk is one line with nothing left behind.
- SIGKILL and SIGINT of real ``wristmimic`` subprocesses during ``convert``, ``train`` and ``evaluate`` (the cases
  not covered by test_faults_disk.py and test_train_faults.py): the rerun (or ``--resume``) completes with the
  result of an uninterrupted run, no temporary file is left and nothing finished is computed again.
- An ``OSError`` nobody wrapped, a ``MemoryError`` or torch's out-of-memory error: one ``error:`` line, exit 1.

Each case asserts the exit code, exactly one ``error:`` (or ``interrupted:``) line on stderr and no
"Traceback", that no partial output is left and that nothing was lost.
"""

from __future__ import annotations

import csv
import errno
import os
import pickle
import re
import resource
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
import typer
from synthetic_raw import synthetic_bones
from typer.testing import CliRunner

from wristmimic.cli.errors import user_errors
from wristmimic.cli.main import app
from wristmimic.errors import InputError
from wristmimic.safe_io import _HOST, STALE_AFTER_S, safe_pickle_load

from conftest import REPO, same_h5, temporaries
from synthetic import converted_intermimic, write_intermimic_folder

SID = "sub1_box_000"
ENV = {
    **os.environ,
    "PYTHONPATH": os.pathsep.join(p for p in (str(REPO), os.environ.get("PYTHONPATH")) if p),
    "OMP_NUM_THREADS": "1",
}
TINY = dict(num_envs=2, horizon=4, minibatch_size=8, epochs=1, actor_hidden=(16,), critic_hidden=(16,), eval_every=0)
"""A training preset of 8 frames an iteration (registered as ``tiny`` in this process and in the subprocesses)."""
CHUNK = 4
"""Trials per part file of the evaluations here (the CLI's default, 256, would write one part at the end)."""
BOOT = (
    "from wristmimic.rl import config\n"
    f"config.PRESETS['tiny'] = config.preset('cpu', **{TINY!r})\n"
    "from wristmimic.evaluate import runner\n"
    f"runner.evaluate_policy.__kwdefaults__['chunk'] = {CHUNK}\n"
    "from wristmimic.cli.main import app\n"
    "app(prog_name='wristmimic')\n"
)
"""``python -c BOOT ARGS`` is ``wristmimic ARGS`` with the tiny preset and small evaluation parts."""
runner = CliRunner()


# ------------------------------------------------------------------------------------------------ helpers


def _cmd(*args: str | Path) -> list[str]:
    return [sys.executable, "-c", BOOT, *map(str, args)]


def _wristmimic(*args: str | Path, preexec_fn: Callable[[], None] | None = None) -> subprocess.CompletedProcess:
    """``wristmimic ARGS`` in a fresh interpreter."""
    return subprocess.run(
        _cmd(*args), env=ENV, capture_output=True, text=True, timeout=300, preexec_fn=preexec_fn
    )  # fmt: skip


def _default_sigint() -> None:
    """``preexec_fn``: SIGINT as a terminal delivers it. A shell's background job (``.ci/run &``) starts with SIGINT
    ignored, and Python then never installs its KeyboardInterrupt handler, so Ctrl-C tests would see nothing."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def _start(*args: str | Path) -> subprocess.Popen:
    return subprocess.Popen(
        _cmd(*args), env=ENV, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, preexec_fn=_default_sigint
    )


def _wait_until(proc: subprocess.Popen, ready: Callable[[], bool], what: str, timeout: float = 120) -> None:
    """Poll ``ready`` every 2 ms while ``proc`` runs; fail (saying why) if it ends or times out first."""
    deadline = time.monotonic() + timeout
    while not ready():
        if proc.poll() is not None:
            out, err = proc.communicate()
            raise AssertionError(f"ended (exit {proc.returncode}) before {what}: {(out + err)[-2000:]}")
        assert time.monotonic() < deadline, f"no {what} within {timeout} s"
        time.sleep(0.002)


def _one_line(stderr: str, prefix: str = "error: ") -> str:
    """The single line on stderr, which starts with ``prefix``; no traceback."""
    assert "Traceback" not in stderr and "Exception ignored" not in stderr, stderr[-3000:]
    lines = stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith(prefix), stderr[-3000:]
    return lines[0]


def _clean_error(r, *fragments: str) -> str:
    """A CliRunner result: exit 1 through the CLI's error path, one ``error:`` line holding ``fragments``."""
    assert r.exit_code == 1, r.output
    assert isinstance(r.exception, SystemExit), repr(r.exception)
    assert "Traceback" not in r.output
    line = _one_line(r.stderr)
    for f in fragments:
        assert f in line, (f, line)
    return line


def _listing(root: Path) -> dict[str, bytes | None]:
    """Every path under ``root`` with its bytes (None for folders)."""
    return {str(p.relative_to(root)): (None if p.is_dir() else p.read_bytes()) for p in sorted(root.rglob("*"))}


@pytest.fixture(scope="module")
def tiny_preset() -> None:
    from wristmimic.rl import config

    with pytest.MonkeyPatch.context() as m:
        m.setitem(config.PRESETS, "tiny", config.preset("cpu", **TINY))
        yield


@pytest.fixture(scope="module")
def im(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """An InterMimic source folder, a warm hull cache, its conversion (the reference) and a small trained run."""
    from wristmimic.rl import TrainSpec, preset, start_run

    tmp = tmp_path_factory.mktemp("suite")
    src = write_intermimic_folder(tmp / "src", sequences=("sub1_box_000", "sub1_box_001"), T=60)
    r = _wristmimic("convert", "intermimic", src, "-o", tmp / "ref.h5", "--hull-cache", tmp / "cache", "-q")
    assert r.returncode == 0, r.stderr
    dataset = converted_intermimic(tmp, T=30)
    spec = TrainSpec(dataset, SID, "wristmimic", 0, "cpu", preset("cpu", **TINY, max_frames=16), ref_frames=20)
    run = start_run(spec, tmp / "run", nthread=1, progress=False).run_dir
    return {"src": src, "cache": tmp / "cache", "ref": tmp / "ref.h5", "dataset": dataset, "run": run}


# ------------------------------------------------------------------------------ 1. -o of the wrong kind


def _bones(folder: Path) -> Path:
    p = folder / "s9" / "bone_vectors.pkl"
    p.parent.mkdir(parents=True)
    p.write_bytes(pickle.dumps(synthetic_bones(np.random.default_rng(0))))
    return p


def _pipeline(folder: Path, src: Path, **tables: dict[str, str]) -> Path:
    """A pipeline file with a convert stage from ``src`` and ``tables`` ({table: {key: path}}) over it."""
    spec = {"pipeline": {"name": "t", "work_dir": str(folder / "work")}, "convert": {"format": "intermimic",
            "source": str(src), "output": str(folder / "d.h5")}}  # fmt: skip
    for table, values in tables.items():
        spec.setdefault(table, {}).update(values)
    text = "".join(f"[{t}]\n" + "".join(f'{k} = "{v}"\n' for k, v in kv.items()) for t, kv in spec.items())
    (folder / "p.toml").write_text(text)
    return folder / "p.toml"


OUTPUT_CASES = [
    "synth-folder", "synth-below-file", "demo-file", "demo-below-file", "demo-inner-folder", "demo-inner-file",
    "run-convert-folder", "run-work-dir-file", "run-report-below-file", "run-hands-file",
    "parahome-folder", "parahome-below-file", "swap-hands-folder", "swap-hands-below-file",
]  # fmt: skip


@pytest.mark.parametrize("case", OUTPUT_CASES)
def test_output_option_of_the_wrong_kind_is_refused_before_any_work(im, tmp_path: Path, case: str) -> None:
    folder = tmp_path / "taken"  # an existing folder
    folder.mkdir()
    (folder / "keep.txt").write_text("keep")
    afile = tmp_path / "taken.txt"  # an existing file
    afile.write_text("keep")
    work = tmp_path / "w"  # inputs written here; everything a pipeline would write goes below it too
    work.mkdir()
    demo_a, demo_b = tmp_path / "demo_a", tmp_path / "demo_b"  # demo folders holding an output of the wrong kind
    (demo_a / "demo.h5").mkdir(parents=True)  # a folder where the demo writes its dataset
    demo_b.mkdir()
    (demo_b / "eval").write_text("not a folder")  # a file where it writes its evaluation
    src = im["src"]
    swap = ["humanoid", "swap-hands", str(im["dataset"]), SID, "--hand", "smplx-free", "-o"]
    make: dict[str, Callable[[], tuple[list[str], list[str]]]] = {
        "synth-folder": lambda: (["synth", "-v", "default", "-o", str(folder)], [f"{folder}: --out: is a folder"]),
        "synth-below-file": lambda: (["synth", "-o", str(afile / "s.h5")], [f"{afile} is a file, not a folder"]),
        "demo-file": lambda: (["demo", "--quick", "-o", str(afile)], [f"{afile}: --out: is a file, not a folder"]),
        "demo-below-file": lambda: (["demo", "--quick", "-o", str(afile / "d")], [f"{afile} is a file, not a folder"]),
        "demo-inner-folder": lambda: (["demo", "--quick", "-o", str(demo_a)],
                                      [f"{demo_a / 'demo.h5'}: --out: is a folder"]),
        "demo-inner-file": lambda: (["demo", "--quick", "-o", str(demo_b)],
                                    [f"{demo_b / 'eval'}: --out: is a file, not a folder"]),
        "run-convert-folder": lambda: (["run", str(_pipeline(work, src, convert={"output": str(folder)}))],
                                       ["p.toml: convert.output: ", f"{folder} is a folder"]),
        "run-work-dir-file": lambda: (["run", str(_pipeline(work, src, pipeline={"work_dir": str(afile)}))],
                                      ["p.toml: pipeline.work_dir: ", f"{afile} is a file, not a folder"]),
        "run-report-below-file": lambda: (["run", str(_pipeline(work, src, report={"output": str(afile / "rep")}))],
                                          ["p.toml: report.output: ", f"{afile} is a file, not a folder"]),
        "run-hands-file": lambda: (["run", str(_pipeline(work, src, hands={"scene": SID, "output_dir": str(afile)}))],
                                   ["p.toml: hands.output_dir: ", f"{afile} is a file, not a folder"]),
        "parahome-folder": lambda: (["humanoid", "parahome", str(_bones(work)), "-o", str(folder)],
                                    [f"{folder}: --out: is a folder"]),
        "parahome-below-file": lambda: (["humanoid", "parahome", str(_bones(work)), "-o", str(afile / "h.xml")],
                                        [f"{afile} is a file, not a folder"]),
        "swap-hands-folder": lambda: ([*swap, str(folder)], [f"{folder}: --out: is a folder"]),
        "swap-hands-below-file": lambda: ([*swap, str(afile / "o.h5")], [f"{afile} is a file, not a folder"]),
    }  # fmt: skip
    args, fragments = make[case]()
    before, run_before = _listing(tmp_path), _listing(im["run"])
    r = runner.invoke(app, args)
    _clean_error(r, *fragments)
    assert r.stdout == ""  # before any work: no banner, no stage started
    assert _listing(tmp_path) == before  # nothing written, not even a temporary file or an empty folder
    assert _listing(im["run"]) == run_before


def test_a_pipeline_path_that_is_not_a_string_is_one_line(im, tmp_path: Path) -> None:
    spec = tmp_path / "p.toml"
    spec.write_text(f'[pipeline]\nwork_dir = 5\n[convert]\nformat = "intermimic"\nsource = "{im["src"]}"\n')
    _clean_error(runner.invoke(app, ["run", str(spec)]), f"{spec}: pipeline.work_dir: 5 (expected a path")
    assert sorted(tmp_path.iterdir()) == [spec]


@pytest.mark.parametrize("text", ["{not json", "[1, 2]"])
def test_a_damaged_pipeline_state_is_one_line_and_kept(im, tmp_path: Path, text: str) -> None:
    work = tmp_path / "work"
    work.mkdir()
    (work / "pipeline_state.json").write_text(text)
    spec = tmp_path / "p.toml"
    spec.write_text(
        f'[pipeline]\nwork_dir = "{work}"\n[convert]\nformat = "intermimic"\nsource = "{im["src"]}"\n'
        f'output = "{tmp_path / "o.h5"}"\n'
    )
    _clean_error(runner.invoke(app, ["run", str(spec)]), "pipeline_state.json", "delete the file")
    assert (work / "pipeline_state.json").read_text() == text and sorted(work.iterdir()) == [
        work / "pipeline_state.json"
    ]
    assert not (tmp_path / "o.h5").exists()


# ------------------------------------------------------------------------------ 2. safe_pickle_load messages


class _Calls:
    """Pickles as ``func(*args)`` (with allowed globals only: the restricted loader calls it)."""

    def __init__(self, func: object, *args: object):
        self.func, self.args = func, args

    def __reduce__(self):
        return (self.func, self.args)


def _detail(message: str) -> str:
    m = re.fullmatch(r".*: <pickle>: cannot be unpickled \((.*)\) \(expected a pickle file\)", message)
    assert m, message
    return m.group(1)


def test_a_long_unpickling_error_is_cut_at_a_word_not_mid_word(tmp_path: Path) -> None:
    words = "this is not a number " * 12  # int() quotes the text (up to 200 characters) in its message
    try:
        int(words)
    except ValueError as exc:
        full = f"ValueError: {exc}"
    assert len(full) > 240
    p = tmp_path / "long.pkl"
    p.write_bytes(pickle.dumps(_Calls(int, words), protocol=4))
    with pytest.raises(InputError) as info:
        safe_pickle_load(p)
    message = str(info.value)
    assert "\n" not in message and message.startswith(f"{p}: <pickle>: cannot be unpickled (ValueError: invalid")
    detail = _detail(message)
    assert detail.endswith(" ...") and len(detail) <= len("ValueError: ") + 200 + len(" ...")
    kept = detail.removesuffix(" ...")
    assert full.startswith(kept) and full[len(kept)] == " "  # cut between two words, not inside one


NOT_ZLIB = b"x marks the spot: the first byte of a zlib stream, then no zlib data"


def _zlib_error(data: bytes) -> str:
    import zlib

    try:
        zlib.decompress(data)
    except zlib.error as exc:
        return str(exc)
    raise AssertionError("decompressed")


@pytest.mark.parametrize(
    ("data", "expected"),
    [
        (pickle.dumps(_Calls(int, "twelve"), protocol=4), "ValueError: invalid literal for int() with base 10: 'twelve'"),
        (pickle.dumps(_Calls(dict, [(1, 2, 3)]), protocol=2),
         "ValueError: dictionary update sequence element #0 has length 3; 2 is required"),
        (pickle.dumps(list(range(50)))[:-20], "UnpicklingError: pickle data was truncated"),
        (NOT_ZLIB, f"error: {_zlib_error(NOT_ZLIB)}"),  # zlib.error escaped as a traceback before
    ],
    ids=["int", "dict", "truncated", "not-zlib"],
)  # fmt: skip
def test_unpickling_errors_are_whole_one_line_messages(tmp_path: Path, data: bytes, expected: str) -> None:
    p = tmp_path / "bad.pkl"
    p.write_bytes(data)
    with pytest.raises(InputError) as info:
        safe_pickle_load(p)
    assert _detail(str(info.value)) == expected


def test_a_long_pickle_error_from_the_command_line_is_one_whole_line(tmp_path: Path) -> None:
    """``humanoid parahome`` reads bone_vectors.pkl with the restricted loader: one line, cut at a word."""
    p = tmp_path / "s1" / "bone_vectors.pkl"
    p.parent.mkdir()
    p.write_bytes(pickle.dumps(_Calls(float, "one two three " * 20), protocol=4))
    out = tmp_path / "h.xml"
    line = _clean_error(runner.invoke(app, ["humanoid", "parahome", str(p), "-o", str(out)]), str(p))
    assert re.search(r"\(ValueError: could not convert string to float: 'one two three [a-z ]+ \.\.\.\)", line), line
    assert not out.exists() and temporaries(tmp_path) == []


# ------------------------------------------------------------------------------ 3. the hull cache


DIE_IN_CACHE_WRITE = (
    "import os, signal, sys\n"
    "import numpy as np\n"
    "savez = np.savez\n"
    "def savez_then_die(fh, **arrays):\n"
    "    savez(fh, **arrays)\n"
    "    fh.flush()\n"
    "    os.kill(os.getpid(), signal.SIGKILL)  # after the bytes, before the rename\n"
    "np.savez = savez_then_die\n"
    "from wristmimic.cli.main import app\n"
    "app(prog_name='wristmimic')\n"
)


def test_hull_cache_write_killed_then_the_next_conversion_removes_its_temporary(im, tmp_path: Path) -> None:
    cache, out = tmp_path / "cache", tmp_path / "o.h5"
    args = ["convert", "intermimic", str(im["src"]), "-o", str(out), "--hull-cache", str(cache), "-q"]
    killed = subprocess.run(
        [sys.executable, "-c", DIE_IN_CACHE_WRITE, *args], env=ENV, capture_output=True, timeout=300
    )  # fmt: skip
    assert killed.returncode == -signal.SIGKILL, killed.stderr[-2000:]
    (stale,) = temporaries(cache)
    assert list(cache.iterdir()) == [stale] and not out.exists()
    m = re.fullmatch(rf"\.([0-9a-f]{{64}})\.npz\.{_HOST}-(\d+)\.[a-z0-9_]{{8}}\.npz\.tmp", stale.name)
    assert m, stale.name
    key, pid = m.group(1), m.group(2)
    (stale_out,) = [p for p in temporaries(tmp_path) if p.parent == tmp_path]  # the output was open meanwhile
    assert stale_out.name.startswith(f".o.h5.{_HOST}-{pid}.")
    old, fresh = cache / f".{key[:16]}.k2j4h5g6.tmp", cache / f".{key[:16]}.x9y8z7w6.tmp"  # the older naming
    for legacy in (old, fresh):
        legacy.write_bytes(b"half a cache file")
    then = time.time() - STALE_AFTER_S - 60
    os.utime(old, (then, then))

    r = _wristmimic(*args)
    assert r.returncode == 0 and "0 hull cache hit(s)" in r.stdout, r.stdout + r.stderr
    dead = f"(left by process {pid}, which is no longer running)"
    assert sorted(r.stderr.splitlines()) == sorted([
        f"removed stale temporary file {old} (left by an unknown process, untouched for 24 h)",
        f"removed stale temporary file {stale} {dead}",
        f"removed stale temporary file {stale_out} {dead}",
    ])  # fmt: skip
    assert sorted(cache.iterdir()) == [fresh, cache / f"{key}.npz"]  # a legacy one of a possibly live writer stays
    assert sorted(tmp_path.iterdir()) == [cache, out]
    same_h5(out, im["ref"])


DECOMPOSE = (
    "import sys\n"
    "import trimesh\n"
    "from wristmimic.convert.hulls import HullParams, convex_decompose\n"
    "from wristmimic.errors import WristmimicError\n"
    "box = trimesh.creation.box((0.3, 0.2, 0.2))\n"
    "try:\n"
    "    convex_decompose(box.vertices, box.faces, HullParams(), sys.argv[1])\n"
    "except WristmimicError as exc:\n"
    "    sys.exit(f'error: {exc}')\n"
)


def test_hull_cache_on_a_full_disk_is_one_line_and_leaves_nothing(tmp_path: Path) -> None:
    """A conversion writes its output's first bytes before any hull, so the cache write is faulted on its own."""
    cache = tmp_path / "cache"

    def small_files() -> None:
        resource.setrlimit(resource.RLIMIT_FSIZE, (1024, 1024))  # a cache file of a box is about 3.6 kB

    r = subprocess.run([sys.executable, "-c", DECOMPOSE, str(cache)], env=ENV, capture_output=True, text=True,
                       timeout=300, preexec_fn=small_files)  # fmt: skip
    assert r.returncode == 1, r.stderr[-2000:]
    line = _one_line(r.stderr)
    assert re.fullmatch(
        rf"error: {re.escape(str(cache))}/[0-9a-f]{{64}}\.npz: could not write \(File too large\)", line
    )
    assert list(cache.iterdir()) == []  # no cache file, no temporary


# ------------------------------------------------------------------------------ 4. SIGKILL / SIGINT


def test_convert_interrupted_by_ctrl_c_writes_nothing_and_a_rerun_matches(im, tmp_path: Path) -> None:
    out = tmp_path / "o.h5"
    args = ["convert", "intermimic", im["src"], "-o", out, "--hull-cache", im["cache"], "-q"]
    for _attempt in range(5):  # the write is short: a Ctrl-C can arrive after it finished; then try again
        proc = _start(*args)
        _wait_until(proc, lambda: bool(temporaries(tmp_path)), "the output being written")
        proc.send_signal(signal.SIGINT)  # Ctrl-C while the output file is being written
        stdout, stderr = proc.communicate(timeout=60)
        if proc.returncode != 0:
            break
        out.unlink()
    assert proc.returncode == 130, stdout + stderr
    assert _one_line(stderr, "interrupted: ") == "interrupted: no output written"
    assert list(tmp_path.iterdir()) == []  # no output, no temporary file

    r = _wristmimic(*args)
    assert r.returncode == 0 and r.stderr == "", r.stderr
    assert list(tmp_path.iterdir()) == [out]
    same_h5(out, im["ref"])


TRIALS = 48
EVAL_ARGS = ("-p", "quick", "-n", str(TRIALS), "--num-envs", "2", "--nthread", "1", "-q")


@pytest.fixture(scope="module")
def eval_reference(im, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """An uninterrupted evaluation (in this process) of the tiny run: the same trials as the CLI runs."""
    from wristmimic.evaluate import evaluate_policy, load_eval_policy, load_protocol

    out = tmp_path_factory.mktemp("eval_ref")
    policy = load_eval_policy(im["run"])
    r = evaluate_policy(policy, load_protocol("quick"), out, trials=TRIALS, num_envs=2, nthread=1, chunk=CHUNK,
                        progress=False)  # fmt: skip
    assert r.trials_run == TRIALS
    return out


def _parts(out: Path) -> dict[Path, tuple[int, int, bytes]]:
    """Part files: path -> (inode, mtime, bytes)."""
    return {p: (p.stat().st_ino, p.stat().st_mtime_ns, p.read_bytes()) for p in (out / "parts").rglob("*.parquet")}


def _trials_in(parts: dict[Path, object]) -> int:
    spans = [re.fullmatch(r"trials-(\d{8})-(\d{8})\.parquet", p.name) for p in parts]
    return sum(int(m.group(2)) - int(m.group(1)) for m in spans if m)


def _rerun_evaluation(im, out: Path, reference: Path, expect_run: int) -> None:
    import json

    r = _wristmimic("evaluate", im["run"], *EVAL_ARGS, "-o", out)
    assert r.returncode == 0, r.stdout + r.stderr
    assert "Traceback" not in r.stderr and not [ln for ln in r.stderr.splitlines() if "stale" not in ln], r.stderr
    assert json.loads((out / "timing.json").read_text())["trials_run"] == expect_run  # no saved trial run again
    for name in (f"{SID}.parquet", "summary.json", "summary.csv", "eval.json"):
        assert (out / name).read_bytes() == (reference / name).read_bytes(), name
    assert temporaries(out) == []


def test_evaluate_killed_then_rerun_runs_only_the_unsaved_trials(im, eval_reference: Path, tmp_path: Path) -> None:
    out = tmp_path / "eval"
    proc = _start("evaluate", im["run"], *EVAL_ARGS, "-o", out)
    _wait_until(proc, lambda: bool(list((out / "parts").rglob("*.parquet"))), "a first part file")
    proc.kill()  # SIGKILL: no handler runs
    proc.communicate(timeout=60)
    assert proc.returncode == -signal.SIGKILL
    saved = _parts(out)
    kept = _trials_in(saved)
    assert 0 < kept < TRIALS and not (out / f"{SID}.parquet").exists()

    _rerun_evaluation(im, out, eval_reference, TRIALS - kept)
    assert {p: v for p, v in _parts(out).items() if p in saved} == saved  # saved parts untouched


def test_evaluate_interrupted_by_ctrl_c_keeps_its_trials_and_a_rerun_matches(
    im, eval_reference: Path, tmp_path: Path
) -> None:
    out = tmp_path / "eval"
    proc = _start("evaluate", im["run"], *EVAL_ARGS, "-o", out)
    _wait_until(proc, lambda: bool(list((out / "parts").rglob("*.parquet"))), "a first part file")
    proc.send_signal(signal.SIGINT)
    stdout, stderr = proc.communicate(timeout=60)
    assert proc.returncode == 130, stdout + stderr
    line = _one_line(stderr, "interrupted: ")
    m = re.fullmatch(rf"interrupted: {re.escape(str(out))}: interrupted after (\d+)/{TRIALS} trials \(kept; rerun to "
                     r"resume\)", line)  # fmt: skip
    assert m, line
    kept = int(m.group(1))
    assert 0 < kept < TRIALS and _trials_in(_parts(out)) == kept  # what it says it kept is on disk
    assert temporaries(out) == [] and not (out / f"{SID}.parquet").exists()

    _rerun_evaluation(im, out, eval_reference, TRIALS - kept)


@pytest.mark.parametrize("moment", ["before-rename", "after-rename"])
def test_ctrl_c_while_a_part_is_written_keeps_every_completed_trial(
    im, eval_reference: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, moment: str
) -> None:
    """Ctrl-C at the two moments a real one can hit while a part is written (the subprocess test above cannot
    choose): before its rename (its trials must still be written, not dropped) and just after it (they count as
    kept). What the message says is kept is what the part files hold; a rerun runs only the rest."""
    import contextlib

    from wristmimic.evaluate import EvalInterrupted, evaluate_policy, load_eval_policy, load_protocol
    from wristmimic.evaluate import runner as eval_runner

    real = eval_runner.atomic_output
    parts_begun: list[Path] = []

    @contextlib.contextmanager
    def ctrl_c_at_the_first_part(path: Path, suffix: str = ""):
        if path.name.startswith("trials-"):
            parts_begun.append(path)
        first = parts_begun == [path]  # the first part write only, not the one the handler makes
        with real(path, suffix) as tmp:
            yield tmp
            if first and moment == "before-rename":
                raise KeyboardInterrupt
        if first and moment == "after-rename":
            raise KeyboardInterrupt

    def evaluate():  # noqa: ANN202
        return evaluate_policy(load_eval_policy(im["run"]), load_protocol("quick"), tmp_path, trials=TRIALS,
                               num_envs=2, nthread=1, chunk=CHUNK, progress=False)  # fmt: skip

    monkeypatch.setattr(eval_runner, "atomic_output", ctrl_c_at_the_first_part)
    with pytest.raises(EvalInterrupted) as info:
        evaluate()
    kept = info.value.completed
    assert CHUNK <= kept < TRIALS and _trials_in(_parts(tmp_path)) == kept and temporaries(tmp_path) == []
    monkeypatch.setattr(eval_runner, "atomic_output", real)
    assert evaluate().trials_run == TRIALS - kept
    for name in (f"{SID}.parquet", "summary.json", "summary.csv", "eval.json"):
        assert (tmp_path / name).read_bytes() == (eval_reference / name).read_bytes(), name


ITERATIONS = 5
FRAMES = 8  # per iteration of the tiny preset


def _metrics(run_dir: Path) -> list[dict[str, str]]:
    from wristmimic.rl.logger import TIME_COLUMNS

    with open(run_dir / "metrics.csv", newline="") as f:
        return [{k: v for k, v in r.items() if k not in TIME_COLUMNS} for r in csv.DictReader(f)]


def test_train_interrupted_by_ctrl_c_saves_and_resume_matches_an_uninterrupted_run(
    im, tiny_preset: None, tmp_path: Path
) -> None:
    import torch

    from wristmimic.rl import TrainSpec, preset, start_run
    from wristmimic.rl.checkpoint import load_checkpoint

    runs = tmp_path / "runs"
    proc = _start("train", im["dataset"], "--scene", SID, "--preset", "tiny", "--max-frames", str(1000 * FRAMES),
                  "-o", runs, "--nthread", "1", "-q")  # fmt: skip

    def rows() -> int:
        found = list(runs.glob("*/metrics.csv"))
        return max(found[0].read_bytes().count(b"\n") - 1, 0) if found else 0

    _wait_until(proc, lambda: rows() >= 2, "a second iteration")
    proc.send_signal(signal.SIGINT)  # Ctrl-C: the current iteration ends, a checkpoint is saved
    stdout, stderr = proc.communicate(timeout=60)
    assert proc.returncode == 130, stdout + stderr
    assert stderr == "" and "Traceback" not in stdout
    (run,) = runs.iterdir()
    said = [ln for ln in stdout.splitlines() if "interrupted" in ln]
    saved = load_checkpoint(run)["iteration"]
    assert said == [f"{run}: interrupted at iteration {saved} ({saved * FRAMES} frames)"], stdout
    assert 2 <= saved < ITERATIONS and [int(r["iteration"]) for r in _metrics(run)] == list(range(1, saved + 1))

    r = _wristmimic("train", "--resume", run, "--max-frames", str(ITERATIONS * FRAMES), "--nthread", "1", "-q")
    assert r.returncode == 0 and f"finished at iteration {ITERATIONS}" in r.stdout, r.stdout + r.stderr
    spec = TrainSpec(im["dataset"], SID, "wristmimic", 0, "tiny", preset("tiny", max_frames=ITERATIONS * FRAMES))
    threads = torch.get_num_threads()
    torch.set_num_threads(1)  # as the subprocesses (OMP_NUM_THREADS=1): the same sums in the same order
    try:
        once = start_run(spec, tmp_path / "once", nthread=1, progress=False).run_dir
    finally:
        torch.set_num_threads(threads)
    assert [int(r["iteration"]) for r in _metrics(run)] == list(range(1, ITERATIONS + 1))  # each iteration once
    assert _metrics(run) == _metrics(once)  # and the numbers of an uninterrupted run
    assert temporaries(runs) == []


# ------------------------------------------------------------------------------ 5. errors nobody wrapped


def test_an_io_error_nobody_wrapped_is_one_line() -> None:
    """A real EIO: /proc/self/mem cannot be read at offset 0 (the pipeline file is read as text)."""
    mem = Path("/proc/self/mem")
    try:
        mem.read_bytes()
    except OSError as exc:
        if exc.errno != errno.EIO:
            pytest.skip(f"/proc/self/mem gives {exc!r} here, not EIO")
    else:
        pytest.skip("/proc/self/mem is readable here")
    r = _wristmimic("run", mem)
    assert r.returncode == 1 and r.stdout == "", r.stdout + r.stderr
    assert _one_line(r.stderr) == f"error: {os.strerror(errno.EIO)}"


def test_a_folder_given_as_a_file_to_read_is_one_line(tmp_path: Path) -> None:
    r = _wristmimic("run", tmp_path)  # IsADirectoryError from reading the pipeline file
    assert r.returncode == 1 and r.stdout == "", r.stdout + r.stderr
    assert _one_line(r.stderr) == f"error: {tmp_path}: {os.strerror(errno.EISDIR)}"
    assert list(tmp_path.iterdir()) == []


def _obey_file_modes() -> None:
    """``preexec_fn``: as root, drop the capabilities that override file modes (CAP_DAC_OVERRIDE,
    CAP_DAC_READ_SEARCH, CAP_FOWNER) from the bounding set, so the command sees a read-only folder as a user does."""
    if os.geteuid() != 0:
        return
    import ctypes

    libc = ctypes.CDLL(None, use_errno=True)
    for cap in (1, 2, 3):
        if libc.prctl(24, cap, 0, 0, 0) != 0:  # PR_CAPBSET_DROP
            raise OSError(ctypes.get_errno(), "prctl(PR_CAPBSET_DROP) failed")


@pytest.mark.parametrize("command", ["synth", "parahome", "swap-hands", "demo", "run", "evaluate"])
def test_a_read_only_output_folder_is_one_line(im, tmp_path: Path, command: str) -> None:
    ro = tmp_path / "ro"
    ro.mkdir(mode=0o500)
    try:
        probe = subprocess.run(
            [sys.executable, "-c", f"open({str(ro / 'probe')!r}, 'w')"], capture_output=True, preexec_fn=_obey_file_modes
        )  # fmt: skip
    except subprocess.SubprocessError as exc:
        pytest.skip(f"cannot drop root's file-mode override here ({exc})")
    if probe.returncode == 0:
        pytest.skip("a read-only folder does not stop this user's writes (root with CAP_DAC_OVERRIDE)")
    spec = tmp_path / "p.toml"
    spec.write_text(f'[pipeline]\nwork_dir = "{ro / "work"}"\n[convert]\nformat = "intermimic"\n'
                    f'source = "{im["src"]}"\noutput = "{tmp_path / "d.h5"}"\n')  # fmt: skip
    args = {
        "synth": ["synth", "-v", "default", "-o", ro / "s.h5"],
        "parahome": ["humanoid", "parahome", _bones(tmp_path), "-o", ro / "h.xml"],
        "swap-hands": ["humanoid", "swap-hands", im["dataset"], SID, "--hand", "smplx-free", "-o", ro / "o.h5"],
        "demo": ["demo", "--quick", "-o", ro / "demo"],
        "run": ["run", spec],
        "evaluate": ["evaluate", im["run"], "-p", "quick", "-n", "2", "--nthread", "1", "-q", "-o", ro / "eval"],
    }[command]
    try:
        before, run_before = _listing(tmp_path), _listing(im["run"])
        r = _wristmimic(*args, preexec_fn=_obey_file_modes)
        assert r.returncode == 1 and r.stdout == "", r.stdout + r.stderr
        line = _one_line(r.stderr)
        assert str(ro) in line and ("not writable" in line or "Permission denied" in line), line
        assert _listing(tmp_path) == before and _listing(im["run"]) == run_before
    finally:
        ro.chmod(0o700)


@pytest.mark.parametrize(
    ("exc", "line"),
    [
        (PermissionError(errno.EACCES, os.strerror(errno.EACCES), "/data/out/x.h5"),
         f"error: /data/out/x.h5: {os.strerror(errno.EACCES)}"),
        (OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), "/data/out/x.h5"),
         f"error: /data/out/x.h5: {os.strerror(errno.ENOSPC)}"),
        (OSError(errno.EXDEV, os.strerror(errno.EXDEV), "/a/x", None, "/b/x"),
         f"error: /a/x -> /b/x: {os.strerror(errno.EXDEV)}"),
        (OSError(errno.EIO, os.strerror(errno.EIO)), f"error: {os.strerror(errno.EIO)}"),
        (OSError("device gone\nsecond line"), "error: device gone"),
        (MemoryError(), "error: out of memory"),
        (MemoryError("Unable to allocate 8.00 EiB for an array with shape (1152921504606846976,) and data type "
                     "float64"),
         "error: out of memory (Unable to allocate 8.00 EiB for an array with shape (1152921504606846976,) and data "
         "type float64)"),
    ],
    ids=["EACCES", "ENOSPC", "rename", "no-filename", "no-errno", "memory", "memory-numpy"],
)  # fmt: skip
def test_user_errors_turns_os_and_memory_errors_into_one_line(exc: BaseException, line: str) -> None:
    """The wrapper itself, for errors a real run cannot provoke on demand here (EACCES as root, ENOSPC, ENOMEM)."""
    cli = typer.Typer()

    @cli.command()
    def fail() -> None:
        with user_errors():
            raise exc

    r = runner.invoke(cli, [])
    assert r.exit_code == 1 and isinstance(r.exception, SystemExit), repr(r.exception)
    assert _one_line(r.stderr) == line


def test_torch_out_of_memory_is_one_line_and_bugs_keep_their_traceback() -> None:
    import torch

    cli = typer.Typer()
    raised: list[BaseException] = []

    @cli.command()
    def fail() -> None:
        with user_errors():
            raise raised[-1]

    raised.append(torch.OutOfMemoryError("CUDA out of memory. Tried to allocate 2.00 GiB. GPU 0 has a total capacity "
                                         "of 139 GiB of which 1 GiB is free.\nIf reserved but unallocated ..."))  # fmt: skip
    r = runner.invoke(cli, [])
    assert r.exit_code == 1 and _one_line(r.stderr) == "error: out of memory (CUDA out of memory)"
    raised.append(ZeroDivisionError("a bug"))
    r = runner.invoke(cli, [])
    assert isinstance(r.exception, ZeroDivisionError)  # not hidden behind a one-line message
