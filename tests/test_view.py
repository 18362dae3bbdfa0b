"""``wristmimic view``: recordings read back with ``rr.chunk.RrdReader`` (entity paths, frames, values,
blueprint), geometry placement, the rollout's terminal state, and the CLI."""

from __future__ import annotations

from pathlib import Path

import mujoco
import numpy as np
import pytest
import rerun as rr
import torch
from typer.testing import CliRunner

from wristmimic.cli.main import app
from wristmimic.convert.common import ConvertOptions
from wristmimic.convert.intermimic import convert_intermimic
from wristmimic.convert.skillmimic_parahome import convert_skillmimic_parahome
from wristmimic.env import window as W
from wristmimic.env.config import EnvConfig, TerminationConfig, WindowConfig
from wristmimic.env.vec_env import WristMimicEnv
from wristmimic.format.reader import open_dataset
from wristmimic.rotations import quat_angle, quat_rotate, wxyz_to_xyzw
from wristmimic.view import record_reference, record_rollout
from wristmimic.view.geometry import body_geoms, entity_part, geom_archetype

from synthetic import write_intermimic_folder, write_parahome_folder

T = 40
NO_END = TerminationConfig(fall_height=-1.0, body_error=1e9, object_error=1e9, contact_lost_frames=10**6)


@pytest.fixture(scope="module")
def files(tmp_path_factory: pytest.TempPathFactory) -> dict[str, tuple[Path, str]]:
    tmp = tmp_path_factory.mktemp("view")
    opts = ConvertOptions(hull_cache_dir=tmp / "hulls", show_progress=False)
    convert_intermimic(write_intermimic_folder(tmp / "im", T=T), tmp / "im.h5", options=opts)
    convert_skillmimic_parahome(write_parahome_folder(tmp / "ph", T=T), tmp / "ph.h5", options=opts)
    return {"smplx": (tmp / "im.h5", "sub1_box_000"), "parahome": (tmp / "ph.h5", "s1_move_box")}


# -- reading a recording back --------------------------------------------------------------------------------
class Recording:
    """Every chunk of an .rrd grouped by entity path, with helpers to pull columns out as numpy."""

    def __init__(self, path: Path):
        self.reader = rr.chunk.RrdReader(path)
        self.batches: dict[str, list] = {}
        for chunk in self.reader.stream().to_chunks():
            self.batches.setdefault(chunk.entity_path, []).append(chunk.to_record_batch())
        self.paths = set(self.batches) - {"/__properties"}

    def static(self, path: str, component: str) -> list:
        """The instances of a static component."""
        rows = [b for b in self.batches[path] if "frame" not in b.schema.names and component in b.schema.names]
        assert len(rows) == 1, (path, component)
        return rows[0].column(component).to_pylist()[0]

    def temporal(self, path: str, component: str) -> tuple[np.ndarray, list]:
        """(frames, per-row values) over every chunk of ``path`` with a ``frame`` column, sorted by frame."""
        frames, values = [], []
        for b in self.batches[path]:
            if "frame" in b.schema.names and component in b.schema.names:
                frames += b.column("frame").to_pylist()
                values += b.column(component).to_pylist()
        order = np.argsort(frames, kind="stable")
        return np.asarray(frames)[order], [values[i] for i in order]

    def vectors(self, path: str, component: str) -> tuple[np.ndarray, np.ndarray]:
        """Rows holding exactly one vector each (transforms) -> (frames, (rows, n))."""
        frames, rows = self.temporal(path, component)
        assert all(len(r) == 1 for r in rows)
        return frames, np.asarray([r[0] for r in rows])

    def scalars(self, path: str) -> tuple[np.ndarray, np.ndarray]:
        frames, rows = self.temporal(path, "Scalars:scalars")
        return frames, np.asarray([r[0] for r in rows])


def body_paths(src: str, names: list[str]) -> set[str]:
    return {f"/{src}/body/{entity_part(n)}" for n in names}


# -- geometry ------------------------------------------------------------------------------------------------
def test_geoms_are_placed_like_mujoco_places_them() -> None:
    """Capsule end points, cylinder and box centres and mesh vertices in the body frame match MuJoCo."""
    xml = """<mujoco><asset><mesh name="tet" vertex="0 0 0  0.1 0 0  0 0.1 0  0 0 0.1"/></asset><worldbody>
      <body name="b" pos="0.3 0 1" quat="0.9 0.1 0.3 0.2"><freejoint/>
        <geom type="capsule" size="0.02" fromto="0.01 0.02 0.03 0.1 0.2 0.3"/>
        <geom type="cylinder" size="0.03" fromto="0 0 0 0 0.2 0"/>
        <geom type="box" size="0.01 0.02 0.03" pos="0.1 0 0" euler="10 20 30"/>
        <geom type="sphere" size="0.05" pos="0 0 0.2"/>
        <geom type="mesh" mesh="tet" pos="0.2 0.1 0"/>
      </body></worldbody></mujoco>"""
    model = mujoco.MjModel.from_xml_string(xml)
    shapes = body_geoms(model, 1)
    assert [s.kind for s in shapes] == ["capsule", "cylinder", "box", "sphere", "mesh"]
    cap = shapes[0].quat, shapes[0].pos, shapes[0].size
    ends = [cap[1] + quat_rotate(cap[0], [0, 0, h * cap[2][1]]) for h in (-1, 1)]
    fromto = np.array([[0.01, 0.02, 0.03], [0.1, 0.2, 0.3]])
    assert np.allclose(sorted(map(tuple, ends)), sorted(map(tuple, fromto)), atol=1e-9)
    # the rerun capsule starts at one end point and extends 2 * half-length along the geom's +z
    capsule = geom_archetype(shapes[0], (255, 0, 0, 255))
    assert isinstance(capsule, rr.Capsules3D)
    start = np.asarray(capsule.translations.pa_array.to_pylist()[0])
    length = capsule.lengths.pa_array.to_pylist()[0]
    end = start + quat_rotate(shapes[0].quat, [0, 0, length])
    assert np.allclose(sorted(map(tuple, [start, end])), sorted(map(tuple, fromto)), atol=1e-6)
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    for g, s in enumerate(shapes):  # body frame -> world equals MuJoCo's geom_xpos
        world = quat_rotate(data.xquat[1], s.pos) + data.xpos[1]
        assert np.allclose(world, data.geom_xpos[g], atol=1e-9), s.kind
    mesh = shapes[4]
    assert mesh.vertices is not None and mesh.faces is not None and mesh.faces.shape[1] == 3
    assert np.allclose(mesh.vertices.mean(0), [0.225, 0.125, 0.025], atol=1e-6)  # tetrahedron centroid + pos


# -- reference only ------------------------------------------------------------------------------------------
def test_reference_recording_holds_the_converted_data(files, tmp_path: Path) -> None:
    path, sid = files["smplx"]
    out = tmp_path / "ref.rrd"
    summary = record_reference(path, sid, out, hulls=True)
    assert summary.ref_frames == T and summary.sim_frames == 0 and out.stat().st_size == summary.bytes
    assert [p.name for p in tmp_path.iterdir()] == ["ref.rrd"]  # no temporary file left beside it
    rec = Recording(out)
    assert len(rec.reader.recordings()) == 1 and len(rec.reader.blueprints()) == 1
    with open_dataset(path) as ds:
        seq = ds.sequence(sid)
        s = seq.load()
        names = ds.humanoid(seq.humanoid_id).body_names
    assert not any(p.startswith("/sim") for p in rec.paths)
    assert body_paths("ref", names) <= rec.paths
    for n in names:  # every body has at least one geom, static
        assert f"/ref/body/{entity_part(n)}/geom_0" in rec.paths
    expected = {"/ref/object/box", "/ref/object/box/mesh", "/ref/object/box/hulls/hull_0", "/metrics/phase"}
    expected |= {"/ref/contacts/contact", "/ref/contacts/avoid", "/metrics/contact/ref/left", "/events", "/info"}
    assert expected <= rec.paths
    assert not any(p.startswith("/metrics/error") for p in rec.paths)
    b = names.index("L_Wrist") if "L_Wrist" in names else len(names) // 2
    frames, trans = rec.vectors(f"/ref/body/{entity_part(names[b])}", "Transform3D:translation")
    _, quat = rec.vectors(f"/ref/body/{entity_part(names[b])}", "Transform3D:quaternion")
    assert frames.tolist() == list(range(T))
    np.testing.assert_array_equal(trans[17], s.body_pos[17, b].astype(np.float32))  # float32 round trip
    np.testing.assert_allclose(quat, wxyz_to_xyzw(s.body_quat[:, b]), atol=1e-7)  # xyzw in rerun
    assert not np.allclose(quat[:, 0], s.body_quat[:, b, 0])  # (not wxyz)
    times, _ = rec.temporal(f"/ref/body/{entity_part(names[b])}", "time")
    _, obj = rec.vectors("/ref/object/box", "Transform3D:translation")
    np.testing.assert_array_equal(obj, s.object_pos[:, 0].astype(np.float32))
    # contact markers: one point per body labelled 1 in each frame, at that body
    frames, pts = rec.temporal("/ref/contacts/contact", "Points3D:positions")
    assert frames.tolist() == list(range(T))
    assert [len(p) for p in pts] == (s.contact_labels == 1).sum(1).tolist()
    t = int(np.argmax((s.contact_labels == 1).sum(1)))
    np.testing.assert_allclose(pts[t], s.body_pos[t][s.contact_labels[t] == 1], atol=1e-7)
    assert rec.static("/ref/contacts/contact", "Points3D:colors") != rec.static(
        "/ref/contacts/avoid", "Points3D:colors"
    )
    # hand contact and phases
    _, left = rec.scalars("/metrics/contact/ref/left")
    np.testing.assert_array_equal(left, s.hand_contact[:, 0].astype(float))
    _, phase = rec.scalars("/metrics/phase")
    first = s.first_contact_frame
    t_c = int(first[first >= 0].min())
    ref_phase = W.phase(torch.arange(T), torch.full((T,), t_c), WindowConfig()).numpy()
    np.testing.assert_array_equal(phase, ref_phase)
    assert set(phase.tolist()) >= {W.GRASP, W.STABILIZE, W.OUTSIDE}
    _, text = rec.temporal("/events", "TextLog:text")
    assert any("phase: grasp" in x[0] for x in text) and any("first contact of the left hand" in x[0] for x in text)
    info = rec.static("/info", "TextDocument:text")[0]
    assert sid in info and f"t_c = {t_c}" in info


def test_reference_with_an_inferred_support(files, tmp_path: Path) -> None:
    path, sid = files["parahome"]
    out = tmp_path / "ph.rrd"
    record_reference(path, sid, out, max_frames=25)
    rec = Recording(out)
    with open_dataset(path) as ds:
        seq = ds.sequence(sid)
        names = ds.humanoid(seq.humanoid_id).body_names
        support = next(o for o in seq.object_ids if ds.object(o).inferred)
        pos0 = seq.array("object_pos", slice(0, 1))[0, seq.object_ids.index(support)]
    assert body_paths("ref", names) <= rec.paths and len(names) == 61
    frames, _ = rec.vectors(f"/ref/body/{entity_part(names[0])}", "Transform3D:translation")
    assert len(frames) == 25
    sp = f"/ref/object/{entity_part(support)}"
    assert {sp, f"{sp}/mesh"} <= rec.paths
    np.testing.assert_allclose(rec.static(sp, "Transform3D:translation")[0], pos0, atol=1e-6)  # one static pose
    assert not rec.temporal(sp, "Transform3D:translation")[0].size
    assert "inferred support" in rec.static("/info", "TextDocument:text")[0]


# -- rollouts ------------------------------------------------------------------------------------------------
def reference_targets(env: WristMimicEnv):
    """A stand-in policy: actions that command the reference joint angles of the next frame."""
    lo, hi = env.scene.ctrl_range[:, 0], env.scene.ctrl_range[:, 1]
    offset, scale = (lo + hi) / 2, (hi - lo) / 2
    wide = np.abs(offset) > 0.1
    offset[wide], scale[wide] = 0.0, np.pi
    offset_t, scale_t = torch.as_tensor(offset, dtype=torch.float32), torch.as_tensor(scale, dtype=torch.float32)

    def act(obs: torch.Tensor) -> torch.Tensor:
        f = int(env.frame[0]) + 1
        target = env.ref.joint_angles[min(f, env.ref.num_frames - 1)]
        return ((target - offset_t) / scale_t).clamp(-1, 1).expand(obs.shape[0], -1)

    return act


def test_rollout_recording_beside_its_reference(files, tmp_path: Path) -> None:
    path, sid = files["smplx"]
    cfg = EnvConfig(wrist_resets=False, termination=NO_END)
    env = WristMimicEnv.from_file(path, sid, num_worlds=1, config=cfg, nthread=1)
    out = tmp_path / "rollout.rrd"
    summary = record_rollout(env, reference_targets(env), out, hulls=True, info={"policy": "stand-in"})
    assert summary.end_reason == "truncated" and summary.sim_frames == T  # frames 0 .. T-1
    rec = Recording(out)
    assert len(rec.reader.blueprints()) == 1
    names = list(env.scene.skeleton.body_names)
    assert body_paths("ref", names) | body_paths("sim", names) <= rec.paths
    assert {"/sim/object/box", "/sim/object/box/mesh", "/sim/object/box/hulls/hull_0", "/ref/object/box"} <= rec.paths
    assert "/ref/object/box/hulls/hull_0" not in rec.paths  # hulls only beside the simulated object
    series = [f"/metrics/error/{k}" for k in ("object_pos/box", "object_rot/box", "wrist_pos/left", "wrist_rot/right")]
    assert set(series) | {"/metrics/error/body_pos/mean", "/metrics/reward", "/metrics/contact/sim/left"} <= rec.paths
    for p in series + ["/metrics/error/body_pos/mean"]:
        frames, v = rec.scalars(p)
        assert frames.tolist() == list(range(T)) and np.isfinite(v).all() and (v >= 0).all(), p
        assert v[0] < 1e-3, p  # the episode starts from the reference state
    # the wrist error curve is the distance between the logged sim and ref wrist translations
    wrist = names[int(env.scene.humanoid.roles["wrists"][0])]
    _, sim_w = rec.vectors(f"/sim/body/{entity_part(wrist)}", "Transform3D:translation")
    _, ref_w = rec.vectors(f"/ref/body/{entity_part(wrist)}", "Transform3D:translation")
    _, err = rec.scalars("/metrics/error/wrist_pos/left")
    np.testing.assert_allclose(err, np.linalg.norm(sim_w - ref_w, axis=1), atol=1e-6)
    assert err.max() > 1e-4  # the simulation is not the reference
    _, reward = rec.scalars("/metrics/reward")
    assert len(reward) == T - 1 and ((reward >= 0) & (reward <= 1)).all()
    info = rec.static("/info", "TextDocument:text")[0]
    assert "policy: stand-in" in info and "truncated" in info
    env.close()


def test_rollout_keeps_the_state_that_ended_the_episode(files, tmp_path: Path) -> None:
    """The environment resets an ended world inside ``step``; the recording still ends on the state that
    triggered the termination (here: the left wrist beyond the grasp-phase threshold), not the reset one."""
    path, sid = files["smplx"]
    env = WristMimicEnv.from_file(path, sid, num_worlds=1, nthread=1)
    out = tmp_path / "zeros.rrd"
    summary = record_rollout(env, lambda obs: torch.zeros(obs.shape[0], env.action_size), out)
    assert summary.end_reason == "terminated: wrist" and 2 <= summary.sim_frames < T
    rec = Recording(out)
    frames, pos = rec.scalars("/metrics/error/wrist_pos/left")
    _, rot = rec.scalars("/metrics/error/wrist_rot/left")
    assert frames.tolist() == list(range(summary.sim_frames))
    thr = env.cfg.wrist
    assert env.ref.t_c == 0 and frames[-1] <= env.cfg.window.tau2  # the grasp phase
    assert pos[-1] > thr.grasp_pos or np.radians(rot[-1]) > thr.grasp_rot
    assert pos[-2] <= thr.grasp_pos and np.radians(rot[-2]) <= thr.grasp_rot
    wrist = env.scene.skeleton.body_names[int(env.scene.humanoid.roles["wrists"][0])]
    _, q = rec.vectors(f"/sim/body/{entity_part(wrist)}", "Transform3D:quaternion")
    ref_q = env.ref.body_quat[frames[-1], int(env.scene.humanoid.roles["wrists"][0])].numpy()
    assert np.degrees(quat_angle(np.r_[q[-1, 3], q[-1, :3]], ref_q)) == pytest.approx(rot[-1], abs=1e-3)
    # the last state continues the rollout (no jump) and is no reference frame (a reset puts one there)
    names = env.scene.skeleton.body_names
    sim = np.stack([rec.vectors(f"/sim/body/{entity_part(n)}", "Transform3D:translation")[1] for n in names], 1)
    assert np.abs(sim[-1] - sim[-2]).max() < 0.3
    ref = env.ref.body_pos.numpy()
    assert np.abs(ref - sim[-1][None]).max(axis=(1, 2)).min() > 5e-3
    ev_frames, text = rec.temporal("/events", "TextLog:text")
    assert [f for f, x in zip(ev_frames, text, strict=True) if "episode ended (terminated: wrist)" in x[0]] == [
        frames[-1]
    ]
    env.close()


class StandInPolicy:
    """A fixed random MLP with a fixed sigma, shaped like ``wristmimic.evaluate.EvalPolicy``."""

    def __init__(self, obs_size: int, action_size: int, metadata: dict):
        g = torch.Generator().manual_seed(1)
        self.w1 = torch.randn(obs_size, 32, generator=g) / obs_size**0.5
        self.w2 = torch.randn(32, action_size, generator=g) * 0.03  # small: the synthetic humanoid stays stable
        self.metadata = metadata
        self.sigma = torch.full((action_size,), 0.02)

    def act(self, obs: torch.Tensor, deterministic: bool = True) -> torch.Tensor:
        return torch.tanh(obs @ self.w1) @ self.w2


@pytest.mark.parametrize("lax", [True, False])
def test_a_trial_seed_replays_the_evaluation_trial(files, tmp_path: Path, lax: bool) -> None:
    """``evaluation_actor(policy, seed)`` reproduces a trial of ``wristmimic.evaluate.run_trials`` (noise
    ``actions``): same length, same termination, same per-trial metrics."""
    from wristmimic.evaluate.trials import TrialSettings, make_env, run_trials
    from wristmimic.view.rollout import evaluation_actor

    path, sid = files["smplx"]
    env_cfg = EnvConfig(wrist_resets=False, termination=NO_END) if lax else EnvConfig()
    meta = {"scene": sid, "variant": "wristmimic", "dataset": str(path), "env": env_cfg}
    env = make_env(meta, 1, nthread=1)
    env.reset()
    policy = StandInPolicy(env.observation_size, env.action_size, meta)
    rows: list[dict] = []
    threads = torch.get_num_threads()
    torch.set_num_threads(1)  # as the recording's rollout runs (faster on a busy machine; same numbers)
    try:
        run_trials(env, policy, TrialSettings(11, "actions", 0.1, 0.8), 2, 3, rows.append)
    finally:
        torch.set_num_threads(threads)
    trial = {k: v[0] for k, v in rows[0].items()}
    env2 = make_env(meta, 1, nthread=1)
    summary = record_rollout(env2, evaluation_actor(policy, int(trial["seed"])), tmp_path / "trial.rrd")
    assert summary.trial["frames_completed"] == trial["frames_completed"]
    assert (summary.end_reason == "truncated") == (not trial["terminated"])
    if trial["terminated"]:
        assert summary.end_reason == f"terminated: {trial['termination_reason']}"
    for k in ("obj_pos_err_cm", "wrist_pos_err_cm", "contact_ratio"):
        assert summary.trial[k] == pytest.approx(trial[k], rel=1e-5, abs=1e-6), k
    for k in ("obj_rot_err_deg", "wrist_rot_err_deg"):
        assert summary.trial[k] == pytest.approx(trial[k], abs=2e-2), k
    mean_only = record_rollout(env2, evaluation_actor(policy), tmp_path / "mean.rrd")
    assert mean_only.trial != summary.trial  # the noise matters
    env.close()
    env2.close()


# -- CLI -----------------------------------------------------------------------------------------------------
runner = CliRunner()


def test_cli_dataset_and_errors(files, tmp_path: Path) -> None:
    path, sid = files["smplx"]
    r = runner.invoke(app, ["view", "--help"])
    assert r.exit_code == 0 and "Example" in r.output and "--reference-only" in r.output
    out = tmp_path / "cli.rrd"
    r = runner.invoke(app, ["view", str(path), "--sequence", sid, "-o", str(out), "--frames", "10"])
    assert r.exit_code == 0, r.output
    assert "wrote" in r.stdout and "reference 10 frames" in r.stdout
    assert Recording(out).vectors("/ref/object/box", "Transform3D:translation")[0].tolist() == list(range(10))
    for args, message in (
        ([str(path), "-o", str(tmp_path / "a.rrd")], "--sequence: missing"),
        ([str(path), "-s", "nope", "-o", str(tmp_path / "a.rrd")], "no such sequence"),
        ([str(path), "-s", sid, "--trial-seed", "1", "-o", str(tmp_path / "a.rrd")], "is for a trained run"),
        ([str(path), "-s", sid, "-o", str(tmp_path / "a.txt")], "not an .rrd file name"),
        ([str(tmp_path / "missing"), "-o", str(tmp_path / "a.rrd")], "not found"),
    ):
        r = runner.invoke(app, ["view", *args])
        assert r.exit_code == 1 and message in r.output, (args, r.output)
        assert len(r.output.strip().splitlines()) == 1 and r.output.startswith("error: ")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cli.rrd"]


def test_cli_records_a_trained_run(files, tmp_path: Path) -> None:
    """A one-iteration run of ``wristmimic.rl`` on the synthetic scene: rollout, sampled trial, reference."""
    from wristmimic.rl import TrainSpec, preset, start_run

    path, sid = files["smplx"]
    ppo = preset("cpu", num_envs=2, horizon=4, max_frames=8, actor_hidden=(16,), critic_hidden=(16,))
    run = start_run(TrainSpec(path, sid, ppo=ppo, ref_frames=20), tmp_path / "run", nthread=1, progress=False).run_dir
    r = runner.invoke(app, ["view", str(run), "-o", str(tmp_path / "a.rrd")])
    assert r.exit_code == 0, r.output
    assert "reference 20 frames, simulation" in r.stdout
    rec = Recording(tmp_path / "a.rrd")
    assert any(p.startswith("/sim/body/") for p in rec.paths)
    assert "actions: policy mean" in rec.static("/info", "TextDocument:text")[0]
    trials = []
    for k, seed in enumerate((3, 3)):
        out = tmp_path / f"trial{k}.rrd"
        r = runner.invoke(app, ["view", str(run / "checkpoint.pt"), "--trial-seed", str(seed), "-o", str(out)])
        assert r.exit_code == 0, r.output
        trials.append(Recording(out).scalars("/metrics/error/body_pos/mean")[1])
    np.testing.assert_array_equal(trials[0], trials[1])  # same trial seed, same rollout
    r = runner.invoke(app, ["view", str(run), "--reference-only", "-o", str(tmp_path / "r.rrd")])
    assert r.exit_code == 0, r.output
    assert not any(p.startswith("/sim") for p in Recording(tmp_path / "r.rrd").paths)
    r = runner.invoke(app, ["view", str(run), "--trial-seed", "1", "--deterministic", "-o", str(tmp_path / "x.rrd")])
    assert r.exit_code == 1 and "conflicts with --trial-seed" in r.output


# -- shared data ---------------------------------------------------------------------------------------------
@pytest.mark.shared_data
def test_shared_parahome_reference_with_inferred_supports(parahome_h5: Path, tmp_path: Path) -> None:
    sid = "s110_move_kettle"
    out = tmp_path / "kettle.rrd"
    summary = record_reference(parahome_h5, sid, out, hulls=True)
    rec = Recording(out)
    with open_dataset(parahome_h5) as ds:
        seq = ds.sequence(sid)
        names = ds.humanoid(seq.humanoid_id).body_names
        inferred = [o for o in seq.object_ids if ds.object(o).inferred]
        body_pos = seq.array("body_pos")
    assert len(names) == 61 and body_paths("ref", names) <= rec.paths
    assert inferred and all(f"/ref/object/{entity_part(o)}/mesh" in rec.paths for o in inferred)
    b = len(names) - 1
    frames, trans = rec.vectors(f"/ref/body/{entity_part(names[b])}", "Transform3D:translation")
    assert len(frames) == summary.ref_frames == seq.num_frames
    np.testing.assert_array_equal(trans[seq.num_frames // 2], body_pos[seq.num_frames // 2, b])
    assert not any(p.startswith("/sim") for p in rec.paths)


# -- issue #17: the end of an episode, plots over the clip, colours, legends, exported rollouts ---------------
def blueprint_views(path: Path) -> dict[str, dict[str, list]]:
    """View name -> its blueprint components (e.g. ``TimeAxis:view_range``) read back from the recording."""
    reader = rr.chunk.RrdReader(path)
    rows: dict[str, dict[str, list]] = {}
    for chunk in reader.stream(store=reader.blueprints()[0]).to_chunks():
        if not chunk.entity_path.startswith("/view/"):
            continue
        b = chunk.to_record_batch()
        view = chunk.entity_path.split("/")[2]
        rows.setdefault(view, {}).update({n: b.column(n).to_pylist()[-1] for n in b.schema.names if ":" in n})
    return {r["ViewBlueprint:display_name"][0]: r for r in rows.values() if "ViewBlueprint:display_name" in r}


def series_names(rec: Recording) -> dict[str, str]:
    """Series path -> its legend name."""
    named = [p for p in rec.paths if any("SeriesLines:names" in b.schema.names for b in rec.batches[p])]
    return {p: rec.static(p, "SeriesLines:names")[0] for p in named}


def test_an_early_end_clears_the_simulation_and_is_marked(files, tmp_path: Path) -> None:
    """Terminated at frame k < T - 1: the simulated geoms are logged at the first frame (not static, which no
    Clear removes), frame k + 1 clears /sim and the simulated series recursively and shows /episode/end with the
    frame and reason; every time-series view spans frames 0..T-1; legend names are short; reference and
    simulated contact series have four distinct colours."""
    from wristmimic.view.record import LEGEND_CHARS

    path, sid = files["smplx"]
    env = WristMimicEnv.from_file(path, sid, num_worlds=1, nthread=1)
    out = tmp_path / "zeros.rrd"
    summary = record_rollout(env, lambda obs: torch.zeros(obs.shape[0], env.action_size), out)
    k = summary.sim_frames - 1
    assert summary.end_reason == "terminated: wrist" and k < T - 1
    rec = Recording(out)
    names = env.scene.skeleton.body_names
    geom = f"/sim/body/{entity_part(names[0])}/geom_0"
    assert not any("frame" not in b.schema.names for b in rec.batches[geom])  # nothing static under /sim
    color = next(c for c in rec.batches[geom][0].schema.names if c.endswith(":colors"))
    assert rec.temporal(geom, color)[0].tolist() == [0]
    for p in ("/sim", "/metrics/error", "/metrics/contact/sim", "/metrics/reward"):
        frames, clear = rec.temporal(p, "Clear:is_recursive")
        assert frames.tolist() == [k + 1] and clear == [[True]], p
    frames, labels = rec.temporal("/episode/end", "Points3D:labels")
    assert frames.tolist() == [k + 1] and labels == [[f"episode ended at frame {k}: terminated: wrist"]]
    _, pos = rec.vectors("/episode/end", "Points3D:positions")
    _, root = rec.vectors(f"/sim/body/{entity_part(names[0])}", "Transform3D:translation")
    np.testing.assert_allclose(pos[0], root[-1], atol=1e-6)
    views = blueprint_views(out)
    assert "/episode/**" in str(views["reference vs simulation"])
    for name in ("position error (m)", "rotation error (deg)", "reward", "contact and phase"):
        assert views[name]["TimeAxis:view_range"] == [{"start": 0, "end": T - 1}], name
    legend = series_names(rec)
    assert legend and all(len(n) <= LEGEND_CHARS for n in legend.values()), legend
    assert legend["/metrics/error/wrist_pos/left"] == "wrist L" and legend["/metrics/error/object_pos/box"] == "box"
    contact = [f"/metrics/contact/{s}/{h}" for s in ("ref", "sim") for h in ("left", "right")]
    assert [legend[p] for p in contact] == ["ref L", "ref R", "sim L", "sim R"]
    colors = [rec.static(p, "SeriesLines:colors")[0] for p in contact]
    assert len(set(colors)) == 4
    env.close()


def test_a_rollout_to_the_end_of_the_clip_clears_nothing(files, tmp_path: Path) -> None:
    path, sid = files["smplx"]
    env = WristMimicEnv.from_file(path, sid, num_worlds=1, config=EnvConfig(wrist_resets=False, termination=NO_END))
    out = tmp_path / "full.rrd"
    assert record_rollout(env, reference_targets(env), out).end_reason == "truncated"
    rec = Recording(out)
    assert not {"/episode/end", "/sim", "/metrics/error"} & rec.paths  # no clear, no marker
    env.close()


def test_view_an_exported_sequence_beside_its_reference(files, tmp_path: Path) -> None:
    """`wristmimic view EXPORT.h5 -s <scene>__sim_mean`: the exported frames as /sim beside the reference the
    provenance names (its reference frames), in the rollout colours, with per-frame plausibility of both."""
    from wristmimic.evaluate import load_eval_policy
    from wristmimic.evaluate.export import export_rollouts
    from wristmimic.plausibility import plausibility_series
    from wristmimic.rl import TrainSpec, preset, start_run
    from wristmimic.view.record import LEGEND_CHARS, PALETTE

    path, sid = files["smplx"]
    ppo = preset("cpu", num_envs=2, horizon=4, max_frames=8, actor_hidden=(16,), critic_hidden=(16,))
    run = start_run(TrainSpec(path, sid, ppo=ppo, ref_frames=20), tmp_path / "run", nthread=1, progress=False).run_dir
    sim_h5 = tmp_path / "sim.h5"
    (seq,) = export_rollouts(load_eval_policy(run), sim_h5, nthread=1, progress=False).sequences
    out = tmp_path / "export.rrd"
    r = runner.invoke(app, ["view", str(sim_h5), "-s", seq, "-o", str(out)])
    assert r.exit_code == 0, r.output
    rec = Recording(out)
    with open_dataset(sim_h5) as ds:
        s = ds.sequence(seq).load()
        n = s.body_pos.shape[0]
        sim_plaus = plausibility_series(ds, seq)
    with open_dataset(path) as ds:
        names = ds.humanoid(ds.sequence(sid).humanoid_id).body_names
    assert body_paths("ref", names) | body_paths("sim", names) <= rec.paths
    frames, trans = rec.vectors(f"/sim/body/{entity_part(names[0])}", "Transform3D:translation")
    assert frames.tolist() == list(range(n))
    np.testing.assert_array_equal(trans, s.body_pos[:, 0].astype(np.float32))
    assert rec.vectors(f"/ref/body/{entity_part(names[0])}", "Transform3D:translation")[0].tolist() == list(range(20))
    geom = f"/sim/body/{entity_part(names[0])}/geom_0"
    color = next(c for c in rec.batches[geom][0].schema.names if c.endswith(":colors"))
    packed = rec.temporal(geom, color)[1][0][0]
    assert packed == int.from_bytes(bytes(PALETTE.sim_body), "big")  # the rollout blue
    for metric in ("hand_object_depth_m", "body_floor_depth_m", "body_jerk_m_s3"):
        assert {f"/metrics/plausibility/{metric}/ref", f"/metrics/plausibility/{metric}/sim"} <= rec.paths
    f, v = rec.scalars("/metrics/plausibility/body_floor_depth_m/sim")
    np.testing.assert_allclose(v, sim_plaus["body_floor_depth_m"][f])
    ref_f, _ = rec.scalars("/metrics/plausibility/body_floor_depth_m/ref")
    assert ref_f.tolist() == list(range(20))
    legend = series_names(rec)
    assert all(len(x) <= LEGEND_CHARS and not x.endswith("~") for x in legend.values()), legend  # none cut
    views = blueprint_views(out)
    assert views["hand-obj (m)"]["TimeAxis:view_range"] == [{"start": 0, "end": 19}]
    assert "reward" not in views and "contact and phase" in views  # no empty reward view: an export has none
    if n < 20:  # the tiny policy's episode ended early
        assert rec.temporal("/sim", "Clear:is_recursive")[0].tolist() == [n]
    assert seq in rec.static("/info", "TextDocument:text")[0]
    r = runner.invoke(app, ["view", str(sim_h5), "-s", seq, "--frames", "3", "-o", str(tmp_path / "x.rrd")])
    assert r.exit_code == 1 and "--frames" in r.output


def test_plausibility_views_show_every_legend_name_in_distinct_colours(files, tmp_path: Path) -> None:
    """Every plausibility metric is in exactly one tab of at most 4 series (2 metrics x ref/sim: a tab of 8 showed
    only 4 legend names at a 900-pixel window); within a tab no two series share a colour, the reference series
    are warm (red over blue) and the simulated ones cool, as the contact series are."""
    from wristmimic.plausibility import plausibility_series
    from wristmimic.view.blueprint import PLAUSIBILITY_VIEWS
    from wristmimic.view.record import write_recording
    from wristmimic.view.tracks import reference_from_dataset

    path, sid = files["smplx"]
    with open_dataset(path) as ds:
        ref = reference_from_dataset(ds, sid, None)
        series = plausibility_series(ds, sid)
    out = tmp_path / "plaus.rrd"
    write_recording(out, ref, [[] for _ in range(ref.body_pos.shape[1])], plausibility={"ref": series, "sim": series})
    rec = Recording(out)
    logged = {p for p in rec.paths if p.startswith("/metrics/plausibility/")}
    assert logged == {f"/metrics/plausibility/{m}/{src}" for m in series for src in ("ref", "sim")}
    prefix = "/metrics/plausibility/"
    views = {
        name: [q.removesuffix("/**") + "/" for q in v["ViewContents:query"]]
        for name, v in blueprint_views(out).items()
        if any(q.startswith(prefix) for q in v.get("ViewContents:query", []))
    }
    assert set(views) == set(PLAUSIBILITY_VIEWS)
    shown: list[str] = []
    for name, queries in views.items():
        paths = sorted(p for p in logged if any(p.startswith(q) for q in queries))
        assert 1 <= len(paths) <= 4, (name, paths)
        colors = {p: rec.static(p, "SeriesLines:colors")[0] for p in paths}
        assert len(set(colors.values())) == len(paths), (name, colors)  # no two series of a tab alike
        for p, c in colors.items():
            red, blue = c >> 24, (c >> 8) & 0xFF
            assert (red > blue) if p.endswith("/ref") else (blue > red), (p, hex(c))
        shown += paths
    assert sorted(shown) == sorted(logged)  # each series in exactly one tab
