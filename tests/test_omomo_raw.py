"""Raw OMOMO converter on synthetic records and a synthetic SMPL-X model file (the real smplx code path)."""

from __future__ import annotations

import pickle
import shutil
from pathlib import Path

import numpy as np
import pytest
import torch
from synthetic_raw import joblib_like_bytes, omomo_record, write_omomo_raw, write_smplx_model
from typer.testing import CliRunner

from wristmimic.cli.main import app
from wristmimic.convert.common import ConvertOptions
from wristmimic.convert.omomo_raw import convert_omomo_raw, read_records
from wristmimic.errors import InputError
from wristmimic.format import open_dataset
from wristmimic.format.validate import validate
from wristmimic.humanoid.smplx_body import SMPLX_INDEX, SmplxModels
from wristmimic.rotations import matrix_to_quat, quat_angle, quat_rotate
from wristmimic.safe_io import safe_pickle_load


def _opts(tmp: Path) -> ConvertOptions:
    return ConvertOptions(hull_cache_dir=tmp / "hulls", show_progress=False)


@pytest.fixture(scope="module")
def omomo(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path, Path, Path]:
    """(records file, captured_objects, SMPL-X models folder, converted file)."""
    root = tmp_path_factory.mktemp("omomo_raw")
    models = root / "models"
    write_smplx_model(models, "male")
    pkl, objs = write_omomo_raw(root)
    out = root / "omomo.h5"
    convert_omomo_raw(pkl, objs, out, smplx_models=models, options=_opts(root))
    return pkl, objs, models, out


def test_file_validates_with_humanoids_per_subject(omomo: tuple[Path, Path, Path, Path]) -> None:
    _, _, _, out = omomo
    assert validate(out) == []
    with open_dataset(out) as ds:
        assert ds.sequence_ids == ["sub1_largebox_000", "sub1_mop_000", "sub2_largebox_001"]
        assert sorted(ds.humanoid_ids) == ["sub1", "sub2"]
        assert ds.humanoid("sub1").family == "smplx" and len(ds.humanoid("sub1").body_names) == 52
        assert ds.sequence("sub1_mop_000").humanoid_id == "sub1"
        assert ds.h5.attrs["up_axis"] == "z" and ds.h5.attrs["converter"] == "omomo-raw"


def test_fk_equals_the_smplx_model_joints(omomo: tuple[Path, Path, Path, Path]) -> None:
    pkl, _, models, out = omomo
    rec = safe_pickle_load(pkl)[0]
    with open_dataset(out) as ds:
        s = ds.sequence("sub1_largebox_000")
        body_pos = s.array("body_pos")
        assert s.extra["smplx_joint_error_m"] < 1e-6
    model, _ = SmplxModels(models).model("male", 16)
    T = len(rec["trans"])
    z = torch.zeros
    with torch.no_grad():
        o = model(
            betas=torch.from_numpy(np.repeat(rec["betas"].reshape(1, 16), T, 0)),
            global_orient=torch.from_numpy(rec["root_orient"]),
            body_pose=torch.from_numpy(rec["pose_body"]),
            transl=torch.from_numpy(rec["trans"]),
            left_hand_pose=z(T, 45, dtype=torch.float64), right_hand_pose=z(T, 45, dtype=torch.float64),
            jaw_pose=z(T, 3, dtype=torch.float64), leye_pose=z(T, 3, dtype=torch.float64),
            reye_pose=z(T, 3, dtype=torch.float64), expression=z(T, 10, dtype=torch.float64),
        )  # fmt: skip
    joints = o.joints[:, :55].numpy()[:, SMPLX_INDEX]
    np.testing.assert_allclose(body_pos, joints, atol=1e-5)  # float32 storage


def test_object_scale_is_baked_and_parts_are_posed(omomo: tuple[Path, Path, Path, Path]) -> None:
    pkl, objs, _, out = omomo
    data = safe_pickle_load(pkl)
    with open_dataset(out) as ds:
        assert sorted(ds.object_ids) == ["largebox_scale0.9", "largebox_scale1.1", "mop_bottom", "mop_top"]
        box = ds.object("largebox_scale0.9")
        assert box.extra["mesh_scale"] == pytest.approx(0.9) and not box.static
        np.testing.assert_allclose(np.abs(box.vertices).max(axis=0), [0.135, 0.09, 0.09], atol=1e-6)
        bottom = ds.object("mop_bottom")
        assert bottom.extra["parent"] == "mop_top" and bottom.extra["part"] == "bottom"
        s = ds.sequence("sub1_mop_000")
        assert s.object_ids == ["mop_top", "mop_bottom"]
        pos, quat = s.array("object_pos"), s.array("object_quat")
        v = ds.object("mop_bottom").vertices
    rec = data[1]
    np.testing.assert_allclose(pos[:, 1], rec["obj_bottom_trans"][:, :, 0], atol=1e-6)
    np.testing.assert_allclose(pos[:, 0], rec["obj_trans"][:, :, 0], atol=1e-6)
    # world vertices: s R v_rest + t (s = 1 for the mop) = pose applied to the stored mesh
    world = quat_rotate(quat[3, 1][None], v) + pos[3, 1]
    expect = v @ rec["obj_bottom_rot"][3].T + rec["obj_bottom_trans"][3, :, 0]
    np.testing.assert_allclose(world, expect, atol=1e-5)
    assert np.degrees(quat_angle(quat[:, 0], matrix_to_quat(rec["obj_rot"]))).max() < 1e-3


def test_without_smplx_models_the_error_says_what_and_where(
    omomo: tuple[Path, Path, Path, Path], tmp_path: Path
) -> None:
    pkl, objs, _, _ = omomo
    out = tmp_path / "o.h5"
    with pytest.raises(InputError) as e:
        convert_omomo_raw(pkl, objs, out, options=_opts(tmp_path))
    assert "--smplx-models" in str(e.value) and "smpl-x.is.tue.mpg.de" in str(e.value)
    (tmp_path / "models").mkdir()
    with pytest.raises(InputError, match=r"SMPLX_MALE.npz: SMPL-X model file missing"):
        convert_omomo_raw(pkl, objs, out, smplx_models=tmp_path / "models", options=_opts(tmp_path))
    assert not out.exists()
    r = CliRunner().invoke(app, ["convert", "omomo-raw", str(pkl), "--objects", str(objs), "-o", str(out), "-q"])
    assert r.exit_code == 1 and "smpl-x.is.tue.mpg.de" in r.output and not out.exists()


def test_bad_records_name_file_key_and_expectation(omomo: tuple[Path, Path, Path, Path], tmp_path: Path) -> None:
    rec = omomo_record("sub3_largebox_000", 10, 0)
    del rec["pose_body"]
    p = tmp_path / "bad.p"
    p.write_bytes(joblib_like_bytes({0: rec}))
    with pytest.raises(InputError, match=r"bad.p: \[0\] sub3_largebox_000.pose_body: missing"):
        read_records(p)
    rec = omomo_record("sub3_largebox_000", 10, 0)
    rec["obj_scale"][5] = 2.0
    p.write_bytes(pickle.dumps({0: rec}))
    with pytest.raises(InputError, match=r"obj_scale: scale .* \(expected constant and > 0\)"):
        read_records(p)
    p.write_bytes(pickle.dumps({0: {**omomo_record("sub3_largebox_000", 10, 0), "seq_name": "nope"}}))
    with pytest.raises(InputError, match=r"seq_name: 'nope' \(expected sub<N>_<object>_<NNN>\)"):
        read_records(p)
    with pytest.raises(InputError, match=r"sub9_x_000: no such sequence"):
        read_records(omomo[0], ["sub9_x_000"])


def test_missing_mesh_leaves_no_output(omomo: tuple[Path, Path, Path, Path], tmp_path: Path) -> None:
    pkl, objs, models, _ = omomo
    objs2 = tmp_path / "captured_objects"
    shutil.copytree(objs, objs2)
    (objs2 / "mop_cleaned_simplified_bottom.obj").unlink()
    out = tmp_path / "o.h5"
    with pytest.raises(InputError, match=r"mop_cleaned_simplified_bottom.obj: mop_bottom: mesh missing"):
        convert_omomo_raw(pkl, objs2, out, smplx_models=models, options=_opts(tmp_path))
    assert not out.exists()


def test_cli_omomo_raw_one_sequence(omomo: tuple[Path, Path, Path, Path], tmp_path: Path) -> None:
    pkl, objs, models, _ = omomo
    out = tmp_path / "c.h5"
    args = ["convert", "omomo-raw", str(pkl), "--objects", str(objs), "--smplx-models", str(models)]
    r = CliRunner().invoke(app, [*args, "-s", "sub2_largebox_001", "-o", str(out), "-q"])
    assert r.exit_code == 0, r.output
    assert "1 sequence(s), 1 object(s)" in r.output
    with open_dataset(out) as ds:
        assert ds.sequence_ids == ["sub2_largebox_001"] and ds.humanoid_ids == ["sub2"]
        assert ds.object_ids == ["largebox"]  # one scale in this file: no suffix
    h = CliRunner().invoke(app, ["convert", "omomo-raw", "--help"])
    assert h.exit_code == 0 and "Example" in h.output
