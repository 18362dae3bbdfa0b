"""Scene builder: gains by body part, finger ranges, collision filtering, objects, sensors, MJCF export,
and the reference replay that chose the timestep."""

from __future__ import annotations

from pathlib import Path

import mujoco
import numpy as np
import pytest
from typer.testing import CliRunner

from wristmimic.cli.main import app
from wristmimic.convert.common import ConvertOptions
from wristmimic.convert.intermimic import convert_intermimic
from wristmimic.convert.skillmimic_parahome import convert_skillmimic_parahome
from wristmimic.format import open_dataset
from wristmimic.rl.config import to_jsonable
from wristmimic.scene import SceneConfig, build_scene, finger_ranges, gain_groups, scene_config_from_dict
from wristmimic.sim.warp_backend import newton_for_pgs

from synthetic import write_intermimic_folder, write_parahome_folder


@pytest.fixture(scope="module")
def synth_files(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    tmp = tmp_path_factory.mktemp("scene")
    opts = ConvertOptions(hull_cache_dir=tmp / "c", show_progress=False)
    im = tmp / "im.h5"
    convert_intermimic(write_intermimic_folder(tmp / "im"), im, options=opts)
    ph = tmp / "ph.h5"
    convert_skillmimic_parahome(write_parahome_folder(tmp / "ph"), ph, options=opts)
    return im, ph


def test_smplx_scene_gains_ranges_and_collisions(synth_files: tuple[Path, Path]) -> None:
    with open_dataset(synth_files[0]) as ds:
        sc = build_scene(ds, "sub1_box_000")
    m = sc.model
    assert m.nu == 153 and m.opt.timestep == pytest.approx(1 / 120) and m.numeric_data[0] == 4
    assert m.opt.integrator == mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    names = sc.skeleton.body_names
    gain = {names[b]: tuple(sc.gains[3 * j]) for j, b in enumerate(sc.skeleton.joint_bodies)}
    assert gain["L_Knee"] == (800, 80) and gain["Spine"] == (1000, 100) and gain["L_Elbow"] == (500, 50)
    assert gain["R_Toe"] == (500, 50) and gain["L_Index2"] == (100, 10) and gain["Head"] == (500, 50)
    # position actuators: kp on gainprm, -kp / -kv on biasprm; joint springs and damping zeroed
    a = sc.actuator_ids[0, 0]
    assert m.actuator_gainprm[a, 0] == 800 and m.actuator_biasprm[a, 1] == -800 and m.actuator_biasprm[a, 2] == -80
    assert np.all(m.jnt_stiffness == 0) and np.all(m.dof_damping[6 : 6 + 153] == 0)
    assert np.allclose(m.dof_armature[6 : 6 + 153], 0.02)
    # InterMimic finger ranges
    j = {n: k for k, n in enumerate(names)}
    r3 = m.jnt_range[sc.model.actuator_trnid[sc.actuator_ids[j["L_Index3"] - 1], 0]]
    assert np.allclose(np.rad2deg(r3[0]), [-90, 5.625]) and np.allclose(np.rad2deg(r3[1]), [-5.625, 5.625])
    r1 = m.jnt_range[sc.model.actuator_trnid[sc.actuator_ids[j["R_Thumb1"] - 1], 0]]
    assert np.allclose(np.rad2deg(r1), [[-55.625, 55.625]] * 3)
    # no self-collision; humanoid meets objects and floor
    hum = [g for g in range(m.ngeom) if m.geom_bodyid[g] in sc.body_ids]
    other = [g for g in range(m.ngeom) if g not in hum and m.geom_contype[g]]

    def collide(a: int, b: int) -> bool:
        return bool(m.geom_contype[a] & m.geom_conaffinity[b] or m.geom_contype[b] & m.geom_conaffinity[a])

    assert not any(collide(a, b) for a in hum for b in hum)
    assert all(collide(a, b) for a in hum[:5] for b in other)
    # dynamic object: stored mass, hull geoms, free joint
    o = sc.objects[0]
    assert o.dynamic and m.body_mass[o.body_id] == pytest.approx(o.record.mass)
    hulls = [g for g in range(m.ngeom) if m.geom_bodyid[g] == o.body_id and m.geom_contype[g]]
    assert len(hulls) == o.record.num_hulls
    assert {"pos:Pelvis", "contact:L_Wrist", "touch:L_Index3:box", "quat:obj_box"} <= set(sc.sensors)


def test_hand_contacts_have_torsional_friction_and_old_runs_keep_theirs(synth_files: tuple[Path, Path]) -> None:
    with open_dataset(synth_files[0]) as ds:
        sc = build_scene(ds, "sub1_box_000")
        old = build_scene(ds, "sub1_box_000", scene_config_from_dict({"timestep": 1 / 120}))
    fingers = ("Wrist", "Index", "Middle", "Ring", "Pinky", "Thumb")
    hand = {sc.body_ids[b] for b, n in enumerate(sc.skeleton.body_names) if any(f in n for f in fingers)}
    for model, condim, torsion in ((sc.model, 4, 0.015), (old.model, 3, 0.005)):
        g = [k for k in range(model.ngeom) if model.geom_bodyid[k] in hand]
        assert g and (model.geom_condim[g] == condim).all()
        if condim == 4:
            assert np.allclose(model.geom_friction[g, 1], torsion)
        ids = set(sc.body_ids.tolist())
        body = [k for k in range(model.ngeom) if model.geom_bodyid[k] in ids and model.geom_bodyid[k] not in hand]
        assert (model.geom_condim[body] == 3).all()  # only the hands get torsional friction


def test_support_friction_governs_object_floor_contacts_but_not_the_hands(synth_files: tuple[Path, Path]) -> None:
    """support_friction: object-floor contacts take it, hand-object contacts keep the hands' friction (priority)."""
    from wristmimic.errors import InputError

    def contact_friction(sc, hand: bool) -> float:
        m, d = sc.model, mujoco.MjData(sc.model)
        o = sc.objects[0]
        mujoco.mj_forward(m, d)
        wrist = sc.body_ids[sc.skeleton.body_names.index("L_Wrist")]
        adr = m.jnt_qposadr[m.body_jntadr[o.body_id]]
        d.qpos[adr : adr + 3] = d.xpos[wrist] if hand else [5.0, 5.0, 0.0]  # on the wrist / half into the floor
        mujoco.mj_forward(m, d)
        want = wrist if hand else 0
        mus = [
            d.contact[i].friction[0]
            for i in range(d.ncon)
            if {m.geom_bodyid[d.contact[i].geom1], m.geom_bodyid[d.contact[i].geom2]} == {o.body_id, want}
        ]
        assert mus, "no contact made"
        return float(mus[0])

    with open_dataset(synth_files[0]) as ds:
        base = build_scene(ds, "sub1_box_000", SceneConfig(hand_friction=None))  # the MJCF's own friction
        low = build_scene(ds, "sub1_box_000", SceneConfig(support_friction=0.3, hand_friction=None))
        grip = build_scene(ds, "sub1_box_000", SceneConfig(hand_friction=2.0))
        default = build_scene(ds, "sub1_box_000")
        legacy = build_scene(ds, "sub1_box_000", scene_config_from_dict({"timestep": 1 / 120}))  # predates the field
        both = build_scene(ds, "sub1_box_000", SceneConfig(hand_friction=2.0, support_friction=0.3))
        for field in ("support_friction", "hand_friction"):
            for bad in (-0.1, float("nan")):
                with pytest.raises(InputError, match=field):
                    build_scene(ds, "sub1_box_000", SceneConfig(**{field: bad}))
    assert contact_friction(base, hand=False) == pytest.approx(1.0)  # MuJoCo's max(floor 1.0, object)
    assert contact_friction(low, hand=False) == pytest.approx(0.3)
    assert contact_friction(low, hand=True) == pytest.approx(contact_friction(base, hand=True)) == pytest.approx(1.0)
    assert (base.model.geom_priority == 0).all()
    # hand_friction: the hands' grip changes, the object's friction with the floor does not
    assert contact_friction(grip, hand=True) == pytest.approx(2.0)
    assert contact_friction(grip, hand=False) == pytest.approx(1.0)
    assert contact_friction(default, hand=True) == pytest.approx(2.0)  # the recipe's grip (SceneConfig's default)
    assert contact_friction(default, hand=False) == pytest.approx(1.0)
    assert contact_friction(legacy, hand=True) == pytest.approx(1.0)  # a run recorded before it keeps the MJCF's
    assert contact_friction(both, hand=True) == pytest.approx(2.0)
    assert contact_friction(both, hand=False) == pytest.approx(0.3)


def test_solver_settings_reach_the_model_and_bad_ones_are_refused(synth_files: tuple[Path, Path]) -> None:
    from wristmimic.errors import InputError

    with open_dataset(synth_files[0]) as ds:
        o = build_scene(ds, "sub1_box_000").model.opt  # defaults: MuJoCo's own
        assert (o.solver, o.iterations, o.ls_iterations, o.tolerance, o.cone, o.impratio, o.noslip_iterations) == (
            mujoco.mjtSolver.mjSOL_NEWTON,
            100,
            50,
            1e-8,
            mujoco.mjtCone.mjCONE_PYRAMIDAL,
            1.0,
            0,
        )
        # a run recorded before the solver fields existed stepped with MuJoCo's Newton, 100 iterations
        recorded = {k: v for k, v in to_jsonable(SceneConfig(solver="pgs", iterations=20)).items()}
        recorded = {k: v for k, v in recorded.items() if k not in ("solver", "iterations")}
        o = build_scene(ds, "sub1_box_000", scene_config_from_dict(recorded)).model.opt
        assert (o.solver, o.iterations) == (mujoco.mjtSolver.mjSOL_NEWTON, 100)
        cfg = SceneConfig(
            solver="newton", iterations=7, ls_iterations=5, tolerance=1e-6, cone="elliptic", impratio=10.0
        )
        o = build_scene(ds, "sub1_box_000", cfg).model.opt
        assert (o.solver, o.iterations, o.ls_iterations, o.tolerance, o.cone, o.impratio) == (
            mujoco.mjtSolver.mjSOL_NEWTON,
            7,
            5,
            1e-6,
            mujoco.mjtCone.mjCONE_ELLIPTIC,
            10.0,
        )
        assert build_scene(ds, "sub1_box_000", SceneConfig(noslip_iterations=3)).model.opt.noslip_iterations == 3
        pgs = build_scene(ds, "sub1_box_000", SceneConfig(solver="pgs", iterations=20)).model
        newton = newton_for_pgs(pgs)  # what the Warp backend steps
        assert (newton.opt.solver, newton.opt.iterations) == (mujoco.mjtSolver.mjSOL_NEWTON, 100)
        assert (pgs.opt.solver, pgs.opt.iterations) == (mujoco.mjtSolver.mjSOL_PGS, 20)
        kept = build_scene(ds, "sub1_box_000", cfg).model
        assert newton_for_pgs(kept) is kept
        for bad in (
            SceneConfig(solver="jacobi"),
            SceneConfig(cone="round"),
            SceneConfig(iterations=0),
            SceneConfig(impratio=0.5),
            SceneConfig(impratio=float("nan")),
            SceneConfig(noslip_iterations=-1),
        ):
            with pytest.raises(InputError, match="scene_config"):
                build_scene(ds, "sub1_box_000", bad)


def test_reference_finger_ranges_change_nothing_where_the_reference_stays_inside(omomo_h5: Path) -> None:
    """OMOMO's finger poses lie inside InterMimic's ranges: both settings build the same scene."""
    with open_dataset(omomo_h5) as ds:
        sid = ds.sequence_ids[0]
        a = build_scene(ds, sid)
        b = build_scene(ds, sid, SceneConfig(finger_ranges="reference"))
    np.testing.assert_array_equal(a.ctrl_range, b.ctrl_range)
    np.testing.assert_array_equal(a.model.jnt_range, b.model.jnt_range)


def test_reference_finger_ranges_contain_parahome_grips_that_intermimic_ranges_cut(parahome_h5: Path) -> None:
    """ParaHome's finger poses fall outside InterMimic's SMPL-X ranges; ``finger_ranges=reference`` moves only the
    range ends the sequence's own finger angles pass, to them plus the margin; body hinges are unchanged."""
    from wristmimic.errors import InputError

    with open_dataset(parahome_h5) as ds:
        sid = "s110_move_kettle" if "s110_move_kettle" in ds.sequence_ids else ds.sequence_ids[0]
        old, new = build_scene(ds, sid), build_scene(ds, sid, SceneConfig(finger_ranges="reference"))
        a = ds.sequence(sid).load().joint_angles.reshape(-1, old.ctrl_range.shape[0])
        for bad in (SceneConfig(finger_ranges="anatomical"), SceneConfig(finger_range_margin=-0.1)):
            with pytest.raises(InputError, match="finger_ranges"):
                build_scene(ds, sid, bad)
    fingers = np.repeat(np.isin(old.skeleton.joint_bodies, old.humanoid.roles["fingers"]), 3)

    def outside(sc) -> np.ndarray:
        return (a < sc.ctrl_range[:, 0] - 1e-6) | (a > sc.ctrl_range[:, 1] + 1e-6)

    assert outside(old)[:, fingers].mean() > 0.1 and not outside(old)[:, ~fingers].any()
    assert not outside(new).any()
    np.testing.assert_array_equal(new.ctrl_range[~fingers], old.ctrl_range[~fingers])
    assert np.all(new.ctrl_range[:, 0] <= old.ctrl_range[:, 0]) and np.all(new.ctrl_range[:, 1] >= old.ctrl_range[:, 1])
    margin = SceneConfig().finger_range_margin
    widened = new.ctrl_range[:, 1] > old.ctrl_range[:, 1]
    np.testing.assert_allclose(new.ctrl_range[widened, 1], a.max(0)[widened] + margin, atol=1e-6)
    np.testing.assert_array_equal(widened, a.max(0) > old.ctrl_range[:, 1] + 1e-6)  # only ends the reference passes
    hinge_range = new.model.jnt_range[new.model.dof_jntid[new.hinge_dofadr.reshape(-1)]]
    np.testing.assert_allclose(hinge_range, new.ctrl_range)  # the joint limits move with the targets


def test_every_colliding_geom_has_friction_even_where_the_source_says_condim_1(tmp_path: Path) -> None:
    """SkillMimic's ParaHome humanoid says condim 1 (frictionless in MuJoCo; Isaac Gym ignores it): the scene gives
    every colliding geom (humanoid, floor, supports, objects) sliding friction; runs recorded before keep it."""
    folder = write_parahome_folder(tmp_path / "ph")
    for xml in (folder / "humanoids").glob("*.xml"):
        xml.write_text(xml.read_text().replace("<geom ", '<geom condim="1" '))
    ph = tmp_path / "ph.h5"
    convert_skillmimic_parahome(folder, ph, options=ConvertOptions(hull_cache_dir=tmp_path / "c", show_progress=False))
    with open_dataset(ph) as ds:
        sid = ds.sequence_ids[0]
        new, old = build_scene(ds, sid), build_scene(ds, sid, scene_config_from_dict({"timestep": 1 / 120}))
    m = new.model
    colliding = (m.geom_contype | m.geom_conaffinity) > 0
    hands = m.geom_condim == 4
    assert colliding.sum() > 10 and hands.sum() > 10 and (m.geom_condim[colliding & ~hands] == 3).all()
    assert m.geom_condim[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, "floor")] == 3
    humanoid = np.isin(old.model.geom_bodyid, old.body_ids)
    assert (old.model.geom_condim[humanoid] == 1).all()  # the source's, as before


def test_humanoid_keeps_its_mjcf_densities_unless_one_is_given(tmp_path: Path) -> None:
    """PHC and SkillMimic weigh capsules by body part; the scene keeps those masses (runs recorded before: 1000)."""
    folder = write_parahome_folder(tmp_path / "ph")
    for xml in (folder / "humanoids").glob("*.xml"):
        text = xml.read_text()
        xml.write_text(text.replace('<geom type="sphere"', '<geom density="4629.63" type="sphere"', 1))
    ph = tmp_path / "ph.h5"
    convert_skillmimic_parahome(folder, ph, options=ConvertOptions(hull_cache_dir=tmp_path / "c", show_progress=False))
    with open_dataset(ph) as ds:
        sid = ds.sequence_ids[0]
        source = mujoco.MjModel.from_xml_string(ds.humanoid(ds.sequence(sid).humanoid_id).mjcf)
        scenes = {
            "default": build_scene(ds, sid),
            "legacy": build_scene(ds, sid, scene_config_from_dict({"timestep": 1 / 120})),
            "uniform": build_scene(ds, sid, SceneConfig(density=1000.0)),
        }
    mass = {k: float(sc.model.body_mass[sc.body_ids].sum()) for k, sc in scenes.items()}
    assert mass["default"] == pytest.approx(float(source.body_mass[1:].sum()), rel=1e-6)
    assert mass["legacy"] == pytest.approx(mass["uniform"]) and mass["default"] > mass["uniform"] + 1.0


def test_parahome_scene_has_fixed_supports(synth_files: tuple[Path, Path]) -> None:
    with open_dataset(synth_files[1]) as ds:
        sc = build_scene(ds, "s1_move_box")
    groups = gain_groups(sc.skeleton, sc.humanoid.roles)
    names = sc.skeleton.body_names
    assert {names[b] for b in groups["toes"]} == {"jLeftBallFoot", "jRightBallFoot"}
    assert "jL5S1" in {names[b] for b in groups["torso"]} and "jT1C7" in {names[b] for b in groups["arms"]}
    fr = finger_ranges(sc.skeleton, sc.humanoid.roles)
    assert len(fr) == 38
    static = [o for o in sc.objects if not o.dynamic]
    assert static and all(sc.model.body_jntnum[o.body_id] == 0 for o in static)


def _replay(ds, sid: str, cfg: SceneConfig) -> dict:
    sc = build_scene(ds, sid, cfg)
    m, d = sc.model, mujoco.MjData(sc.model)
    s = ds.sequence(sid).load()
    d.qpos[0:3], d.qpos[3:7] = s.root_pos[0], s.root_quat[0]
    d.qpos[sc.hinge_qposadr.ravel()] = s.joint_angles[0].ravel()
    for k, o in enumerate(sc.objects):
        if o.dynamic:
            d.qpos[o.qposadr : o.qposadr + 3], d.qpos[o.qposadr + 3 : o.qposadr + 7] = (
                s.object_pos[0, k],
                s.object_quat[0, k],
            )
    mujoco.mj_forward(m, d)
    maxv = 0.0
    for t in range(1, s.num_frames):
        d.ctrl[sc.actuator_ids.ravel()] = np.clip(s.joint_angles[t].ravel(), sc.ctrl_range[:, 0], sc.ctrl_range[:, 1])
        for _ in range(cfg.substeps):
            mujoco.mj_step(m, d)
        assert np.isfinite(d.qpos).all() and np.isfinite(d.qvel).all(), (sid, t)
        maxv = max(maxv, float(np.abs(d.qvel).max()))
    return {"maxv": maxv, "warnings": sum(int(w.number) for w in d.warning)}


@pytest.mark.shared_data
def test_reference_replay_through_pd_is_stable_on_every_shared_sequence(omomo_h5: Path, parahome_h5: Path) -> None:
    """The chosen timestep (1/120 s, 4 substeps, implicitfast) replays every shared reference through the PD
    controller with no NaN, no solver warning and bounded velocities (the humanoid may fall: balance is the
    policy's job)."""
    cfg = SceneConfig()
    for f in (omomo_h5, parahome_h5):
        with open_dataset(f) as ds:
            for sid in ds.sequence_ids:
                r = _replay(ds, sid, cfg)
                assert r["warnings"] == 0 and r["maxv"] < 100.0, (sid, r)


def test_scene_cli_exports_loadable_mjcf(synth_files: tuple[Path, Path], tmp_path: Path) -> None:
    out = tmp_path / "scene.xml"
    r = CliRunner().invoke(app, ["scene", str(synth_files[0]), "sub1_box_000", "-o", str(out)])
    assert r.exit_code == 0, r.output
    m = mujoco.MjModel.from_xml_path(str(out))
    assert m.nu == 153 and m.numeric_data[0] == 4
    r = CliRunner().invoke(app, ["scene", str(synth_files[0]), "nope", "-o", str(out)])
    assert r.exit_code == 1 and "nope" in r.stderr


def test_object_density_scales_mass_and_inertia_and_bad_values_are_refused(synth_files: tuple[Path, Path]) -> None:
    from wristmimic.errors import InputError

    with open_dataset(synth_files[0]) as ds:
        base = build_scene(ds, "sub1_box_000")
        light = build_scene(ds, "sub1_box_000", SceneConfig(object_density=200.0))
        (o,) = base.dynamic_objects
        rec_density = ds.object(o.id).density
        ratio = 200.0 / rec_density
        assert light.model.body_mass[o.body_id] == pytest.approx(base.model.body_mass[o.body_id] * ratio)
        np.testing.assert_allclose(light.model.body_inertia[o.body_id], base.model.body_inertia[o.body_id] * ratio)
        humanoid = [b for b in range(base.model.nbody) if b != o.body_id]
        np.testing.assert_array_equal(light.model.body_mass[humanoid], base.model.body_mass[humanoid])
        for bad in (0.0, -5.0, float("nan")):
            with pytest.raises(InputError, match="object_density"):
                build_scene(ds, "sub1_box_000", SceneConfig(object_density=bad))


def test_refsafe_false_keeps_the_contact_time_constant_at_a_long_timestep(synth_files: tuple[Path, Path]) -> None:
    """MuJoCo's refsafe raises a contact's time constant to 2 x timestep: at 1/60 s the default 0.02 s becomes
    0.033 s (stiffness K ~ 1 / timeconst^2, so 2.78x softer); ``refsafe=False`` keeps 0.02 s. At 1/120 s nothing
    binds on this scene, so both settings give the same contacts."""

    def stiffness(cfg: SceneConfig) -> np.ndarray:
        sc = build_scene(ds, "sub1_box_000", cfg)
        m, d = sc.model, mujoco.MjData(sc.model)
        adr = m.jnt_qposadr[m.body_jntadr[sc.objects[0].body_id]]
        d.qpos[adr : adr + 3] = [5.0, 5.0, 0.0]  # the box half into the floor, far from the humanoid
        mujoco.mj_forward(m, d)
        rows = np.isin(d.efc_type, [mujoco.mjtConstraint.mjCNSTR_CONTACT_PYRAMIDAL])
        assert rows.any(), "no contact made"
        return d.efc_KBIP[rows, 0]

    with open_dataset(synth_files[0]) as ds:
        assert not build_scene(ds, "sub1_box_000").model.opt.disableflags & mujoco.mjtDisableBit.mjDSBL_REFSAFE
        long = {"timestep": 1 / 60, "substeps": 2}
        safe, kept = stiffness(SceneConfig(**long)), stiffness(SceneConfig(**long, refsafe=False))
        assert kept == pytest.approx(safe * (2 / 60 / 0.02) ** 2, rel=1e-6)
        assert stiffness(SceneConfig(refsafe=False)) == pytest.approx(stiffness(SceneConfig()), rel=1e-9)
        from wristmimic.errors import InputError

        for bad in (None, "no", 0):  # a recorded or --set value that is not a boolean is refused, not read as one
            with pytest.raises(InputError, match="scene_config.refsafe"):
                build_scene(ds, "sub1_box_000", scene_config_from_dict({"refsafe": bad}))
