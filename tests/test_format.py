"""Format v1: writer/reader round trip, lazy reads, atomic writes, version and foreign-file checks."""

from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np
import pytest

from wristmimic.convert.common import ConvertOptions
from wristmimic.convert.intermimic import convert_intermimic
from wristmimic.errors import InputError, SchemaVersionError
from wristmimic.format import SCHEMA_VERSION, DatasetWriter, open_dataset
from wristmimic.format.validate import validate

from synthetic import write_intermimic_folder


@pytest.fixture(scope="module")
def synth_h5(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = write_intermimic_folder(tmp_path_factory.mktemp("src"), ("sub1_box_000", "sub1_box_001"), T=70)
    out = tmp_path_factory.mktemp("out") / "synth.h5"
    cache = tmp_path_factory.mktemp("hulls")
    convert_intermimic(root, out, options=ConvertOptions(hull_cache_dir=cache, show_progress=False))
    return out


def test_root_attributes_and_index(synth_h5: Path) -> None:
    with open_dataset(synth_h5) as ds:
        a = ds.attrs
        assert a["schema_version"] == SCHEMA_VERSION and a["quat_order"] == "wxyz" and a["up_axis"] == "z"
        assert a["fps"] == 30.0 and a["units"] == "m" and a["source_format"] == "intermimic-pt"
        assert set(a["input_sha256"]) >= {"humanoid.xml", "motions/sub1_box_000.pt", "objects/box.urdf"}
        assert ds.sequence_ids == ["sub1_box_000", "sub1_box_001"]
        assert [r["num_frames"] for r in ds.index()] == [70, 70]


def test_reader_returns_humanoid_objects_and_lazy_arrays(synth_h5: Path) -> None:
    with open_dataset(synth_h5) as ds:
        seq = ds.sequence("sub1_box_000")
        assert seq.object_ids == ["box"] and seq.humanoid_id == "humanoid_sub1"
        d = seq["body_pos"]
        assert d.shape == (70, 52, 3) and d.chunks[0] == 64 and d.compression == "gzip"
        part = seq.array("body_pos", slice(10, 20))
        assert part.shape == (10, 52, 3)
        rec = seq.load()
        assert np.array_equal(rec.body_pos[10:20], part)
        hum = ds.humanoid(seq.humanoid_id)
        assert hum.num_bodies == 52 and len(hum.roles["fingers"]) == 30
        assert [hum.body_names[i] for i in hum.roles["wrists"]] == ["L_Wrist", "R_Wrist"]
        obj = ds.object("box")
        assert obj.num_hulls >= 1 and obj.surface_points.shape == (1024, 3) and obj.mass > 0


def test_validate_passes_then_lists_every_problem(synth_h5: Path, tmp_path: Path) -> None:
    assert validate(synth_h5) == []
    bad = tmp_path / "bad.h5"
    bad.write_bytes(synth_h5.read_bytes())
    with h5py.File(bad, "r+") as f:
        f["sequences/sub1_box_000/root_quat"][0] = [2.0, 0, 0, 0]
        f["sequences/sub1_box_000/contacts/labels"][3, 4] = 5
        f["sequences/sub1_box_001/body_pos"][1, 1, 1] = np.nan
        f["sequences/sub1_box_001"].attrs["humanoid_id"] = "nobody"
        del f["humanoids/humanoid_sub1/roles/wrists"]
    problems = validate(bad)
    text = "\n".join(problems)
    assert "sub1_box_000/root_quat: 1 quaternions not unit" in text
    assert "sub1_box_000/contacts/labels: 1 values outside" in text
    assert "roles/wrists: missing" in text
    assert "humanoid_id 'nobody' not in /humanoids" in text
    assert len(problems) >= 4


def test_other_major_version_is_rejected(synth_h5: Path, tmp_path: Path) -> None:
    p = tmp_path / "v2.h5"
    p.write_bytes(synth_h5.read_bytes())
    with h5py.File(p, "r+") as f:
        f.attrs["schema_version"] = "2.0.0"
    with pytest.raises(SchemaVersionError, match=r"v2\.h5: /\.schema_version: is '2\.0\.0'"):
        open_dataset(p)
    with h5py.File(p, "r+") as f:
        f.attrs["schema_version"] = "1.7.0"  # another minor is fine
    open_dataset(p).close()


def test_foreign_and_truncated_files_get_one_line_errors(synth_h5: Path, tmp_path: Path) -> None:
    foreign = tmp_path / "foreign.h5"
    with h5py.File(foreign, "w") as f:
        f["x"] = 1
    with pytest.raises(InputError, match="foreign.h5: /.format: missing") as e:
        open_dataset(foreign)
    assert "\n" not in str(e.value)
    trunc = tmp_path / "trunc.h5"
    trunc.write_bytes(synth_h5.read_bytes()[:5000])
    with pytest.raises(InputError, match="trunc.h5: not a readable HDF5 file"):
        open_dataset(trunc)
    text = tmp_path / "notes.h5"
    text.write_text("hello")
    assert validate(text)[0].startswith(str(text))
    with pytest.raises(InputError, match="is a folder, expected a canonical .h5 file"):
        open_dataset(tmp_path)
    with pytest.raises(InputError, match="no such file"):
        open_dataset(tmp_path / "missing.h5")


def test_writer_leaves_nothing_behind_on_failure(tmp_path: Path) -> None:
    out = tmp_path / "out.h5"
    with (
        pytest.raises(RuntimeError),
        DatasetWriter(out, source_dataset="x", source_format="y", converter="z", input_sha256={}),
    ):
        raise RuntimeError("boom")
    assert list(tmp_path.iterdir()) == []


def test_unwritable_output_folder_is_reported(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="does not exist"):
        DatasetWriter(
            tmp_path / "missing" / "o.h5", source_dataset="x", source_format="y", converter="z", input_sha256={}
        ).__enter__()
    # /proc refuses new files even for root
    with pytest.raises(InputError, match="not writable"):
        DatasetWriter(
            Path("/proc/o.h5"), source_dataset="x", source_format="y", converter="z", input_sha256={}
        ).__enter__()


def test_written_files_get_the_usual_permissions(tmp_path: Path) -> None:
    import os

    from wristmimic.safe_io import atomic_output

    with atomic_output(tmp_path / "out.txt") as tmp:
        tmp.write_text("x")
    umask = os.umask(0)
    os.umask(umask)
    assert (tmp_path / "out.txt").stat().st_mode & 0o777 == 0o666 & ~umask


_CTRL_C_SCRIPT = """
import collections, os, signal, sys, threading, time
from pathlib import Path
import numpy as np
from wristmimic.format import DatasetWriter
from wristmimic.format.records import HumanoidRecord

signal.signal(signal.SIGINT, signal.default_int_handler)
n = 200_000
human = HumanoidRecord(name="h", family="smplx", mjcf="<mujoco/>" * 100_000,
                       body_names=[f"body_{i}" for i in range(n)], parents=np.full(n, -1, np.int32),
                       joint_bodies=np.zeros(0, np.int32), roles={})
folder = Path(sys.argv[1])
def writer(out):
    return DatasetWriter(out, source_dataset="x", source_format="y", converter="z", input_sha256={})
t0 = time.perf_counter()
with writer(folder / "time.h5") as w:
    w.add_humanoid("h", human)
one = time.perf_counter() - t0
(folder / "time.h5").unlink()
seen = collections.Counter()
for k in range(40):
    out = folder / f"o{k}.h5"
    timer = threading.Timer(one * (k + 0.5) / 40, os.kill, (os.getpid(), signal.SIGINT))
    finished = False
    try:
        with writer(out) as w:
            timer.start()
            w.add_humanoid("h", human)
            w.add_humanoid("h2", human)
        finished = True  # a loaded machine can finish the writes before the timer fires
        timer.join()
        time.sleep(0.05)
    except KeyboardInterrupt:
        seen["late" if finished else "interrupted"] += 1
        assert finished or not out.exists(), out
    except BaseException as exc:
        seen[type(exc).__name__] += 1
    left = sorted(p.name for p in folder.iterdir() if p.name != out.name)
    assert left == [], left
    out.unlink(missing_ok=True)
print(dict(seen))
"""


def test_ctrl_c_in_the_middle_of_an_hdf5_string_write_is_a_clean_interrupt(tmp_path: Path) -> None:
    """h5py converts variable-length strings in a Python callback. A KeyboardInterrupt raised inside it broke
    HDF5's state: ``TypeError: Operation not defined for data type class`` or a segfault on close (seen in
    ``convert`` under Ctrl-C). SIGINT is sent at 40 moments of such writes, in a subprocess: each one must end as
    a plain KeyboardInterrupt with no file left behind (one that a loaded machine delivers after the writes have
    finished leaves the finished file; at least 30 of the 40 must land inside the writes)."""
    import ast
    import subprocess
    import sys

    r = subprocess.run(
        [sys.executable, "-c", _CTRL_C_SCRIPT, str(tmp_path)], capture_output=True, text=True, timeout=300
    )
    assert r.returncode == 0, r.stderr[-2000:]
    seen = ast.literal_eval(r.stdout.strip())
    # every SIGINT ends as a KeyboardInterrupt; most land inside the writes (on a loaded machine some come after
    # them, when the written file rightly stays: 13 of 40 at nice 19 beside a 2-thread training run, 2026-12-04)
    assert set(seen) <= {"interrupted", "late"} and seen.get("interrupted", 0) >= 20, r.stdout + r.stderr[-2000:]


def test_ctrl_c_right_after_the_temporary_file_is_made_leaves_nothing(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The fault suite sends Ctrl-C as soon as the temporary output appears: a SIGINT between its creation and
    the code that guards it must still remove it."""
    import os
    import signal

    from wristmimic import safe_io

    if signal.getsignal(signal.SIGINT) is not signal.default_int_handler:
        pytest.skip("SIGINT is not handled by Python's default handler in this process")
    real_close = os.close

    def close_then_ctrl_c(fd: int) -> None:
        real_close(fd)
        os.kill(os.getpid(), signal.SIGINT)

    monkeypatch.setattr(safe_io.os, "close", close_then_ctrl_c)
    with pytest.raises(KeyboardInterrupt):
        DatasetWriter(
            tmp_path / "o.h5", source_dataset="x", source_format="y", converter="z", input_sha256={}
        ).__enter__()
    monkeypatch.undo()
    assert list(tmp_path.iterdir()) == []
