"""The data gate: every command that reads a canonical sequence checks that sequence, its humanoid and its
objects first (``wristmimic.format.validate.check_sequence``) and stops with validate's one-line message, exit 1,
no traceback and no output; ``validate`` reports the same problems, range checks included."""

from __future__ import annotations

import shutil
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path

import h5py
import numpy as np
import pytest
from typer.testing import CliRunner

from wristmimic.cli.main import app
from wristmimic.errors import InputError
from wristmimic.format import validate as V
from wristmimic.format.validate import check_sequence, validate
from wristmimic.rl import TrainSpec, preset, start_run

from synthetic import write_intermimic_folder

SID, OTHER, T = "sub1_box_000", "sub1_box_001", 40
S = f"sequences/{SID}/"
REPO = Path(__file__).resolve().parents[1]
cli = CliRunner()
TINY = preset("cpu", num_envs=2, horizon=4, minibatch_size=8, epochs=1, actor_hidden=(16,), critic_hidden=(16,),
              max_frames=8)  # fmt: skip


@pytest.fixture(scope="module")
def good(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Two converted sequences (same humanoid, object ``box``), T frames each; valid."""
    from wristmimic.convert.common import ConvertOptions
    from wristmimic.convert.intermimic import convert_intermimic

    tmp = tmp_path_factory.mktemp("gate")
    out = tmp / "good.h5"
    src = write_intermimic_folder(tmp / "im", (SID, OTHER), T=T)
    convert_intermimic(src, out, options=ConvertOptions(hull_cache_dir=tmp / "c", show_progress=False))
    assert validate(out) == []
    return out


def _copy(good: Path, dst: Path, edit: Callable[[h5py.File], None]) -> Path:
    shutil.copyfile(good, dst)
    with h5py.File(dst, "r+") as f:
        edit(f)
    return dst


def _set(name: str, index: tuple, value: object) -> Callable[[h5py.File], None]:
    def edit(f: h5py.File) -> None:
        f[name][index] = value

    return edit


def _root_quat_of_length_2(f: h5py.File) -> None:
    q = f[S + "root_quat"][:, :2]
    del f[S + "root_quat"]
    f[S + "root_quat"] = q


def _hull_offsets_past_the_end(f: h5py.File) -> None:
    o = f["objects/box/hulls/vertex_offsets"][()]
    o[-1] += 3
    f["objects/box/hulls/vertex_offsets"][...] = o


def _mass(f: h5py.File) -> None:
    f["objects/box"].attrs["mass"] = 1e9


def _object_ids_not_json(f: h5py.File) -> None:
    f[S].attrs["object_ids"] = '["box"'


# name -> (edit, key the message names, what it says)
BAD = {
    "nan_body_pos": (_set(S + "body_pos", (25, 3, 1), np.nan), S + "body_pos", "1 non-finite values"),
    "inf_root": (_set(S + "root_pos", (2, 2), np.inf), S + "root_pos", "1 non-finite values"),
    "1e30_root": (_set(S + "root_pos", (2, 0), 1e30), S + "root_pos", "1 values with |x| > 100 m (max 1e+30"),
    "quat_length_2": (_root_quat_of_length_2, S + "root_quat", f"shape ({T}, 2), expected ({T}, 4)"),
    "non_unit_quat": (_set(S + "joint_quat", (4, 7), [0.5, 0, 0, 0]), S + "joint_quat", "1 quaternions not unit"),
    "hull_offsets": (_hull_offsets_past_the_end, "objects/box/hulls", "offsets inconsistent"),
    "window_500_10": (_set(S + "contacts/window", slice(None), [500, 10]), S + "contacts/window", "[500, 10]"),
    "joint_angle_1e30": (_set(S + "joint_angles", (3, 2, 0), 1e30), S + "joint_angles", "|x| > 3.14259 rad"),
    "mass_1e9": (_mass, "objects/box", "mass 1e+09 kg implausible (expected 0.001 to 10000 kg)"),
    "object_ids_not_json": (_object_ids_not_json, S[:-1], "unreadable attributes"),
}


def _one_line_error(r, path: Path, key: str, text: str) -> str:
    """Exit 1 through the CLI's error wrapper (not an uncaught exception), one ``error:`` line naming the file,
    the key and the problem; returns the message."""
    assert r.exit_code == 1, r.output
    assert r.exception is None or isinstance(r.exception, SystemExit), repr(r.exception)
    assert "Traceback" not in r.output
    err = r.stderr.strip()
    assert err.startswith("error: ") and "\n" not in err, err
    assert f"{path}: {key}: " in err and text in err, (key, text, err)
    return err[len("error: ") :]


@pytest.mark.parametrize("case", list(BAD))
def test_every_command_refuses_bad_data_before_writing(good: Path, tmp_path: Path, case: str) -> None:
    edit, key, text = BAD[case]
    bad = _copy(good, tmp_path / "bad.h5", edit)
    outs = {c: tmp_path / c for c in ("scene", "view", "train", "swap")}
    for d in outs.values():
        d.mkdir()
    commands = {
        "scene": ["scene", str(bad), SID, "-o", str(outs["scene"] / "scene.xml")],
        "view": ["view", str(bad), "--sequence", SID, "-o", str(outs["view"] / "ref.rrd")],
        "train": ["train", str(bad), "--scene", SID, "--num-envs", "2", "--max-frames", "16", "-q", "--nthread", "1",
                  "--out", str(outs["train"])],
        "swap": ["humanoid", "swap-hands", str(bad), SID, "--hand", "smplx-free", "-o", str(outs["swap"] / "s.h5")],
    }  # fmt: skip
    messages = {c: _one_line_error(cli.invoke(app, args), bad, key, text) for c, args in commands.items()}
    assert len(set(messages.values())) == 1, messages  # one gate, one message
    for c, d in outs.items():
        assert list(d.iterdir()) == [], (c, list(d.iterdir()))  # no scene, recording, run folder or temp file
    with pytest.raises(InputError) as e:
        check_sequence(bad, SID)
    assert str(e.value) == messages["scene"]
    r = cli.invoke(app, ["validate", str(bad)])
    assert r.exit_code == 1 and messages["scene"] in r.stderr.splitlines(), r.stderr  # validate's own wording


def test_gate_checks_only_the_sequence_a_command_uses(good: Path, tmp_path: Path) -> None:
    bad = _copy(good, tmp_path / "bad.h5", _set(f"sequences/{OTHER}/root_pos", (0, 0), 1e30))
    check_sequence(bad, SID)  # the other sequence's data is not this command's
    with pytest.raises(InputError, match=f"sequences/{OTHER}/root_pos: 1 values with"):
        check_sequence(bad, OTHER)
    r = cli.invoke(app, ["scene", str(bad), SID, "-o", str(tmp_path / "ok.xml")])
    assert r.exit_code == 0 and (tmp_path / "ok.xml").is_file(), r.output
    with pytest.raises(InputError, match="no such sequence"):
        check_sequence(bad, "nope")
    problems = validate(bad)
    assert len(problems) == 1 and problems[0].startswith(f"sequences/{OTHER}/root_pos"), problems


def test_validate_range_and_consistency_checks(good: Path, tmp_path: Path) -> None:
    def many(f: h5py.File) -> None:
        f[S + "object_pos"][1, 0, 2] = -250.0  # beyond 100 m
        f[S + "contacts/distance"][0, 0] = -0.5
        fcf = f[S + "contacts/first_contact_frame"][()]
        f[S + "contacts/first_contact_frame"][...] = [T + 5, fcf[1]]
        f["objects/box/com"][...] = [20.0, 0, 0]  # 20 m from the object's frame
        f["objects/box"].attrs["density"] = 0.0
        f["objects/box/inertia"][...] = np.diag([1.0, 1.0, 5.0])  # 5 > 1 + 1: no rigid body has it
        f[f"sequences/{OTHER}/contacts/window"][...] = [-1, -1]

    problems = "\n".join(validate(_copy(good, tmp_path / "bad.h5", many)))
    assert f"{S}object_pos: 1 values with |x| > 100 m (max 250" in problems
    assert f"{S}contacts/distance: 1 negative distances" in problems
    assert f"{S}contacts/first_contact_frame: [{T + 5}," in problems and f"outside [-1, {T})" in problems
    assert "objects/box/com: 1 values with |x| > 10 m" in problems
    assert "objects/box: density 0 kg/m^3 implausible" in problems
    assert "objects/box/inertia: principal moments [1.0, 1.0, 5.0] break A + B >= C" in problems
    assert f"sequences/{OTHER}/contacts/window: [-1, -1], expected [0, 15]" in problems  # its t_c is 0


def test_window_must_surround_the_first_contact(good: Path, tmp_path: Path) -> None:
    """A window that is in range but not [t_c - t_b, t_c + t_a] around the earliest first contact is refused."""

    def shift(f: h5py.File) -> None:
        f[S + "contacts/hand"][:, 0] = False
        f[S + "contacts/hand"][10:20, 0] = True
        f[S + "contacts/first_contact_frame"][...] = [10, -1]
        f[S + "contacts/window"][...] = [1, 26]  # t_c 10, t_b 10, t_a 15: [0, 25] expected

    with pytest.raises(InputError, match=r"contacts/window: \[1, 26\], expected \[0, 25\]"):
        check_sequence(_copy(good, tmp_path / "shifted.h5", shift), SID)

    def shift_and_fix(f: h5py.File) -> None:
        shift(f)
        f[S + "contacts/window"][...] = [0, 25]

    fixed = _copy(good, tmp_path / "fixed.h5", shift_and_fix)
    check_sequence(fixed, SID)
    late = _copy(fixed, tmp_path / "late.h5", _set(S + "contacts/first_contact_frame", slice(None), [25, -1]))
    with pytest.raises(InputError, match="first_contact_frame: \\[25, -1\\]: no contact of hand 0 at frame 25"):
        check_sequence(late, SID)


def test_gate_runs_once_per_command_and_again_when_the_file_changes(
    good: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    copy = _copy(good, tmp_path / "copy.h5", lambda f: None)
    calls: list[str] = []
    inner = V.sequence_array_problems
    monkeypatch.setattr(V, "sequence_array_problems", lambda ds, seq: calls.append(seq.id) or inner(ds, seq))
    start_run(TrainSpec(copy, SID, "wristmimic", 0, "cpu", TINY), tmp_path / "run", nthread=1, progress=False)
    assert calls == [SID]  # the run check and the environment share one pass of the gate
    with h5py.File(copy, "r+") as f:
        f[S + "body_pos"][0, 0, 0] = np.nan
    with pytest.raises(InputError, match="body_pos: 1 non-finite values"):
        check_sequence(copy, SID)
    assert calls == [SID, SID]


def test_run_on_bad_data_from_before_the_gate_is_refused(
    good: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The reported case: a run trained on a sequence with one NaN in body_pos (here beyond --ref-frames, so that
    training itself is sane) before the gate existed. evaluate, view and train --resume now refuse it, leave no
    output and do not touch the run."""
    import wristmimic.rl.train as train_mod
    import wristmimic.scene as scene_mod

    edit, key, text = BAD["nan_body_pos"]
    bad = _copy(good, tmp_path / "bad.h5", edit)
    with monkeypatch.context() as m:  # what main did: no gate
        m.setattr(train_mod, "check_sequence", lambda ds, sid: None)
        m.setattr(scene_mod, "check_sequence", lambda ds, sid: None)
        spec = TrainSpec(bad, SID, "wristmimic", 0, "cpu", TINY, ref_frames=20)
        run = start_run(spec, tmp_path / "run", nthread=1, progress=False).run_dir
    before = {p.name: p.read_bytes() for p in run.iterdir() if p.is_file()}
    r = cli.invoke(app, ["evaluate", str(run), "-p", "quick", "-n", "2", "--num-envs", "2", "--nthread", "1", "-q"])
    _one_line_error(r, bad, key, text)
    r = cli.invoke(app, ["view", str(run), "-o", str(tmp_path / "rollout.rrd")])
    _one_line_error(r, bad, key, text)
    r = cli.invoke(app, ["train", "--resume", str(run), "--max-frames", "64", "-q", "--nthread", "1"])
    _one_line_error(r, bad, key, text)
    assert not (tmp_path / "rollout.rrd").exists() and not (run / "eval").exists()
    assert {p.name: p.read_bytes() for p in run.iterdir() if p.is_file()} == before  # nothing lost or changed


def test_real_process_prints_one_line_and_leaves_no_run(good: Path, tmp_path: Path) -> None:
    edit, key, text = BAD["nan_body_pos"]
    bad = _copy(good, tmp_path / "bad.h5", edit)
    args = [sys.executable, "-m", "wristmimic.cli.main", "train", str(bad), "--scene", SID, "--max-frames", "16"]
    p = subprocess.run([*args, "-q", "--out", str(tmp_path / "runs")], capture_output=True, text=True, cwd=REPO)
    assert p.returncode == 1 and p.stdout == "", (p.stdout, p.stderr)
    assert p.stderr.count("\n") == 1 and p.stderr.startswith(f"error: {bad}: {key}: {text}"), p.stderr
    assert not (tmp_path / "runs").exists()
