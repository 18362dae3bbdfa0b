"""No tracebacks: output options naming the wrong kind of path, broken checkpoints, refused pickles, broken
evaluation folders and a URDF naming a missing mesh each end in one ``error:`` (or ``warning:``) line, exit 1
(0 for the warning), nothing partial left behind and nothing from a file run."""

from __future__ import annotations

import os
import pickle
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch
from typer.testing import CliRunner

from wristmimic.cli.main import app

from synthetic import converted_intermimic, write_intermimic_folder

SID = "sub1_box_000"
REPO = Path(__file__).resolve().parents[1]
runner = CliRunner()


def _listing(root: Path) -> dict[str, bytes | None]:
    """Every path under ``root`` with its bytes (None for folders): compares a tree before and after."""
    return {str(p.relative_to(root)): (None if p.is_dir() else p.read_bytes()) for p in sorted(root.rglob("*"))}


def _clean_error(r, *fragments: str) -> str:
    """Exit 1 through the CLI's error path: exactly one ``error:`` line on stderr, no traceback, the fragments."""
    assert r.exit_code == 1, r.output
    assert isinstance(r.exception, SystemExit), repr(r.exception)  # not an exception escaping the command
    assert "Traceback" not in r.output and "Traceback" not in r.stderr
    lines = r.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), r.stderr
    assert "weights_only" not in r.output  # never suggest the unsafe option
    for f in fragments:
        assert f in lines[0], (f, lines[0])
    return lines[0]


def _convert(src: Path, out: Path, tmp: Path):
    return runner.invoke(app, ["convert", "intermimic", str(src), "-o", str(out), "-q", "--hull-cache", str(tmp / "c")])


@pytest.fixture(scope="module")
def work(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """A converted file, a tiny trained run and its quick evaluation (about 10 s once per module)."""
    from wristmimic.rl import TrainSpec, preset, start_run

    tmp = tmp_path_factory.mktemp("nt")
    dataset = converted_intermimic(tmp, 40)
    tiny = dict(num_envs=2, horizon=4, minibatch_size=8, epochs=1, actor_hidden=(16,), critic_hidden=(16,))
    spec = TrainSpec(dataset, SID, "wristmimic", 0, "cpu", preset("cpu", **tiny, max_frames=16), ref_frames=12)
    run = start_run(spec, tmp / "run", nthread=1, progress=False).run_dir
    r = runner.invoke(app, ["evaluate", str(run), "-p", "quick", "-n", "2", "--num-envs", "2", "--nthread", "1", "-q"])
    assert r.exit_code == 0, r.output
    return {"dataset": dataset, "run": run, "eval": run / "eval" / "quick", "im": tmp / "im"}


# ----------------------------------------------------------------------------------------- output options


@pytest.mark.parametrize(
    "case",
    ["convert-folder", "scene-folder", "view-folder", "scene-below-file", "train-file", "evaluate-file", "report-file",
     "report-below-file"],
)  # fmt: skip
def test_output_option_of_the_wrong_kind(work: dict[str, Path], tmp_path: Path, case: str) -> None:
    folder = tmp_path / "taken.rrd"  # an existing folder (named like a recording for `view`)
    folder.mkdir()
    (folder / "keep.txt").write_text("keep")
    afile = tmp_path / "taken.txt"  # an existing file
    afile.write_text("keep")
    ds, run = str(work["dataset"]), str(work["run"])
    args, fragments = {
        "convert-folder": (["convert", "intermimic", str(work["im"]), "-o", str(folder), "-q", "--hull-cache",
                            str(tmp_path / "c")], [str(folder), "--out", "is a folder"]),
        "scene-folder": (["scene", ds, SID, "-o", str(folder)], [str(folder), "--out", "is a folder"]),
        "view-folder": (["view", ds, "-s", SID, "-o", str(folder)], [str(folder), "--out", "is a folder"]),
        "scene-below-file": (["scene", ds, SID, "-o", str(afile / "s.xml")], [f"{afile} is a file, not a folder"]),
        "train-file": (["train", ds, "-s", SID, "-o", str(afile), "--max-frames", "8", "-q"],
                       [str(afile), "--out", "is a file, not a folder"]),
        "evaluate-file": (["evaluate", run, "-p", "quick", "-n", "2", "-q", "-o", str(afile)],
                          [str(afile), "--out", "is a file, not a folder"]),
        "report-file": (["report", str(work["eval"]), "-o", str(afile)], [str(afile), "is a file, not a folder"]),
        "report-below-file": (["report", str(work["eval"]), "-o", str(afile / "rep")],
                              [f"{afile} is a file, not a folder"]),
    }[case]  # fmt: skip
    before, run_before = _listing(tmp_path), _listing(work["run"])
    _clean_error(runner.invoke(app, args), *fragments)
    assert _listing(tmp_path) == before  # nothing written, no temporary file left beside the target
    assert _listing(work["run"]) == run_before


# ------------------------------------------------------------------------------------------- checkpoints


class _System:
    """Pickles as ``os.system(command)``: loading it with plain pickle would run the command."""

    def __init__(self, command: str):
        self.command = command

    def __reduce__(self):
        return (os.system, (self.command,))


def _bad_checkpoint(kind: str, good: Path, dest: Path, marker: Path) -> tuple[str, ...]:
    """Write a broken ``checkpoint.pt`` of ``kind``; the fragments its error line must hold."""
    if kind == "text":
        dest.write_text("this is a text file, not a checkpoint\n")
        return ("not a torch file (cannot be read: neither a zip archive nor a pickle)",)
    if kind == "random":
        dest.write_bytes(np.random.default_rng(0).bytes(4096))
        return ("not a torch file (cannot be read: neither a zip archive nor a pickle)",)
    if kind == "truncated":
        data = good.read_bytes()
        dest.write_bytes(data[: len(data) // 2])
        return ("not a torch file (cannot be read: truncated or corrupt zip archive)",)
    if kind == "malicious":  # torch.save's own zip layout, pickle protocol 2
        torch.save({"format": "wristmimic-ppo-checkpoint", "payload": _System(f"touch {marker}")}, dest)
        return ("<pickle>: not a plain tensor: contains code or objects (GLOBAL posix.system)",)
    if kind == "malicious-raw":  # a bare protocol-4 pickle: torch's message does not name the global
        dest.write_bytes(pickle.dumps(_System(f"touch {marker}"), protocol=4))
        return ("<pickle>: not a plain tensor: contains code or objects (GLOBAL posix.system)",)
    if kind == "protocol-4":  # tensors only, but pickle protocol 4: refused without calling it code
        torch.save(torch.load(good, weights_only=True, map_location="cpu"), dest, pickle_protocol=4)
        return ("not a torch file (cannot be read: pickle opcode FRAME, which the safe loader does not read)",)
    if kind == "no-config":
        state = torch.load(good, weights_only=True, map_location="cpu")
        del state["config"]
        torch.save(state, dest)
        return ("config: missing", "expected a checkpoint written by `wristmimic train`")
    raise AssertionError(kind)


CHECKPOINT_KINDS = ["text", "random", "truncated", "malicious", "malicious-raw", "protocol-4", "no-config"]


@pytest.mark.parametrize("command", ["evaluate", "view", "resume"])
@pytest.mark.parametrize("kind", CHECKPOINT_KINDS)
def test_broken_checkpoint(work: dict[str, Path], tmp_path: Path, kind: str, command: str) -> None:
    run = tmp_path / "run"
    run.mkdir()
    (run / "config.json").write_bytes((work["run"] / "config.json").read_bytes())
    marker = tmp_path / "code-ran"
    fragments = _bad_checkpoint(kind, work["run"] / "checkpoint.pt", run / "checkpoint.pt", marker)
    before = _listing(tmp_path)
    args = {
        "evaluate": ["evaluate", str(run), "-p", "quick", "-n", "2", "-q"],
        "view": ["view", str(run / "checkpoint.pt"), "-o", str(tmp_path / "v.rrd")],
        "resume": ["train", "--resume", str(run), "-q"],
    }[command]
    line = _clean_error(runner.invoke(app, args), str(run / "checkpoint.pt"), *fragments)
    assert "..." not in line  # nothing cut off mid-sentence
    assert not marker.exists()  # nothing from the file ran
    assert _listing(tmp_path) == before  # no eval folder, no recording, no metrics or checkpoint rewritten


@pytest.mark.parametrize("command", ["evaluate", "view"])
def test_checkpoint_weights_that_do_not_fit_the_network(work: dict[str, Path], tmp_path: Path, command: str) -> None:
    run = tmp_path / "run"
    run.mkdir()
    state = torch.load(work["run"] / "checkpoint.pt", weights_only=True, map_location="cpu")
    state["policy"]["normalizer.mean"] = torch.zeros(3)
    torch.save(state, run / "checkpoint.pt")
    before = _listing(tmp_path)
    args = {
        "evaluate": ["evaluate", str(run), "-p", "quick", "-n", "2", "-q"],
        "view": ["view", str(run), "-o", str(tmp_path / "v.rrd")],
    }[command]
    _clean_error(runner.invoke(app, args), str(run / "checkpoint.pt"), "policy: cannot be rebuilt", "size mismatch")
    assert _listing(tmp_path) == before


@pytest.mark.parametrize("kind", ["random", "malicious", "malicious-raw", "truncated", "protocol-4"])
def test_broken_motion_tensor(tmp_path: Path, kind: str) -> None:
    """The same messages where a dataset's .pt must hold one tensor (load_pt_tensor): convert intermimic."""
    src = write_intermimic_folder(tmp_path / "src")
    motion = src / "motions" / f"{SID}.pt"
    marker = tmp_path / "code-ran"
    fragments = _bad_checkpoint(kind, motion, motion, marker)
    out = tmp_path / "o.h5"
    r = _convert(src, out, tmp_path)
    _clean_error(r, str(motion), *fragments, "expected a tensor saved by torch.save")
    assert not marker.exists() and not out.exists()
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".o.h5")]  # no temporary file either


def test_checkpoint_error_from_the_real_command_line(work: dict[str, Path], tmp_path: Path) -> None:
    """The installed entry point (rich's pretty tracebacks included) prints the same single line."""
    bad = tmp_path / "checkpoint.pt"
    bad.write_text("hello")
    env = dict(os.environ, PYTHONPATH=str(REPO))
    p = subprocess.run(
        [sys.executable, "-m", "wristmimic.cli.main", "evaluate", str(bad)],
        capture_output=True, text=True, env=env, timeout=120,
    )  # fmt: skip
    assert p.returncode == 1 and p.stdout == "", (p.stdout, p.stderr)
    assert "Traceback" not in p.stderr and p.stderr.count("\n") == 1 and p.stderr.startswith(f"error: {bad}: <file>:")


# --------------------------------------------------------------------------------------- evaluation folders


def _broken_summary(folder: Path, kind: str) -> tuple[Path, tuple[str, ...]]:
    import json

    summary = folder / "summary.json"
    doc = json.loads(summary.read_text())
    if kind == "list":
        summary.write_text(json.dumps(doc["scenes"]))
        return summary, ("<root>: holds a JSON list", "expected a JSON object")
    if kind == "scenes-not-objects":
        summary.write_text(json.dumps(dict(doc, scenes=["x"])))
        return summary, ("scenes: holds a JSON list", "scene summaries")
    if kind == "scene-not-a-name":
        summary.write_text(json.dumps(dict(doc, scenes=[dict(doc["scenes"][0], scene="../../x")])))
        return summary, ("scenes[0].scene", "not a plain name")
    if kind == "policy-list":
        summary.write_text(json.dumps(dict(doc, policy=[1])))
        return summary, ("policy: not an object",)
    if kind == "not-utf8":
        summary.write_bytes(b"\xff\xfe{}")
        return summary, ("<file>: not UTF-8 text",)
    table = folder / f"{SID}.parquet"
    if kind == "truncated-parquet":
        table.write_bytes(table.read_bytes()[:200])
        return table, ("<file>: not a readable parquet file (Parquet magic bytes not found in footer)",)
    if kind == "empty-parquet":
        table.write_bytes(b"")
        return table, ("<file>: not a readable parquet file",)
    if kind == "wrong-column-type":
        import pandas as pd

        df = pd.read_parquet(table)
        df["trial"] = "x"
        df.to_parquet(table, index=False)
        return table, ("trial: values of type", "expected int64 values")
    raise AssertionError(kind)


@pytest.mark.parametrize(
    "kind",
    ["list", "scenes-not-objects", "scene-not-a-name", "policy-list", "not-utf8", "truncated-parquet", "empty-parquet",
     "wrong-column-type"],
)  # fmt: skip
def test_broken_evaluation_folder(work: dict[str, Path], tmp_path: Path, kind: str) -> None:
    import shutil

    ev = tmp_path / "ev"
    shutil.copytree(work["eval"], ev)
    path, fragments = _broken_summary(ev, kind)
    before = _listing(tmp_path)
    _clean_error(runner.invoke(app, ["report", str(ev), "-o", str(tmp_path / "rep")]), str(path), *fragments)
    assert _listing(tmp_path) == before and not (tmp_path / "rep").exists()


# --------------------------------------------------------------------------------------------------- URDF


def test_urdf_naming_a_missing_mesh_warns_once_and_uses_the_layout_file(tmp_path: Path) -> None:
    """The URDF's mesh is missing but the layout's ``objects/<name>/<name>.obj`` is there: one warning line that
    names both, and the conversion succeeds (the SkillMimic ParaHome release's pot.urdf needs this)."""
    src = write_intermimic_folder(tmp_path / "src")
    urdf = src / "objects" / "box.urdf"
    urdf.write_text(urdf.read_text().replace("objects/box/box.obj", "objects/box/box_v2.obj"))
    out = tmp_path / "o.h5"
    r = _convert(src, out, tmp_path)
    assert r.exit_code == 0 and r.exception is None, r.output
    warnings = r.stderr.splitlines()
    assert warnings == [f"warning: {urdf}: mesh: objects/box/box_v2.obj not found; using {src / 'objects/box/box.obj'}"]
    assert out.is_file()
    (src / "objects" / "box" / "box.obj").unlink()  # no fallback either: an error, nothing written
    out.unlink()
    r = _convert(src, out, tmp_path)
    _clean_error(r, "box")
    assert not out.exists()
