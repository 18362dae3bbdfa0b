"""Humanoids generated from ParaHome bone vectors and from SMPL-X shape (synthetic model file)."""

from __future__ import annotations

import pickle
from pathlib import Path

import numpy as np
import pytest
from synthetic_raw import synthetic_bones, write_smplx_model
from typer.testing import CliRunner

from wristmimic.cli.main import app
from wristmimic.errors import InputError
from wristmimic.humanoid.parahome import ACTUATOR_ORDER, BODY_NAMES, generate_parahome_humanoid
from wristmimic.humanoid.roles import detect_profile
from wristmimic.humanoid.skeleton import load_skeleton
from wristmimic.humanoid.smplx_body import (
    BODY_NAMES as SMPLX_BODIES,
)
from wristmimic.humanoid.smplx_body import (
    MODEL_URL,
    SMPLX_INDEX,
    SmplxModels,
    body_offsets,
    check_model_file,
    find_model_file,
    smplx_mjcf,
)
from wristmimic.rotations import quat_to_matrix

from conftest import shared_path


def _flat(bones: dict) -> dict[tuple[str, str], np.ndarray]:
    return {(p, c): np.asarray(v, float) for part in bones.values() for p, ch in part.items() for c, v in ch.items()}


@pytest.fixture(scope="module")
def smplx_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    d = tmp_path_factory.mktemp("smplx_models")
    write_smplx_model(d, "male")
    return d


# --------------------------------------------------------------------------------------------- ParaHome


def test_bone_vector_humanoid_matches_skillmimic_s110() -> None:
    bones = shared_path("parahome_raw", "s110", "bone_vectors.pkl")
    ref = load_skeleton(shared_path("skillmimic_parahome", "humanoids", "s110.xml").read_text())
    gen = load_skeleton(generate_parahome_humanoid(bones))
    assert gen.body_names == ref.body_names
    np.testing.assert_array_equal(gen.parents, ref.parents)
    assert np.abs(gen.rest_pos - ref.rest_pos).max() < 1e-3  # < 1 mm (measured: 2e-9 m)
    np.testing.assert_allclose(gen.model.geom_size, ref.model.geom_size, atol=1e-6)
    np.testing.assert_allclose(gen.model.body_mass, ref.model.body_mass, rtol=1e-6)
    assert detect_profile(gen).family == "parahome"
    names = [gen.model.actuator(i).name for i in range(gen.model.nu)]
    assert names == [ref.model.actuator(i).name for i in range(ref.model.nu)]


def test_generated_parahome_humanoid_from_synthetic_bones(tmp_path: Path) -> None:
    bones = synthetic_bones(np.random.default_rng(3))
    p = tmp_path / "s9" / "bone_vectors.pkl"
    p.parent.mkdir()
    p.write_bytes(pickle.dumps(bones))
    mjcf = generate_parahome_humanoid(p)
    assert 'model="s9"' in mjcf
    skel = load_skeleton(mjcf)
    assert skel.body_names == BODY_NAMES and skel.num_bodies == 61 and skel.num_joints == 60
    flat = _flat(bones)
    for b in range(1, 61):
        parent = skel.body_names[skel.parents[b]]
        np.testing.assert_allclose(skel.rest_pos[b], flat[(parent, skel.body_names[b])], atol=1e-9)
    np.testing.assert_array_equal(skel.rest_quat, np.tile([1.0, 0, 0, 0], (61, 1)))
    assert detect_profile(skel).family == "parahome"
    assert sorted(ACTUATOR_ORDER) == sorted(BODY_NAMES[1:]) and skel.model.nu == 180


def test_missing_bone_vector_is_named(tmp_path: Path) -> None:
    bones = synthetic_bones(np.random.default_rng(0))
    del bones["lhand"]["jLeftFifthPIP"]["jLeftFifthDIP"]
    p = tmp_path / "bone_vectors.pkl"
    p.write_bytes(pickle.dumps(bones))
    with pytest.raises(InputError, match=r"bone_vectors.pkl: lhand/jLeftFifthPIP/jLeftFifthDIP: bone vector missing"):
        generate_parahome_humanoid(p)
    bones = synthetic_bones(np.random.default_rng(0))
    bones["body"]["jT9T8"]["jT1C7"] = np.array([np.nan, 0.0, 0.0])
    p.write_bytes(pickle.dumps(bones))
    with pytest.raises(InputError, match=r"body/jT9T8/jT1C7: bad bone vector"):
        generate_parahome_humanoid(p)


def test_humanoid_cli_writes_mjcf_atomically(tmp_path: Path) -> None:
    p = tmp_path / "s3" / "bone_vectors.pkl"
    p.parent.mkdir()
    p.write_bytes(pickle.dumps(synthetic_bones(np.random.default_rng(1))))
    out = tmp_path / "s3.xml"
    r = CliRunner().invoke(app, ["humanoid", "parahome", str(p), "-o", str(out)])
    assert r.exit_code == 0, r.output
    assert "61 bodies" in r.output and load_skeleton(out.read_text()).num_bodies == 61
    bad = tmp_path / "bad.pkl"
    bad.write_bytes(pickle.dumps({"body": {}}))
    out2 = tmp_path / "bad.xml"
    r = CliRunner().invoke(app, ["humanoid", "parahome", str(bad), "-o", str(out2)])
    assert r.exit_code == 1 and "lhand" in r.output and not out2.exists()
    h = CliRunner().invoke(app, ["humanoid", "parahome", "--help"])
    assert h.exit_code == 0 and "Example" in h.output


# --------------------------------------------------------------------------------------------- SMPL-X


def test_smplx_humanoid_offsets_come_from_the_joint_regressor(smplx_dir: Path) -> None:
    betas = np.random.default_rng(5).normal(0, 1, 16)
    body = SmplxModels(smplx_dir).shaped_body("male", betas)
    d = dict(np.load(smplx_dir / "smplx" / "SMPLX_MALE.npz"))
    v_shaped = d["v_template"] + np.einsum("vck,k->vc", d["shapedirs"][:, :, :16].astype(np.float64), betas)
    J = d["J_regressor"] @ v_shaped
    np.testing.assert_allclose(body.joints, J, atol=1e-9)
    skel = load_skeleton(smplx_mjcf(body, "sub1"))
    assert skel.body_names == SMPLX_BODIES and detect_profile(skel).family == "smplx"
    P = quat_to_matrix(np.array([0.5, 0.5, 0.5, 0.5]))
    expect = (J[SMPLX_INDEX[1:]] - J[SMPLX_INDEX[skel.parents[1:]]]) @ P.T
    np.testing.assert_allclose(skel.rest_pos[1:], expect, atol=1e-7)
    np.testing.assert_allclose(body_offsets(J)[1:], expect, atol=1e-12)
    # upright: hips below the pelvis (-z), left hip on +y, toes forward (+x)
    assert skel.rest_pos[1, 2] < 0 and skel.rest_pos[1, 1] > 0 and skel.rest_pos[4, 0] > 0
    assert skel.model.nu == 153


def test_smplx_humanoid_matches_intermimic_layout(smplx_dir: Path) -> None:
    ref = load_skeleton(shared_path("intermimic_omomo", "omomo.xml").read_text())
    skel = load_skeleton(smplx_mjcf(SmplxModels(smplx_dir).shaped_body("male", np.zeros(16))))
    assert skel.body_names == ref.body_names
    np.testing.assert_array_equal(skel.parents, ref.parents)
    np.testing.assert_allclose(np.degrees(skel.joint_range), np.degrees(ref.joint_range), atol=1e-3)
    np.testing.assert_allclose(skel.model.jnt_stiffness, ref.model.jnt_stiffness)


def test_missing_smplx_model_says_what_and_where(tmp_path: Path) -> None:
    with pytest.raises(InputError) as e:
        find_model_file(tmp_path, "female")
    msg = str(e.value)
    assert "SMPLX_FEMALE.npz" in msg and MODEL_URL in msg and str(tmp_path) in msg


def test_bad_model_files_are_named(tmp_path: Path) -> None:
    p = tmp_path / "SMPLX_MALE.npz"
    np.savez(p, v_template=np.zeros((100, 3)))
    with pytest.raises(InputError, match="SMPLX_MALE.npz: f: missing"):
        check_model_file(p, 16)
    parents = np.array([[0, 0, 0, 0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 9, 9, 12, 13, 14, 16, 17, 18, 19, 15, 15, 15]
                        + [20, 25, 26, 20, 28, 29, 20, 31, 32, 20, 34, 35, 20, 37, 38]
                        + [21, 40, 41, 21, 43, 44, 21, 46, 47, 21, 49, 50, 21, 52, 53], list(range(55))])  # fmt: skip
    small = dict(v_template=np.zeros((100, 3)), f=np.zeros((5, 3), int), J_regressor=np.zeros((55, 100)),
                 weights=np.zeros((100, 55)), kintree_table=parents, shapedirs=np.zeros((100, 3, 20)),
                 posedirs=np.zeros((100, 3, 486)))  # fmt: skip
    np.savez(p, **small)
    assert check_model_file(p, 16) == 10
    (tmp_path / "smplx").mkdir()
    np.savez(tmp_path / "smplx" / "SMPLX_MALE.npz", **small)
    with pytest.raises(InputError, match="10 shape components, the subject has 16 betas"):
        SmplxModels(tmp_path / "smplx").shaped_body("male", np.ones(16))
    small["kintree_table"] = parents[:, ::-1].copy()
    np.savez(p, **small)
    with pytest.raises(InputError, match="kintree_table: not the SMPL-X kinematic tree"):
        check_model_file(p, 10)
