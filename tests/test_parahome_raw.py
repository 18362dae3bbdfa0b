"""Raw ParaHome converter on a synthetic sequence made by ParaHome's documented forward kinematics."""

from __future__ import annotations

import json
import os
import pickle
import shutil
from pathlib import Path

import numpy as np
import pytest
from synthetic_raw import BODY23, HAND25, write_parahome_raw
from typer.testing import CliRunner

from wristmimic.cli.main import app
from wristmimic.convert.common import ConvertOptions
from wristmimic.convert.parahome_raw import HAND20, convert_parahome_raw, read_annotations
from wristmimic.errors import InputError
from wristmimic.format import open_dataset
from wristmimic.format.validate import validate
from wristmimic.humanoid.parahome import BODY_NAMES
from wristmimic.rotations import matrix_to_quat, quat_angle

T = 40


def _opts(tmp: Path) -> ConvertOptions:
    return ConvertOptions(hull_cache_dir=tmp / "hulls", show_progress=False)


@pytest.fixture(scope="module")
def raw(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict, Path]:
    root = tmp_path_factory.mktemp("parahome_raw")
    truth = write_parahome_raw(root / "data", "s7", T)
    out = root / "s7.h5"
    convert_parahome_raw(root / "data", "s7", out, annotations=[0, 1], frames=["5:25"], options=_opts(root))
    return root, truth, out


def _truth_index(name: str) -> int:
    if name in BODY23:
        return BODY23.index(name)
    side = "Left" if "Left" in name else "Right"
    return (23 if side == "Left" else 48) + HAND25.index(name.removeprefix(f"j{side}"))


def test_file_validates_and_clips_are_cut(raw: tuple[Path, dict, Path]) -> None:
    _, _, out = raw
    assert validate(out) == []
    with open_dataset(out) as ds:
        assert ds.sequence_ids == ["s7_0_20", "s7_20_40", "s7_5_25"]
        assert ds.sequence("s7_0_20").text == "move kettle"
        assert ds.sequence("s7_20_40").text == "open microwave"
        assert ds.sequence("s7_5_25").text == "move kettle; open microwave"
        assert ds.sequence("s7_5_25").num_frames == 20
        assert ds.h5.attrs["converter"] == "parahome-raw"
        h = ds.humanoid("s7")
        assert list(h.body_names) == list(BODY_NAMES) and h.family == "parahome"


def test_fk_reproduces_joint_positions_and_rotations(raw: tuple[Path, dict, Path]) -> None:
    _, truth, out = raw
    idx = [_truth_index(n) for n in BODY_NAMES]
    with open_dataset(out) as ds:
        s = ds.sequence("s7_5_25")
        bp = s.array("body_pos")
        np.testing.assert_allclose(bp, truth["joints"][5:25][:, idx], atol=2e-5)
        assert s.extra["fk_position_error_m"]["max"] < 2e-5
        bq = s.array("body_quat")
    rg = truth["gt"][5:25, :3, :3]
    # right wrist: R_g R_body[10] R_hand[right wrist]; a right finger: R_g R_body[10] R_hand[20 + k]
    wrist = matrix_to_quat(rg @ truth["rb"][5:25, 10] @ truth["rh"][5:25, 20])
    assert np.degrees(quat_angle(bq[:, BODY_NAMES.index("jRightWrist")], wrist)).max() < 1e-3
    k = HAND20.index("SecondPIP")
    pip = matrix_to_quat(rg @ truth["rb"][5:25, 10] @ truth["rh"][5:25, 20 + k])
    assert np.degrees(quat_angle(bq[:, BODY_NAMES.index("jRightSecondPIP")], pip)).max() < 1e-3
    knee = matrix_to_quat(rg @ truth["rb"][5:25, BODY23.index("jLeftKnee")])
    assert np.degrees(quat_angle(bq[:, BODY_NAMES.index("jLeftKnee")], knee)).max() < 1e-3


def test_scene_objects_parts_and_static_flags(raw: tuple[Path, dict, Path]) -> None:
    _, _, out = raw
    with open_dataset(out) as ds:
        assert sorted(ds.object_ids) == sorted(
            ["kettle", "diningtable", "cup", "drawer_base", "drawer_part1", "microwave_base", "microwave_part1"]
        )  # book is not in the scene
        static = {o: ds.object(o).static for o in ds.object_ids}
        assert static == {
            "kettle": False, "diningtable": True, "cup": True, "drawer_base": True, "drawer_part1": False,
            "microwave_base": True, "microwave_part1": False,
        }  # fmt: skip
        assert ds.object("cup").extra["static_rule"].startswith("motion")
        assert ds.object("diningtable").extra["static_rule"] == "name"
        drawer = ds.object("drawer_part1").extra
        assert drawer["parent"] == "drawer_base" and drawer["joint"]["type"] == "prismatic"
        np.testing.assert_allclose(drawer["joint"]["axis"], [1, 0, 0], atol=1e-6)
        assert drawer["joint"]["range"][1] == pytest.approx(0.24, abs=1e-6)
        door = ds.object("microwave_part1").extra
        assert door["joint"]["type"] == "revolute" and abs(door["joint"]["axis"][2]) > 0.999
        assert door["joint"]["range"][1] - door["joint"]["range"][0] == pytest.approx(np.pi / 2, abs=1e-6)
        s = ds.sequence("s7_0_20")
        assert s.object_ids[:3] == ["drawer_part1", "kettle", "microwave_part1"]  # dynamic first
        assert s.extra["held_frames"] == {"cup": 1, "kettle": 2}
        assert len(s.extra["joint_states"]["drawer_part1"]) == 20


def test_object_poses_follow_transforms_and_hold_gaps(raw: tuple[Path, dict, Path]) -> None:
    root, truth, out = raw
    tf = pickle.loads((root / "data/seq/s7/object_transformations.pkl").read_bytes())
    with open_dataset(out) as ds:
        s = ds.sequence("s7_0_20")
        k = s.object_ids.index("kettle")
        pos, quat = s.array("object_pos")[:, k], s.array("object_quat")[:, k]
    for f in (0, 4, 8):
        np.testing.assert_allclose(pos[f], tf[f]["kettle_base"][:3, 3], atol=1e-6)
        assert np.degrees(quat_angle(quat[f], matrix_to_quat(tf[f]["kettle_base"][:3, :3]))) < 1e-3
    np.testing.assert_allclose(pos[5], pos[4], atol=1e-7)  # missing in frames 5, 6: held
    np.testing.assert_allclose(pos[6], pos[4], atol=1e-7)


def test_contacts_are_on_the_hand_holding_the_kettle(raw: tuple[Path, dict, Path]) -> None:
    _, _, out = raw
    with open_dataset(out) as ds:
        s = ds.sequence("s7_0_20")
        h = ds.humanoid("s7")
        lab = s.array("contacts/labels")
        hand = s.array("contacts/hand")
    right = np.asarray(h.roles["right_hand"])
    left = np.asarray(h.roles["left_hand"])
    assert (lab[:, right] == 1).any(axis=1).mean() > 0.5
    assert not (lab[:, left] == 1).any()
    assert hand[:, 1].mean() > 0.5 and not hand[:, 0].any()


def test_both_annotation_file_names_are_read(tmp_path: Path) -> None:
    (tmp_path / "text_annotations.json").write_text(json.dumps({"10 19": "b", "0 9": "a"}))
    ann, path = read_annotations(tmp_path, 15)
    assert ann == [(0, 10, "a"), (10, 15, "b")] and path.name == "text_annotations.json"
    (tmp_path / "text_annotations.json").write_text(json.dumps({"9 0": "bad"}))
    with pytest.raises(InputError, match="9 0: not a frame range"):
        read_annotations(tmp_path, 15)


def _copy(raw: tuple[Path, dict, Path], tmp_path: Path) -> Path:
    shutil.copytree(raw[0] / "data", tmp_path / "data")
    return tmp_path / "data"


def test_missing_mesh_fails_or_is_skipped(raw: tuple[Path, dict, Path], tmp_path: Path) -> None:
    data = _copy(raw, tmp_path)
    (data / "scan/cup/simplified/base.obj").unlink()
    out = tmp_path / "o.h5"
    with pytest.raises(InputError, match=r"cup/simplified/base.obj: cup_base: mesh missing"):
        convert_parahome_raw(data, "s7", out, frames=["0:10"], options=_opts(tmp_path))
    assert not out.exists() and not list(tmp_path.glob(".o.h5*"))
    r = convert_parahome_raw(data, "s7", out, frames=["0:10"], skip_missing=True, options=_opts(tmp_path))
    assert "cup_base" in r.skipped and out.exists()


def test_code_in_a_sequence_pickle_is_refused(raw: tuple[Path, dict, Path], tmp_path: Path) -> None:
    data = _copy(raw, tmp_path)
    marker = tmp_path / "pwned"

    class Evil:
        def __reduce__(self):
            return (os.system, (f"touch {marker}",))

    (data / "seq/s7/joint_states.pkl").write_bytes(pickle.dumps({"drawer_part1": Evil()}))
    out = tmp_path / "o.h5"
    with pytest.raises(InputError, match="joint_states.pkl: <pickle>: refused global"):
        convert_parahome_raw(data, "s7", out, options=_opts(tmp_path))
    assert not marker.exists() and not out.exists()


def test_bad_inputs_name_file_key_and_expectation(raw: tuple[Path, dict, Path], tmp_path: Path) -> None:
    data = _copy(raw, tmp_path)
    out = tmp_path / "o.h5"
    with pytest.raises(InputError, match=r"--frames: 30:10 is not|outside"):
        convert_parahome_raw(data, "s7", out, frames=["30:10"], options=_opts(tmp_path))
    with pytest.raises(InputError, match=r"seq/s99: sequence folder not found"):
        convert_parahome_raw(data, "s99", out, options=_opts(tmp_path))
    body = pickle.loads((data / "seq/s7/body_joint_orientations.pkl").read_bytes())
    (data / "seq/s7/hand_joint_orientations.pkl").write_bytes(pickle.dumps(body))
    with pytest.raises(
        InputError, match=r"hand_joint_orientations.pkl: <array>: shape \(40, 23, 6\) \(expected \(40, 40, 6\)\)"
    ):
        convert_parahome_raw(data, "s7", out, options=_opts(tmp_path))
    assert not out.exists()


def test_cli_parahome_raw(raw: tuple[Path, dict, Path], tmp_path: Path) -> None:
    out = tmp_path / "c.h5"
    args = ["convert", "parahome-raw", str(raw[0] / "data"), "-s", "s7", "--frames", "0:12", "-o", str(out)]
    r = CliRunner().invoke(app, [*args, "-q", "--hull-cache", str(tmp_path / "hulls")])
    assert r.exit_code == 0, r.output
    assert "1 sequence(s), 7 object(s)" in r.output and validate(out) == []
    h = CliRunner().invoke(app, ["convert", "parahome-raw", "--help"])
    assert h.exit_code == 0 and "Example" in h.output
