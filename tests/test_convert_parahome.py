"""SkillMimic ParaHome converter: clip names, 409/415 columns, rotation vectors, FK, supports, contacts."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from wristmimic.convert.common import ConvertOptions
from wristmimic.convert.skillmimic_parahome import (
    column_map,
    convert_skillmimic_parahome,
    objects_from_skill,
    parse_clip_name,
)
from wristmimic.errors import InputError
from wristmimic.format import open_dataset
from wristmimic.format.validate import validate
from wristmimic.humanoid.kinematics import forward_kinematics, qpos_from
from wristmimic.humanoid.skeleton import load_skeleton
from wristmimic.rotations import quat_angle, rotvec_to_quat
from wristmimic.safe_io import load_pt_tensor

from conftest import shared_path
from synthetic import parahome_motion, write_parahome_folder


@pytest.mark.parametrize("n,width", [(1, 409), (2, 415)])
def test_column_map_covers_every_column_once(n: int, width: int) -> None:
    covered = np.zeros(width, int)
    for a, b, _ in column_map(n).values():
        covered[a:b] += 1
    assert (covered == 1).all()


def test_clip_names_and_objects() -> None:
    p = parse_clip_name("003_s10_place_kettle_2580_2680")
    assert (p["subject"], p["skill"], p["start"], p["end"]) == ("s10", "place_kettle", "2580", "2680")
    assert parse_clip_name("002_s110_move_kettle")["skill"] == "move_kettle"
    avail = ["kettle", "cup", "cuttingboard", "pan"]
    assert objects_from_skill("pour_kettlecup", avail) == ["kettle", "cup"]
    assert objects_from_skill("move_cuttingboard", avail) == ["cuttingboard"]
    assert objects_from_skill("getup_chair", avail) == []
    with pytest.raises(InputError, match="NNN_sXX_<skill>"):
        parse_clip_name("kettle")


def _convert(src: Path, out: Path, cache: Path, **kw):
    return convert_skillmimic_parahome(
        src, out, options=ConvertOptions(hull_cache_dir=cache, show_progress=False), **kw
    )


def test_one_and_two_object_clips(tmp_path: Path) -> None:
    src = write_parahome_folder(tmp_path / "src", {"001_s1_move_box": 1, "010_s2_pour_kettlecup_5_45": 2})
    r = _convert(src, tmp_path / "o.h5", tmp_path / "c")
    assert sorted(r.sequences) == ["s1_move_box", "s2_pour_kettlecup_5_45"]
    assert validate(tmp_path / "o.h5") == []
    raw = parahome_motion(40, seed=1, num_objects=2)
    with open_dataset(tmp_path / "o.h5") as ds:
        s = ds.sequence("s2_pour_kettlecup_5_45")
        rec = s.load()
        assert s.object_ids[:2] == ["kettle", "cup"] and s.humanoid_id == "s2"
        assert np.allclose(rec.object_pos[:, 1], raw[:, 408:411], atol=1e-6)
        assert np.all(quat_angle(rec.object_quat[:, 0], rotvec_to_quat(raw[:, 405:408])) < 1e-5)
        assert np.all(quat_angle(rec.root_quat, rotvec_to_quat(raw[:, 3:6])) < 1e-5)
        assert np.abs(rec.body_pos - rec.source_body_pos).max() < 1e-4  # same humanoid made the motion
        # both objects rest untouched in mid-air at 0.8 m: each gets an inferred support under it
        sup = [o for o in s.object_ids if ds.object(o).inferred]
        assert len(sup) == 2
        for o in sup:
            ob = ds.object(o)
            assert ob.static and ob.extra["top_z"] == pytest.approx(0.75, abs=1e-3)  # box 0.1 m tall at 0.8


def test_missing_humanoid_or_mesh_is_named_and_skip_missing_converts_the_rest(tmp_path: Path) -> None:
    src = write_parahome_folder(tmp_path / "src", {"001_s1_move_box": 1, "002_s9_move_pan": 1})
    (src / "humanoids" / "s9.xml").unlink()
    with pytest.raises(InputError, match=r"002_s9_move_pan\.pt: s9_move_pan: humanoid humanoids/s9\.xml missing"):
        _convert(src, tmp_path / "o.h5", tmp_path / "c")
    assert not (tmp_path / "o.h5").exists()
    (src / "humanoids" / "s9.xml").write_text((src / "humanoids" / "s1.xml").read_text())
    with pytest.raises(InputError, match="no object of .* named in skill 'move_pan'"):
        _convert(src, tmp_path / "o.h5", tmp_path / "c")
    r = _convert(src, tmp_path / "o.h5", tmp_path / "c", skip_missing=True)
    assert r.sequences == ["s1_move_box"] and "s9_move_pan" in r.skipped
    r = _convert(src, tmp_path / "p.h5", tmp_path / "c", clips=["s9_move_pan"], objects=["box"], subject="s1")
    assert r.sequences == ["s9_move_pan"]


def test_object_count_must_match_columns(tmp_path: Path) -> None:
    src = write_parahome_folder(tmp_path / "src", {"001_s1_move_box": 1})
    with pytest.raises(InputError, match="409 columns = 1 object"):
        _convert(src, tmp_path / "o.h5", tmp_path / "c", objects=["box", "cup"])


@pytest.mark.shared_data
def test_shared_parahome_converts_validates_and_fk_matches(parahome_h5: Path) -> None:
    assert validate(parahome_h5) == []
    with open_dataset(parahome_h5) as ds:
        assert ds.sequence_ids == ["s110_move_kettle", "s114_move_pan", "s29_move_pot"]
        kettle = ds.object("kettle")
        assert kettle.hull_meta["params"]["max_convex_hull"] == 80
        assert np.diff(kettle.hull_vertex_offsets).max() <= 64
        files = {p.stem[4:]: p for p in shared_path("skillmimic_parahome", "motions").rglob("*.pt")}
        for sid in ds.sequence_ids:
            seq = ds.sequence(sid)
            s = seq.load()
            assert ds.humanoid(seq.humanoid_id).num_bodies == 61
            raw = load_pt_tensor(files[sid])
            T = raw.shape[0]
            skel = load_skeleton(ds.humanoid(seq.humanoid_id).mjcf)
            fk = forward_kinematics(skel.model, qpos_from(skel, s.root_pos, s.root_quat, s.joint_angles))
            assert np.degrees(quat_angle(fk.body_quat, s.body_quat)).max() < 0.5
            d = np.linalg.norm(fk.body_pos - raw[:, 189:372].reshape(T, 61, 3), axis=-1)
            print(f"{sid}: position error mean {d.mean():.4f} m, max {d.max():.4f} m")
            assert d.mean() < 0.02 and d.max() < 0.08, (sid, d.mean(), d.max())
            assert np.abs(s.object_pos[:, 0] - raw[:, 402:405]).max() < 1e-6
            assert np.degrees(quat_angle(s.object_quat[:, 0], rotvec_to_quat(raw[:, 405:408]))).max() < 1e-3
            # every inferred support sits exactly under the object while it rests there
            sup = [ds.object(o) for o in s.object_ids if ds.object(o).inferred]
            assert sup, sid
            obj = ds.object(s.object_ids[0])
            if not s.hand_contact[:5].any():  # untouched at the start (kettle, pan): held up by a support
                assert any(o.extra["intervals"][0][0] == 0 for o in sup), sid
            for o in sup:
                for a, b in o.extra["intervals"]:
                    from wristmimic.rotations import quat_rotate

                    z = quat_rotate(s.object_quat[a : b + 1, 0, None], obj.vertices[None])[..., 2].min(axis=1)
                    z = z + s.object_pos[a : b + 1, 0, 2]
                    assert abs(np.median(z) - o.extra["top_z"]) < 0.005, (sid, o.name)
            assert (s.hand_contact.any(axis=0)).any(), sid
            assert (s.first_contact_frame >= 0).any()
