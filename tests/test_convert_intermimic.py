"""InterMimic (OMOMO) converter: column mapping, conventions, FK reproduction, determinism, hull cache."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from wristmimic.convert.common import ConvertOptions
from wristmimic.convert.intermimic import COLUMNS, NUM_COLUMNS, convert_intermimic
from wristmimic.format import open_dataset
from wristmimic.format.validate import validate
from wristmimic.humanoid.kinematics import forward_kinematics, qpos_from
from wristmimic.humanoid.skeleton import load_skeleton
from wristmimic.rotations import quat_angle, xyzw_to_wxyz
from wristmimic.safe_io import load_pt_tensor

from conftest import shared_path
from synthetic import intermimic_motion, save_pt, smplx_like_mjcf, write_intermimic_folder


def test_every_column_is_mapped_once() -> None:
    covered = np.zeros(NUM_COLUMNS, int)
    for a, b, _ in COLUMNS.values():
        covered[a:b] += 1
    assert (covered == 1).all()


def _convert(src: Path, out: Path, cache: Path, **kw) -> object:
    return convert_intermimic(src, out, options=ConvertOptions(hull_cache_dir=cache, show_progress=False), **kw)


def test_synthetic_conversion_keeps_conventions(tmp_path: Path) -> None:
    src = write_intermimic_folder(tmp_path / "src")
    raw = intermimic_motion(40, seed=0)
    _convert(src, tmp_path / "o.h5", tmp_path / "c")
    with open_dataset(tmp_path / "o.h5") as ds:
        s = ds.sequence("sub1_box_000").load()
    # xyzw -> wxyz at the edge
    assert np.allclose(s.root_quat, xyzw_to_wxyz(raw[:, 3:7]), atol=1e-6)
    assert np.allclose(s.object_quat[:, 0], xyzw_to_wxyz(raw[:, 321:325]), atol=1e-6)
    assert np.allclose(s.object_pos[:, 0], raw[:, 318:321], atol=1e-6)
    # shipped labels kept, object flag kept
    assert np.array_equal(s.contact_labels, raw[:, 331:383].astype(np.int8))
    assert s.object_contact.all()
    # this humanoid made the motion, so FK positions equal the source positions
    assert np.abs(s.body_pos - s.source_body_pos).max() < 1e-4
    assert not s.source_body_pos_valid[18:33].any() and s.source_body_pos_valid[:18].all()
    # left hand labelled in contact from frame 0 -> window starts at 0
    assert s.first_contact_frame.tolist() == [0, -1] and s.contact_window.tolist() == [0, 15]


def test_convert_twice_identical_and_second_run_hits_hull_cache(tmp_path: Path) -> None:
    src = write_intermimic_folder(tmp_path / "src")
    r1 = _convert(src, tmp_path / "a.h5", tmp_path / "cache")
    r2 = _convert(src, tmp_path / "b.h5", tmp_path / "cache")
    assert r1.hull_cache_hits == {"box": False} and r2.hull_cache_hits == {"box": True}
    with open_dataset(tmp_path / "a.h5") as a, open_dataset(tmp_path / "b.h5") as b:
        ra, rb = a.sequence("sub1_box_000").load(), b.sequence("sub1_box_000").load()
        for k, v in ra.arrays().items():
            assert np.array_equal(v, rb.arrays()[k]), k
        oa, ob = a.object("box"), b.object("box")
        assert np.array_equal(oa.hull_vertices, ob.hull_vertices)
        assert np.array_equal(oa.surface_points, ob.surface_points)


@pytest.mark.shared_data
def test_shared_omomo_converts_and_validates(omomo_h5: Path) -> None:
    assert validate(omomo_h5) == []
    with open_dataset(omomo_h5) as ds:
        assert len(ds.sequence_ids) == 9
        assert set(ds.object_ids) == {"largetable", "plasticbox"}
        obj = ds.object("largetable")
        assert 1 <= obj.num_hulls <= 10 and np.diff(obj.hull_vertex_offsets).max() <= 64
        assert obj.hull_meta["params"]["seed"] == 0 and obj.hull_meta["coacd_version"]
        assert obj.urdf["lateral_friction"] == pytest.approx(0.9)


def test_each_subject_gets_the_skeleton_its_positions_were_made_with(tmp_path: Path) -> None:
    """The shipped humanoid is generic; sub2's positions come from a skeleton with 10 % longer legs and 8 %
    longer forearms. The converter reads it back (FK then reproduces the stored positions), one humanoid per
    subject; with fit_subjects=False every sequence uses the shipped body and is centimetres off."""
    legs = {f"{s}_{b}": 1.1 for s in "LR" for b in ("Knee", "Ankle")}
    subject = smplx_like_mjcf({**legs, "L_Wrist": 1.08, "R_Wrist": 1.08})
    src = write_intermimic_folder(tmp_path / "src", ("sub1_box_000", "sub2_box_000"))
    save_pt(src / "motions" / "sub2_box_000.pt", intermimic_motion(40, seed=1, mjcf=subject))
    _convert(src, tmp_path / "fit.h5", tmp_path / "c")
    _convert(src, tmp_path / "generic.h5", tmp_path / "c", fit_subjects=False)
    generic = load_skeleton(smplx_like_mjcf())
    with open_dataset(tmp_path / "fit.h5") as ds:
        assert ds.humanoid_ids == ["humanoid_sub1", "humanoid_sub2"]
        s = ds.sequence("sub2_box_000").load()
        assert s.humanoid_id == "humanoid_sub2"
        v = s.source_body_pos_valid
        assert np.abs(s.body_pos[:, v] - s.source_body_pos[:, v]).max() < 1e-4
        sk2 = load_skeleton(ds.humanoid("humanoid_sub2").mjcf)
        assert sk2.rest_pos[sk2.index("L_Ankle")] == pytest.approx([0, 0, -0.44], abs=1e-4)
        assert sk2.rest_pos[sk2.index("R_Wrist")] == pytest.approx([0, -0.27, 0], abs=1e-4)
        assert np.allclose(load_skeleton(ds.humanoid("humanoid_sub1").mjcf).rest_pos, generic.rest_pos, atol=1e-6)
        assert "fitted" in ds.humanoid("humanoid_sub2").source_file
    with open_dataset(tmp_path / "generic.h5") as ds:
        assert ds.humanoid_ids == ["humanoid"]
        s = ds.sequence("sub2_box_000").load()
        assert np.abs(s.body_pos[:, v] - s.source_body_pos[:, v]).max() > 0.03


def test_body_positions_of_no_single_skeleton_are_refused(tmp_path: Path) -> None:
    from wristmimic.errors import InputError

    src = write_intermimic_folder(tmp_path / "src")
    raw = intermimic_motion(40, seed=0)
    raw[:, 162:318] += np.random.default_rng(0).normal(0.0, 0.005, raw[:, 162:318].shape)
    save_pt(src / "motions" / "sub1_box_000.pt", raw)
    with pytest.raises(InputError, match=r"sub1_box_000\.pt: columns 162:318: .*not forward kinematics of one"):
        _convert(src, tmp_path / "o.h5", tmp_path / "c")
    assert not (tmp_path / "o.h5").exists()
    _convert(src, tmp_path / "o.h5", tmp_path / "c", fit_subjects=False)
    assert (tmp_path / "o.h5").exists()


@pytest.mark.shared_data
def test_shared_omomo_fk_reproduces_source(omomo_h5: Path) -> None:
    """FK of the stored (per-subject) humanoid + stored joint angles gives the stored rotations (< 0.5 deg) and
    the source's non-finger positions (< 0.1 mm; the shipped omomo.xml: mean 2-4 cm, max 10 cm); objects equal
    the source."""
    errors = []
    with open_dataset(omomo_h5) as ds:
        for sid in ds.sequence_ids:
            seq = ds.sequence(sid)
            s = seq.load()
            skel = load_skeleton(ds.humanoid(seq.humanoid_id).mjcf)
            raw = load_pt_tensor(shared_path("intermimic_omomo", "motions", f"{sid}.pt"))
            T = raw.shape[0]
            fk = forward_kinematics(skel.model, qpos_from(skel, s.root_pos, s.root_quat, s.joint_angles))
            src_quat = xyzw_to_wxyz(raw[:, 383:591].reshape(T, 52, 4))
            assert np.degrees(quat_angle(fk.body_quat, src_quat)).max() < 0.5
            assert np.degrees(quat_angle(s.body_quat, src_quat)).max() < 0.5
            d = np.linalg.norm(fk.body_pos - raw[:, 162:318].reshape(T, 52, 3), axis=-1)[:, s.source_body_pos_valid]
            errors.append((d.mean(), d.max()))
            assert d.max() < 1e-4, (sid, d.mean(), d.max())
            assert np.abs(s.object_pos[:, 0] - raw[:, 318:321]).max() < 1e-6
            assert np.degrees(quat_angle(s.object_quat[:, 0], xyzw_to_wxyz(raw[:, 321:325]))).max() < 1e-3
    print(
        f"OMOMO non-finger position error (m): mean {np.mean([e[0] for e in errors]):.4f}, worst max {max(e[1] for e in errors):.4f}"
    )


@pytest.mark.shared_data
def test_shared_omomo_humanoids_stand_on_the_floor(omomo_h5: Path) -> None:
    """Per subject, the lowest foot point over the sequences' first 30 frames is on the floor (InterAct's rule);
    the shipped omomo.xml floated sub2's feet 8-11 cm there. Over whole clips the lowest foot stays within
    -2..+3 cm of the floor at the median frame."""
    from wristmimic.humanoid.fit import lowest_foot_height

    with open_dataset(omomo_h5) as ds:
        assert sorted(ds.humanoid_ids) == ["omomo_sub2", "omomo_sub8"]
        first: dict[str, list[float]] = {}
        for sid in ds.sequence_ids:
            s = ds.sequence(sid).load()
            hum = ds.humanoid(s.humanoid_id)
            skel = load_skeleton(hum.mjcf)
            feet = [hum.body_names[b] for b in hum.roles["feet"]]
            qpos = qpos_from(skel, s.root_pos, s.root_quat, s.joint_angles)
            first.setdefault(s.humanoid_id, []).append(lowest_foot_height(hum.mjcf, qpos[:30], feet))
            per_frame = [lowest_foot_height(hum.mjcf, q[None], feet) for q in qpos[::5]]
            assert -0.02 < np.median(per_frame) < 0.03, (sid, np.median(per_frame))
    for hid, lows in first.items():
        assert min(lows) == pytest.approx(0.0, abs=1e-3), (hid, lows)


@pytest.mark.shared_data
def test_shared_omomo_hand_contacts_and_window(omomo_h5: Path) -> None:
    with open_dataset(omomo_h5) as ds:
        for sid in ds.sequence_ids:
            s = ds.sequence(sid)
            first = s.array("contacts/first_contact_frame")
            win = s.array("contacts/window")
            assert (first >= 0).any(), sid
            tc = first[first >= 0].min()
            assert win[0] == max(tc - 10, 0) and win[1] == min(tc + 15, s.num_frames - 1)
            meta = s.contact_meta
            assert meta["t_b"] == 10 and meta["t_a"] == 15 and meta["params"]["contact_m"] == 0.02


def test_one_sequence_can_be_selected(tmp_path: Path) -> None:
    src = write_intermimic_folder(tmp_path / "src", ("sub1_box_000", "sub2_box_001"))
    r = _convert(src, tmp_path / "o.h5", tmp_path / "c", sequences=["sub2_box_001"])
    assert r.sequences == ["sub2_box_001"]


def test_extra_motion_file_with_other_object_name_needs_that_object(tmp_path: Path) -> None:
    src = write_intermimic_folder(tmp_path / "src")
    save_pt(src / "motions" / "sub1_chair_000.pt", intermimic_motion(30))
    from wristmimic.errors import InputError

    with pytest.raises(InputError, match="chair"):
        _convert(src, tmp_path / "o.h5", tmp_path / "c")
    assert not (tmp_path / "o.h5").exists()


@pytest.mark.shared_data
def test_shared_sequence_converted_again_is_identical_and_hits_the_hull_cache(omomo_h5: Path, tmp_path: Path) -> None:
    src = shared_path("intermimic_omomo")
    r = convert_intermimic(
        src, tmp_path / "again.h5", sequences=["sub2_largetable_000"], options=ConvertOptions(show_progress=False)
    )
    assert r.hull_cache_hits == {"largetable": True}
    assert r.seconds_per_object["largetable"] < 10  # no decomposition
    with open_dataset(omomo_h5) as a, open_dataset(tmp_path / "again.h5") as b:
        ra, rb = a.sequence("sub2_largetable_000").load(), b.sequence("sub2_largetable_000").load()
        for k, v in ra.arrays().items():
            assert np.array_equal(v, rb.arrays()[k]), k
        assert np.array_equal(a.object("largetable").hull_vertices, b.object("largetable").hull_vertices)
