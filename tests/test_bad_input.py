"""Bad input: one-line errors naming file, key and expectation; non-zero exit; no partial output."""

from __future__ import annotations

import pickle
from pathlib import Path

import numpy as np
import pytest
import torch
from typer.testing import CliRunner

from wristmimic.cli.main import app
from wristmimic.errors import InputError
from wristmimic.safe_io import load_pt_tensor

from synthetic import intermimic_motion, save_pt, write_intermimic_folder, write_parahome_folder

runner = CliRunner()


def _cli(*args: str):
    return runner.invoke(app, list(args))


def _assert_one_line_error(result, *fragments: str) -> None:
    assert result.exit_code != 0
    err = result.stderr.strip()
    assert err.startswith("error: ") and "\n" not in err, err
    for f in fragments:
        assert f in err, (f, err)


@pytest.fixture
def im_src(tmp_path: Path) -> Path:
    return write_intermimic_folder(tmp_path / "src")


def _convert_im(src: Path, out: Path, tmp: Path):
    return _cli("convert", "intermimic", str(src), "-o", str(out), "--hull-cache", str(tmp / "cache"), "-q")


def test_wrong_tensor_shape(im_src: Path, tmp_path: Path) -> None:
    save_pt(im_src / "motions" / "sub1_box_000.pt", np.zeros((30, 500)))
    r = _convert_im(im_src, tmp_path / "o.h5", tmp_path)
    _assert_one_line_error(r, "sub1_box_000.pt", "shape (30, 500)", "591")
    assert not (tmp_path / "o.h5").exists()


def test_nan_values(im_src: Path, tmp_path: Path) -> None:
    d = intermimic_motion(40)
    d[7, 100] = np.nan
    save_pt(im_src / "motions" / "sub1_box_000.pt", d)
    r = _convert_im(im_src, tmp_path / "o.h5", tmp_path)
    _assert_one_line_error(r, "sub1_box_000.pt", "row 7 column 100", "non-finite")
    assert not (tmp_path / "o.h5").exists()


class _Evil:
    def __reduce__(self):
        return (print, ("pwned",))


def test_pickle_with_code_is_refused(im_src: Path, tmp_path: Path) -> None:
    with open(im_src / "motions" / "sub1_box_000.pt", "wb") as f:
        pickle.dump(_Evil(), f)
    r = _convert_im(im_src, tmp_path / "o.h5", tmp_path)
    _assert_one_line_error(r, "sub1_box_000.pt", "tensor")
    assert "pwned" not in r.output
    torch.save({"a": torch.zeros(3)}, im_src / "motions" / "sub1_box_000.pt")  # a dict, not a tensor
    with pytest.raises(InputError, match="holds a dict"):
        load_pt_tensor(im_src / "motions" / "sub1_box_000.pt")


def test_truncated_pt(im_src: Path, tmp_path: Path) -> None:
    p = im_src / "motions" / "sub1_box_000.pt"
    p.write_bytes(p.read_bytes()[:200])
    r = _convert_im(im_src, tmp_path / "o.h5", tmp_path)
    _assert_one_line_error(r, "sub1_box_000.pt", "cannot be read")


def test_missing_humanoid(im_src: Path, tmp_path: Path) -> None:
    (im_src / "humanoid.xml").unlink()
    r = _convert_im(im_src, tmp_path / "o.h5", tmp_path)
    _assert_one_line_error(r, str(im_src), "*.xml", "humanoid")


def test_missing_mesh(im_src: Path, tmp_path: Path) -> None:
    (im_src / "objects" / "box" / "box.obj").unlink()
    r = _convert_im(im_src, tmp_path / "o.h5", tmp_path)
    _assert_one_line_error(r, "box")
    assert not (tmp_path / "o.h5").exists()


def test_missing_humanoid_parahome(tmp_path: Path) -> None:
    src = write_parahome_folder(tmp_path / "src")
    (src / "humanoids" / "s1.xml").unlink()
    r = _cli(
        "convert",
        "skillmimic-parahome",
        str(src),
        "-o",
        str(tmp_path / "o.h5"),
        "-q",
        "--hull-cache",
        str(tmp_path / "c"),
    )
    _assert_one_line_error(r, "001_s1_move_box.pt", "humanoids/s1.xml missing")


def test_output_not_writable(im_src: Path, tmp_path: Path) -> None:
    r = _convert_im(im_src, Path("/proc/o.h5"), tmp_path)
    _assert_one_line_error(r, "/proc/o.h5", "not writable")
    r = _convert_im(im_src, tmp_path / "nope" / "o.h5", tmp_path)
    _assert_one_line_error(r, "does not exist")


def test_truncated_and_foreign_h5_for_inspect_and_validate(tmp_path: Path) -> None:
    foreign = tmp_path / "foreign.h5"
    import h5py

    with h5py.File(foreign, "w") as f:
        f["data"] = np.zeros(3)
    _assert_one_line_error(_cli("inspect", str(foreign)), "foreign.h5", "format")
    r = _cli("validate", str(foreign))
    assert r.exit_code == 1 and "foreign.h5" in r.stderr
    trunc = tmp_path / "trunc.h5"
    trunc.write_bytes(foreign.read_bytes()[:100])
    _assert_one_line_error(_cli("inspect", str(trunc)), "trunc.h5", "not a readable HDF5 file")
