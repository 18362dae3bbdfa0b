"""Plausibility metrics on hand-edited synthetic sequences whose answer is known: an object pushed into the table,
a humanoid sunk into the floor, a foot sliding at a set speed, an object moving with nothing touching it, a box a
set distance below a labelled wrist, constant-velocity and cubic trajectories; plus inspect and report output."""

from __future__ import annotations

import json
import shutil
from collections.abc import Callable
from pathlib import Path

import h5py
import mujoco
import numpy as np
import pytest
from typer.testing import CliRunner

from wristmimic.cli.main import app
from wristmimic.errors import InputError
from wristmimic.format import open_dataset
from wristmimic.format.writer import DatasetWriter
from wristmimic.plausibility import PlausibilityFrames, jerk, measure, plausibility, plausibility_series
from wristmimic.report import build_report
from wristmimic.scene import build_scene

SID = "synth_default"
FPS = 30.0


@pytest.fixture(scope="module")
def synth(tmp_path_factory: pytest.TempPathFactory) -> Path:
    from wristmimic.synth.generate import generate

    return generate(tmp_path_factory.mktemp("plaus") / "synth.h5", variants=("default",))


def edited(src: Path, dst: Path, edit: Callable[[h5py.Group], None]) -> Path:
    """A copy of ``src`` whose sequence ``SID`` was changed in place by ``edit``."""
    shutil.copy(src, dst)
    with h5py.File(dst, "r+") as f:
        edit(f["sequences"][SID])
    return dst


def frozen(g: h5py.Group) -> None:
    """Every frame holds the pose of frame 0 (humanoid and objects)."""
    for name in ("root_pos", "root_quat", "joint_quat", "joint_angles", "body_pos", "body_quat", "source_body_pos"):
        a = g[name][()]
        g[name][...] = np.broadcast_to(a[:1], a.shape)
    for name in ("object_pos", "object_quat"):
        a = g[name][()]
        g[name][...] = np.broadcast_to(a[:1], a.shape)


def split_box_hulls(path: Path) -> None:
    """Replace the box's one hull by four quarter boxes (the scene's object body then has several geoms, which
    MuJoCo's mid phase tests as a tree)."""
    with h5py.File(path, "r+") as f:
        h = f["objects/box/hulls"]
        v, fc = h["vertices"][()], h["faces"][()]
        lo, hi = v.min(axis=0), v.max(axis=0)
        mid = (lo + hi) / 2
        verts, faces = [], []
        for ix in (0, 1):
            for iy in (0, 1):
                a = np.array([(lo[0], mid[0])[ix], (lo[1], mid[1])[iy], lo[2]])
                b = np.array([(mid[0], hi[0])[ix], (mid[1], hi[1])[iy], hi[2]])
                verts.append(np.where(v > mid, b, a).astype(np.float32))  # the 8 corners in the hull's order
                faces.append(fc)
        for name, data in (
            ("vertices", np.concatenate(verts)),
            ("faces", np.concatenate(faces)),
            ("vertex_offsets", np.arange(5, dtype=np.int64) * len(v)),
            ("face_offsets", np.arange(5, dtype=np.int64) * len(fc)),
        ):
            del h[name]
            h.create_dataset(name, data=data)


def run(path: Path) -> PlausibilityFrames:
    with open_dataset(path) as ds:
        return measure(ds, SID)


def test_object_pushed_5cm_into_the_table_gives_5cm_object_support_depth(synth: Path, tmp_path: Path) -> None:
    def sink_box(g: h5py.Group) -> None:
        p = g["object_pos"][()]
        p[:, 0, 2] -= 0.05  # the box (object 0) 5 cm lower at every frame
        g["object_pos"][...] = p

    ref = run(synth).series()["object_support_depth_m"]
    mod = run(edited(synth, tmp_path / "sunk.h5", sink_box)).series()["object_support_depth_m"]
    # frames 0-35 (stand, reach): the box rests on the table; the reference puts it exactly on the top
    assert ref[:36].max() < 0.001
    assert np.allclose(mod[:36], 0.05, atol=0.002), mod[:36]


def test_humanoid_sunk_3cm_gives_3cm_more_floor_penetration(synth: Path, tmp_path: Path) -> None:
    def sink(g: h5py.Group) -> None:
        for name in ("root_pos", "body_pos"):
            a = g[name][()]
            a[..., 2] -= 0.03
            g[name][...] = a

    ref, mod = run(synth), run(edited(synth, tmp_path / "sunk.h5", sink))
    extra = mod.series()["body_floor_depth_m"] - ref.series()["body_floor_depth_m"]
    assert np.allclose(extra, 0.03, atol=0.001), extra
    r, m = ref.summary(), mod.summary()
    assert m["foot_height_min_mm"] == pytest.approx(r["foot_height_min_mm"] - 30.0, abs=1.0)
    assert m["body_floor_over_pct"] == 100.0 and r["body_floor_over_pct"] == 0.0


def test_foot_sliding_at_a_known_speed_skates_at_that_speed(synth: Path, tmp_path: Path) -> None:
    v = 0.3  # m/s along x, the whole standing humanoid

    def slide(g: h5py.Group) -> None:
        frozen(g)
        t = np.arange(g["root_pos"].shape[0]) / FPS
        for name in ("root_pos", "body_pos", "source_body_pos"):
            a = g[name][()]
            a[..., 0] += (v * t).reshape(-1, *([1] * (a.ndim - 2)))
            g[name][...] = a

    still = run(edited(synth, tmp_path / "still.h5", frozen)).summary()
    s = run(edited(synth, tmp_path / "slide.h5", slide)).summary()
    assert still["foot_stance_pct"] > 90.0 and still["foot_skate_max_cm_s"] < 0.1
    assert s["foot_stance_pct"] == still["foot_stance_pct"]
    assert s["foot_skate_mean_cm_s"] == pytest.approx(100 * v, abs=0.1)
    assert s["foot_skate_max_cm_s"] == pytest.approx(100 * v, abs=0.1)
    assert s["foot_skate_over_pct"] == 100.0 and still["foot_skate_over_pct"] == 0.0
    # a constant velocity has no jerk (float32 positions: a few 0.01 m/s^3 of rounding)
    assert s["body_jerk_max"] < 0.5 and s["body_jerk_over_pct"] == 0.0


def test_object_moving_with_nothing_touching_it_floats_and_on_the_table_does_not(synth: Path, tmp_path: Path) -> None:
    def fly(z: float, y0: float) -> Callable[[h5py.Group], None]:
        def edit(g: h5py.Group) -> None:
            frozen(g)
            p = g["object_pos"][()]
            n = len(p)
            p[:, 0] = np.stack([np.full(n, 0.5), y0 + 0.2 * np.arange(n) / FPS, np.full(n, z)], axis=1)
            g["object_pos"][...] = p

        return edit

    assert run(synth).summary()["object_float_frames"] == 0.0
    up = run(edited(synth, tmp_path / "fly.h5", fly(1.6, 0.9)))  # 0.2 m/s, 1.6 m high, beside the humanoid
    assert up.summary()["object_float_frames"] == up.num_frames
    assert np.allclose(up.object_speed, 0.2, atol=1e-3)
    on_table = run(edited(synth, tmp_path / "slide.h5", fly(0.85, -0.45)))  # slides on the table top
    assert on_table.object_touched.all() and on_table.summary()["object_float_frames"] == 0.0
    assert on_table.summary()["object_support_depth_max_mm"] < 1.0


def _lowest_z(m: mujoco.MjModel, d: mujoco.MjData, g: int) -> float:
    """Lowest world z of a box, capsule or sphere geom (analytic)."""
    R, s, z = d.geom_xmat[g].reshape(3, 3), m.geom_size[g], d.geom_xpos[g, 2]
    t = m.geom_type[g]
    if t == mujoco.mjtGeom.mjGEOM_BOX:
        return float(z - np.abs(R[2]) @ s)
    if t == mujoco.mjtGeom.mjGEOM_CAPSULE:
        return float(z - abs(R[2, 2]) * s[1] - s[0])
    assert t == mujoco.mjtGeom.mjGEOM_SPHERE, t
    return float(z - s[0])


@pytest.mark.parametrize(("below", "expected_mm", "hulls"), [(0.05, 50.0, 1), (0.05, 50.0, 4), (0.30, 200.0, 1)])
def test_box_below_a_labelled_wrist_gives_that_gap(
    synth: Path, tmp_path: Path, below: float, expected_mm: float, hulls: int
) -> None:
    """A box whose top is ``below`` under the right wrist's lowest point while only R_Wrist is labelled in contact:
    the gap is that distance (searched up to 0.2 m, so 0.3 m reads 0.2 m), with one hull or four."""
    with open_dataset(synth) as ds:
        sc = build_scene(ds, SID)
        seq = ds.sequence(SID)
        wrist = sc.skeleton.body_names.index("R_Wrist")
        d = mujoco.MjData(sc.model)
        d.qpos[0:3], d.qpos[3:7] = seq.array("root_pos", slice(0, 1))[0], seq.array("root_quat", slice(0, 1))[0]
        d.qpos[sc.hinge_qposadr.ravel()] = seq.array("joint_angles", slice(0, 1))[0].ravel()
        mujoco.mj_kinematics(sc.model, d)
        geoms = np.flatnonzero(sc.model.geom_bodyid == sc.body_ids[wrist])
        low = min(_lowest_z(sc.model, d, int(g)) for g in geoms)
        centre = d.geom_xpos[geoms[0]]
        half_height = float(ds.object("box").hull_vertices[:, 2].max())

    def place(g: h5py.Group) -> None:
        frozen(g)
        p, q = g["object_pos"][()], g["object_quat"][()]
        p[:, 0] = [centre[0], centre[1], low - below - half_height]
        q[:, 0] = [1.0, 0.0, 0.0, 0.0]
        g["object_pos"][...], g["object_quat"][...] = p, q
        lab = np.zeros_like(g["contacts/labels"][()])
        lab[:, wrist] = 1
        g["contacts/labels"][...] = lab

    path = edited(synth, tmp_path / "gap.h5", place)
    if hulls == 4:
        split_box_hulls(path)
        with open_dataset(path) as ds:
            assert ds.object("box").num_hulls == 4
    r = run(path)
    s = r.summary()
    assert s["hand_gap_pairs"] == r.num_frames  # one labelled hand body per frame
    assert s["hand_gap_mean_mm"] == pytest.approx(expected_mm, abs=1.0)
    assert s["hand_gap_max_mm"] == pytest.approx(expected_mm, abs=1.0)
    assert s["hand_gap_over_pct"] == 100.0


def test_hand_pushed_into_a_box_gives_the_penetration_depth(synth: Path, tmp_path: Path) -> None:
    """A box whose top is 2 cm above the lowest point of the right hand (below it, so only that point's geom
    enters through the top face): hand-object depth 2 cm."""
    with open_dataset(synth) as ds:
        sc = build_scene(ds, SID)
        seq = ds.sequence(SID)
        d = mujoco.MjData(sc.model)
        d.qpos[0:3], d.qpos[3:7] = seq.array("root_pos", slice(0, 1))[0], seq.array("root_quat", slice(0, 1))[0]
        d.qpos[sc.hinge_qposadr.ravel()] = seq.array("joint_angles", slice(0, 1))[0].ravel()
        mujoco.mj_kinematics(sc.model, d)
        hand = sc.body_ids[sc.humanoid.roles["right_hand"]]
        geoms = np.flatnonzero(np.isin(sc.model.geom_bodyid, hand))
        lows = [_lowest_z(sc.model, d, int(g)) for g in geoms]
        g_low = int(geoms[int(np.argmin(lows))])
        centre = d.geom_xpos[g_low]
        half_height = float(ds.object("box").hull_vertices[:, 2].max())

    def place(g: h5py.Group) -> None:
        frozen(g)
        p, q = g["object_pos"][()], g["object_quat"][()]
        p[:, 0] = [centre[0], centre[1], min(lows) + 0.02 - half_height]
        q[:, 0] = [1.0, 0.0, 0.0, 0.0]
        g["object_pos"][...], g["object_quat"][...] = p, q

    depth = run(edited(synth, tmp_path / "pen.h5", place)).series()["hand_object_depth_m"]
    assert np.allclose(depth, 0.02, atol=0.001), depth[:5]


def test_jerk_is_the_third_derivative() -> None:
    t = np.arange(40) / FPS
    cubic = np.zeros((40, 3))
    cubic[:, 1] = 7.0 * t**3 / 6.0  # third derivative 7 m/s^3
    j = jerk(cubic, FPS)
    assert np.isnan(j[[0, -2, -1]]).all() and np.allclose(j[1:-2], 7.0, rtol=1e-6)
    line = np.stack([0.5 * t, -t, 2 * t], axis=1)
    assert np.allclose(jerk(line, FPS)[1:-2], 0.0, atol=1e-6)
    spike = np.zeros((10, 3))
    spike[5, 2] = 0.001  # one 1 mm glitch: 3 mm * 30^3 = 81 m/s^3 on the two frames whose stencil weights it 3x
    assert np.nanmax(jerk(spike, FPS)) == pytest.approx(81.0)


def test_reference_summary_and_series_agree(synth: Path) -> None:
    with open_dataset(synth) as ds:
        s, series = plausibility(ds, SID), plausibility_series(ds, SID)
    T = int(s["frames"])
    assert all(len(v) == T for v in series.values())
    assert s["hand_object_depth_max_mm"] == pytest.approx(1000 * series["hand_object_depth_m"].max())
    assert s["foot_skate_max_cm_s"] == pytest.approx(100 * np.nanmax(series["foot_skate_speed_m_s"]))
    assert s["hand_gap_pairs"] > 0 and s["hand_gap_max_mm"] < 20.0  # the generator labels contact below 2 cm


def test_inspect_prints_plausibility_and_can_skip_it(synth: Path) -> None:
    runner = CliRunner()
    r = runner.invoke(app, ["inspect", str(synth)])
    assert r.exit_code == 0, r.output
    assert "plausibility (" in r.stdout and "hand-object" in r.stdout and "skating" in r.stdout
    r = runner.invoke(app, ["inspect", str(synth), "--no-plausibility"])
    assert r.exit_code == 0 and "plausibility" not in r.stdout
    r = runner.invoke(app, ["inspect", str(synth), "--json", "-s", SID])
    p = json.loads(r.stdout)["sequences"][SID]["plausibility"]
    with open_dataset(synth) as ds:
        direct = plausibility(ds, SID)
    assert p["body_floor_depth_max_mm"] == pytest.approx(direct["body_floor_depth_max_mm"], abs=0.01)
    r = runner.invoke(app, ["inspect", str(synth), "-s", "nope"])
    assert r.exit_code == 1 and "nope" in r.stderr and len(r.stderr.strip().splitlines()) == 1


def _fake_export(synth: Path, out: Path, sunk_m: float, checkpoint_sha256: str = "") -> Path:
    """A file shaped like `wristmimic export` output: the reference sequence as ``<scene>__sim_7``, sunk into the
    floor by ``sunk_m``, with the root ``export`` attribute naming the dataset (and the checkpoint's sha256)."""
    with open_dataset(synth) as ds:
        seq = ds.sequence(SID).load()
        hum, objs = ds.humanoid(seq.humanoid_id), {o: ds.object(o) for o in seq.object_ids}
    seq.root_pos = seq.root_pos - np.array([0, 0, sunk_m], np.float32)
    seq.body_pos = seq.body_pos - np.array([0, 0, sunk_m], np.float32)
    attrs = {"export": {"dataset": str(synth), "scene": SID, "checkpoint_sha256": checkpoint_sha256}}
    with DatasetWriter(
        out, source_dataset="synthetic", source_format="wristmimic-run", converter="export", input_sha256={},
        extra_attrs=attrs,
    ) as w:  # fmt: skip
        w.add_humanoid(seq.humanoid_id, hum)
        for oid, rec in objs.items():
            w.add_object(oid, rec)
        w.add_sequence(f"{SID}__sim_7", seq)
    return out


def test_report_tables_reference_against_simulation(synth: Path, tmp_path: Path) -> None:
    from test_report import fake_eval

    ev = fake_eval(tmp_path / "ev", "synthetic", "WristMimic (Ours)", "wristmimic", SID, 4, 3, 5.0)
    sim = _fake_export(synth, tmp_path / "sim.h5", 0.03)
    res = build_report([ev], tmp_path / "rep", plausibility=[sim])
    assert "plausibility.csv" in res.files
    import pandas as pd

    df = pd.read_csv(tmp_path / "rep" / "plausibility.csv")
    assert df["scene"].tolist() == [SID] and df["sim_sequences"].tolist() == [1]
    ref_mm, sim_mm = df["body_floor_depth_max_mm_ref"][0], df["body_floor_depth_max_mm_sim"][0]
    assert sim_mm - ref_mm == pytest.approx(30.0, abs=1.0)
    md = (tmp_path / "rep" / "summary.md").read_text()
    assert "## Physical plausibility" in md and SID in md
    # a file that is not an export is refused in one line
    with pytest.raises(InputError, match="export"):
        build_report([ev], tmp_path / "rep2", plausibility=[synth])
    # the CLI option
    r = CliRunner().invoke(app, ["report", str(ev), "--plausibility", str(sim), "-o", str(tmp_path / "rep3")])
    assert r.exit_code == 0, r.output
    assert (tmp_path / "rep3" / "plausibility.csv").read_text() == (tmp_path / "rep" / "plausibility.csv").read_text()


def test_report_finds_the_export_of_the_evaluated_policy_beside_its_evaluation(synth: Path, tmp_path: Path) -> None:
    import pandas as pd
    from test_report import fake_eval

    run, sha = tmp_path / "run", "ab" * 32
    ev = fake_eval(tmp_path / "run" / "eval" / "paper", "synthetic", "WristMimic (Ours)", "wristmimic", SID, 4, 3, 5.0)
    doc = json.loads((ev / "summary.json").read_text())
    doc["policy"] |= {"checkpoint_sha256": sha, "run_dir": str(run)}
    (ev / "summary.json").write_text(json.dumps(doc))
    _fake_export(synth, tmp_path / "other.h5", 0.10, "cd" * 32)
    shutil.copy(tmp_path / "other.h5", ev / "other_checkpoint.h5")  # another policy's export: passed over
    shutil.copy(synth, ev.parent / "reference.h5")  # a dataset, not an export: passed over
    (run / "broken.h5").write_bytes(b"not hdf5")  # unreadable: passed over
    for where in (run, ev.parent, ev):  # the run folder, the evaluation's parent, the evaluation folder
        sim = _fake_export(synth, where / "sim.h5", 0.03, sha)
        res = build_report([ev], tmp_path / f"rep_{where.name}", plausibility=None)
        assert res.exports == [sim.resolve()] and "plausibility.csv" in res.files, where
        df = pd.read_csv(tmp_path / f"rep_{where.name}" / "plausibility.csv")
        assert df["sim_sequences"].tolist() == [1]
        sim_mm, ref_mm = df["body_floor_depth_max_mm_sim"][0], df["body_floor_depth_max_mm_ref"][0]
        assert sim_mm - ref_mm == pytest.approx(30.0, abs=1.0), where
        sim.unlink()
    sim = _fake_export(synth, run / "sim.h5", 0.03, sha)
    given = build_report([ev], tmp_path / "rep_given", plausibility=[sim])  # given and found: counted once
    assert given.exports == [sim]
    assert "plausibility.csv" not in build_report([ev], tmp_path / "rep_off", find_exports=False).files
    r = CliRunner().invoke(app, ["report", str(ev), "-o", str(tmp_path / "rep_cli")])
    assert r.exit_code == 0 and f"plausibility of the exports {sim.resolve()}" in r.output, r.output
    r = CliRunner().invoke(app, ["report", str(ev), "--no-find-exports", "-o", str(tmp_path / "rep_cli_off")])
    assert r.exit_code == 0 and not (tmp_path / "rep_cli_off" / "plausibility.csv").exists()
    r = CliRunner().invoke(app, ["report", "--help"])
    assert "--no-find-exports" in r.output
