"""Hand embodiments (issue #10): every built-in hand and a user MJCF hand swapped onto the synthetic SMPL-X
humanoid (always) and the shared OMOMO / ParaHome humanoids (skipped without shared data): the file validates,
the scene compiles with the hand's own ranges and finger gains, roles are consistent, the environment steps,
and the wrist pose under reference replay is unchanged. A misaligned palm fails that check; the left hand of a
user file is the mirror image of its right hand; bad inputs give one-line errors."""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

import mujoco
import numpy as np
import pytest
import torch
from typer.testing import CliRunner

from wristmimic.cli.main import app
from wristmimic.env.config import variant_config
from wristmimic.env.vec_env import WristMimicEnv
from wristmimic.errors import InputError
from wristmimic.format import open_dataset
from wristmimic.format.validate import validate
from wristmimic.humanoid.hands import BUILTIN_HANDS, swap_hands, wrist_replay_deviation
from wristmimic.humanoid.skeleton import load_skeleton
from wristmimic.scene import build_scene

TOL = 1e-6
USER_HAND = """<mujoco model="test_hand">
  <compiler angle="degree"/>
  <worldbody>
    <body name="palm" pos="0.3 0.2 1.0" euler="0 30 0">
      <freejoint/>
      <geom type="box" size="0.04 0.035 0.01" pos="0 -0.04 0"/>
      <geom type="sphere" size="0.01" pos="0 -0.02 0.03" contype="0" conaffinity="0"/>
      <body name="f1" pos="0.02 -0.08 0" euler="0 0 10">
        <joint name="f1_flex" type="hinge" axis="1 0 0" range="-10 80"/>
        <joint name="f1_spread" type="hinge" axis="0 0 -1" range="-15 20"/>
        <geom type="capsule" fromto="0 0 0 0.005 -0.04 -0.002" size="0.008"/>
        <body name="f1b" pos="0.005 -0.045 -0.002">
          <joint name="f1b_flex" type="hinge" axis="-1 0 0"/>
          <geom type="capsule" fromto="0 0 0 0 -0.03 0" size="0.007"/>
        </body>
      </body>
      <body name="thumb" pos="0.04 -0.03 -0.01" quat="0.9 0.1 0.3 0.2">
        <joint name="thumb_y" type="hinge" axis="0 1 0" range="-30 45"/>
        <geom type="cylinder" fromto="0 0 0 0.03 -0.02 0" size="0.009"/>
        <body name="thumb_tip" pos="0.03 -0.02 0">
          <geom type="ellipsoid" size="0.01 0.012 0.008" euler="10 20 30"/>
        </body>
      </body>
    </body>
  </worldbody>
</mujoco>
"""
FINGERS_PER_HAND = {"smplx-intermimic": 15, "smplx-free": 15, "parahome-box": 19, "user": 4}


@pytest.fixture(scope="module")
def synth_h5(tmp_path_factory: pytest.TempPathFactory) -> Path:
    from wristmimic.synth import generate

    return generate(tmp_path_factory.mktemp("hands") / "synth.h5", variants=("default",))


@pytest.fixture(scope="module")
def user_hand(tmp_path_factory: pytest.TempPathFactory) -> Path:
    p = tmp_path_factory.mktemp("hand") / "user_hand.xml"
    p.write_text(USER_HAND)
    return p


def _hand_arg(hand: str, user_hand: Path) -> str:
    return str(user_hand) if hand == "user" else hand


def check_roles(path: Path, original: Path, sid: str, fingers_per_hand: int) -> None:
    """Roles of the swapped humanoid are consistent and its non-finger bodies are the original's."""
    with open_dataset(path) as ds, open_dataset(original) as ds0:
        h = ds.humanoid(ds.sequence(sid).humanoid_id)
        h0 = ds0.humanoid(ds0.sequence(sid).humanoid_id)
    skel = load_skeleton(h.mjcf)
    r = {k: set(v.tolist()) for k, v in h.roles.items()}
    assert r["left_fingers"].isdisjoint(r["right_fingers"])
    assert r["fingers"] == r["left_fingers"] | r["right_fingers"]
    assert len(r["left_fingers"]) == len(r["right_fingers"]) == fingers_per_hand
    for side, w in (("left", 0), ("right", 1)):
        wrist = int(h.roles["wrists"][w])
        assert r[f"{side}_hand"] == set(skel.subtree(wrist)) == r[f"{side}_fingers"] | {wrist}
        assert all(not skel.children(b) for b in r[f"{side}_fingertips"])
        assert r[f"{side}_fingertips"] == {b for b in r[f"{side}_fingers"] if not skel.children(b)}
    assert r["fingers"].isdisjoint(r["key_bodies"]) and 0 not in r["key_bodies"]
    assert r["contact_bodies"] == r["key_bodies"] | r["left_fingertips"] | r["right_fingertips"]
    assert r["non_finger"] == set(range(skel.num_bodies)) - r["fingers"]
    # the hand extends beyond the wrist along the forearm (T-pose convention kept)
    d = mujoco.MjData(skel.model)
    d.qpos[3] = 1
    mujoco.mj_kinematics(skel.model, d)
    for side, w in (("left", 0), ("right", 1)):
        wb = int(h.roles["wrists"][w]) + 1
        arm = d.xpos[wb] - d.xpos[skel.model.body_parentid[wb]]
        tips = (d.xpos[h.roles[f"{side}_fingertips"] + 1] - d.xpos[wb]).mean(axis=0)
        assert tips @ arm / np.linalg.norm(tips) / np.linalg.norm(arm) > 0.8
    names = lambda hh, role: [hh.body_names[b] for b in hh.roles[role]]  # noqa: E731
    for role in ("key_bodies", "wrists", "left_arm", "right_arm", "feet", "head", "root"):
        assert names(h, role) == names(h0, role), role


def check_env_steps(path: Path, sid: str) -> None:
    env = WristMimicEnv.from_file(path, sid, num_worlds=4, nthread=1, max_frames=12)
    try:
        obs, _ = env.reset()
        assert torch.isfinite(obs).all()
        for _ in range(3):
            obs, rew, term, trunc, _ = env.step(torch.zeros(4, env.action_size))
            assert torch.isfinite(obs).all() and torch.isfinite(rew).all()
    finally:
        env.close()


def check_wrist_replay(path: Path, original: Path, sid: str) -> tuple[float, float]:
    with open_dataset(path) as ds, open_dataset(original) as ds0:
        a, b = ds0.sequence(sid), ds.sequence(sid)
        h0, h = ds0.humanoid(a.humanoid_id), ds.humanoid(b.humanoid_id)
        dev = wrist_replay_deviation(
            load_skeleton(h0.mjcf), a.load(), load_skeleton(h.mjcf), b.load(), (h0.roles["wrists"], h.roles["wrists"])
        )
    return dev


def same_scene_model(a: Path, b: Path, sid: str) -> None:
    """Two files' scenes have the same bodies, masses, inertias, joint ranges and gains."""
    with open_dataset(a) as da, open_dataset(b) as db:
        sa, sb = build_scene(da, sid), build_scene(db, sid)
    assert sa.skeleton.body_names == sb.skeleton.body_names
    assert np.allclose(sa.model.body_mass, sb.model.body_mass, rtol=0, atol=1e-12)
    assert np.allclose(sa.model.body_inertia, sb.model.body_inertia, rtol=0, atol=1e-12)
    assert np.array_equal(sa.model.jnt_range, sb.model.jnt_range) and np.array_equal(sa.gains, sb.gains)


def finger_scene_ranges(path: Path, sid: str) -> dict[str, np.ndarray]:
    with open_dataset(path) as ds:
        sc = build_scene(ds, sid)
    names, m = sc.skeleton.body_names, sc.model
    fingers = sc.humanoid.roles["fingers"]
    out = {}
    for j, b in enumerate(sc.skeleton.joint_bodies):
        if b in fingers:
            out[names[b]] = m.jnt_range[m.actuator_trnid[sc.actuator_ids[j], 0]]
            assert np.allclose(sc.gains[3 * j : 3 * j + 3], [100, 10])  # finger gains
    return out


# ------------------------------------------------------------------------------------------- synthetic


@pytest.mark.parametrize("hand", [*BUILTIN_HANDS, "user"])
def test_swapped_synthetic_humanoid(hand: str, synth_h5: Path, user_hand: Path, tmp_path: Path) -> None:
    out = tmp_path / f"{hand}.h5"
    res = swap_hands(synth_h5, "synth_default", _hand_arg(hand, user_hand), out)
    assert validate(out) == []
    assert res.num_fingers == (30, 2 * FINGERS_PER_HAND[hand])
    check_roles(out, synth_h5, "synth_default", FINGERS_PER_HAND[hand])
    pos, rot = check_wrist_replay(out, synth_h5, "synth_default")
    assert pos < TOL and rot < TOL and res.wrist_deviation[0] < TOL
    ranges = finger_scene_ranges(out, "synth_default")
    if hand == "smplx-free":
        assert all(np.allclose(r, [[-np.pi, np.pi]] * 3) for r in ranges.values())
    if hand == "smplx-intermimic":  # the humanoid's own hand with InterMimic's ranges: the scene is unchanged
        same_scene_model(synth_h5, out, "synth_default")
    if hand == "user":  # its own ranges, x/z mirrored on the left, missing axes locked
        assert np.allclose(np.rad2deg(ranges["R_Wrist_f1"]), [[-10, 80], [0, 0], [-20, 15]], atol=1e-4)
        assert np.allclose(np.rad2deg(ranges["L_Wrist_f1"]), [[-80, 10], [0, 0], [-15, 20]], atol=1e-4)
        assert np.allclose(ranges["R_Wrist_f1b"], [[-np.pi, np.pi], [0, 0], [0, 0]], atol=1e-5)
        assert np.allclose(ranges["R_Wrist_thumb_tip"], 0.0, atol=1e-5)
    with open_dataset(out) as ds:
        h = ds.humanoid(ds.sequence("synth_default").humanoid_id)
        assert h.hand == (hand if hand != "user" else "user_hand") and h.hand_source
        s = ds.sequence("synth_default").load()
        lab, flags = s.contact_labels, s.hand_contact
        for side in (0, 1):
            f = h.roles["right_fingers" if side else "left_fingers"]
            assert np.all((lab[:, f] == 1) == flags[:, side, None])
    check_env_steps(out, "synth_default")


def test_misaligned_palm_fails_the_wrist_check(synth_h5: Path, tmp_path: Path) -> None:
    out = tmp_path / "ok.h5"
    swap_hands(synth_h5, "synth_default", "parahome-box", out)
    with open_dataset(out) as ds, open_dataset(synth_h5) as ds0:
        seq, seq0 = ds.sequence("synth_default").load(), ds0.sequence("synth_default").load()
        h, h0 = ds.humanoid(seq.humanoid_id), ds0.humanoid(seq0.humanoid_id)
    root = ET.fromstring(h.mjcf)
    wrist = next(b for b in root.iter("body") if b.get("name") == "R_Wrist")
    wrist.set("pos", " ".join(str(float(x) + 0.01 * (k == 0)) for k, x in enumerate(wrist.get("pos").split())))
    wrist.set("quat", "0.9961947 0 0.0871557 0")  # the palm 1 cm and 10 degrees off
    bad = load_skeleton(ET.tostring(root, encoding="unicode"))
    pos, rot = wrist_replay_deviation(load_skeleton(h0.mjcf), seq0, bad, seq, (h0.roles["wrists"], h.roles["wrists"]))
    assert pos > 0.005 and rot > 0.1


def test_left_user_hand_is_the_mirror_of_the_right(synth_h5: Path, user_hand: Path, tmp_path: Path) -> None:
    out = tmp_path / "user.h5"
    swap_hands(synth_h5, "synth_default", str(user_hand), out)
    with open_dataset(out) as ds:
        h = ds.humanoid(ds.sequence("synth_default").humanoid_id)
    skel = load_skeleton(h.mjcf)
    m, d = skel.model, mujoco.MjData(skel.model)
    rng = np.random.default_rng(0)
    M = np.diag([1.0, -1.0, 1.0])
    for trial in range(3):
        d.qpos[:] = 0
        d.qpos[3] = 1
        for b in h.roles["right_fingers"]:
            name = skel.body_names[b]
            left = skel.index(name.replace("R_Wrist_", "L_Wrist_"))
            a = rng.uniform(-0.5, 0.5, 3) if trial else np.zeros(3)
            j, jl = list(skel.joint_bodies).index(b), list(skel.joint_bodies).index(left)
            d.qpos[skel.hinge_qposadr[j]] = a
            d.qpos[skel.hinge_qposadr[jl]] = a * [-1, 1, -1]
        mujoco.mj_kinematics(m, d)
        wl, wr = (int(w) + 1 for w in h.roles["wrists"])
        Rl, Rr = d.xmat[wl].reshape(3, 3), d.xmat[wr].reshape(3, 3)
        assert np.allclose(Rl, M @ Rr @ M)  # the wrists themselves are mirror images in the rest pose
        geoms_r = [g for g in range(m.ngeom) if m.geom_bodyid[g] in {int(b) + 1 for b in h.roles["right_hand"]}]
        geoms_l = [g for g in range(m.ngeom) if m.geom_bodyid[g] in {int(b) + 1 for b in h.roles["left_hand"]}]
        assert len(geoms_r) == len(geoms_l) == 5  # visual-only geom dropped
        for gr, gl in zip(geoms_r, geoms_l, strict=True):
            pr = Rr.T @ (d.geom_xpos[gr] - d.xpos[wr])  # in the wrist frame
            pl = Rl.T @ (d.geom_xpos[gl] - d.xpos[wl])
            assert np.allclose(pl, M @ pr, atol=1e-9)
            Gr = Rr.T @ d.geom_xmat[gr].reshape(3, 3)
            Gl = Rl.T @ d.geom_xmat[gl].reshape(3, 3)
            assert np.allclose(Gl, M @ Gr @ M, atol=1e-9)
            assert np.allclose(m.geom_size[gl], m.geom_size[gr])


def test_finger_target_variants_are_refused_on_a_swapped_hand(synth_h5: Path, tmp_path: Path) -> None:
    out = tmp_path / "free.h5"
    swap_hands(synth_h5, "synth_default", "smplx-free", out)
    with pytest.raises(InputError, match="finger pose targets"):
        WristMimicEnv.from_file(out, "synth_default", num_worlds=2, config=variant_config("intermimic"), max_frames=8)


def test_bad_inputs_give_one_line_errors(synth_h5: Path, user_hand: Path, tmp_path: Path) -> None:
    out = tmp_path / "o.h5"
    with pytest.raises(InputError, match="unknown hand 'robotiq'"):
        swap_hands(synth_h5, "synth_default", "robotiq", out)
    with pytest.raises(InputError, match=r"user_hand.xml: body wrist: palm body not found"):
        swap_hands(synth_h5, "synth_default", str(user_hand), out, palm="wrist")
    with pytest.raises(InputError, match=r"synth.h5: sequences/nope: no such sequence"):
        swap_hands(synth_h5, "nope", "smplx-free", out)
    with pytest.raises(InputError, match="--ranges"):
        swap_hands(synth_h5, "synth_default", "smplx-free", out, ranges="loose")
    mesh = tmp_path / "mesh_hand.xml"
    text = USER_HAND.replace('type="cylinder" fromto="0 0 0 0.03 -0.02 0" size="0.009"', 'type="mesh" mesh="m"')
    asset = '<asset><mesh name="m" vertex="0 0 0 0.01 0 0 0 0.01 0 0 0 0.01"/></asset>\n  <worldbody>'
    mesh.write_text(text.replace("<worldbody>", asset, 1))
    with pytest.raises(InputError, match="mesh_hand.xml: body thumb: geom type mjGEOM_MESH not supported"):
        swap_hands(synth_h5, "synth_default", str(mesh), out)
    ball = tmp_path / "ball_hand.xml"
    ball.write_text(USER_HAND.replace('name="thumb_y" type="hinge" axis="0 1 0" range="-30 45"', 'type="ball"'))
    with pytest.raises(InputError, match="non-hinge joint"):
        swap_hands(synth_h5, "synth_default", str(ball), out)
    assert not out.exists()
    r = CliRunner().invoke(
        app, ["humanoid", "swap-hands", str(synth_h5), "synth_default", "--hand", "robotiq", "-o", str(out)]
    )
    assert r.exit_code == 1 and r.output.strip().count("\n") == 0 and "unknown hand" in r.output
    assert not out.exists()


def test_cli_swap_hands_and_list(synth_h5: Path, tmp_path: Path) -> None:
    out = tmp_path / "box.h5"
    r = CliRunner().invoke(
        app, ["humanoid", "swap-hands", str(synth_h5), "synth_default", "--hand", "parahome-box", "-o", str(out)]
    )
    assert r.exit_code == 0, r.output
    assert "52 -> 60 bodies" in r.output and "wrist" in r.output and validate(out) == []
    r = CliRunner().invoke(app, ["humanoid", "hands"])
    assert r.exit_code == 0 and all(n in r.output for n in BUILTIN_HANDS)


# ------------------------------------------------------------------------------------------- real data


@pytest.mark.slow
@pytest.mark.parametrize("which", ["omomo", "parahome"])
def test_swapped_real_humanoids(which: str, request: pytest.FixtureRequest, user_hand: Path, tmp_path: Path) -> None:
    src = request.getfixturevalue(f"{which}_h5")
    sid = "sub2_largetable_000" if which == "omomo" else "s110_move_kettle"
    own = {"omomo": ("smplx-intermimic", 15), "parahome": ("parahome-box", 19)}[which]
    with open_dataset(src) as ds:
        n0 = len(ds.humanoid(ds.sequence(sid).humanoid_id).roles["fingers"])
    for hand in [*BUILTIN_HANDS, "user"]:
        out = tmp_path / f"{which}-{hand}.h5"
        res = swap_hands(src, sid, _hand_arg(hand, user_hand), out)
        assert validate(out) == [], hand
        assert res.num_fingers == (n0, 2 * FINGERS_PER_HAND[hand])
        check_roles(out, src, sid, FINGERS_PER_HAND[hand])
        pos, rot = check_wrist_replay(out, src, sid)
        assert pos < TOL and rot < TOL, hand
        ranges = finger_scene_ranges(out, sid)
        if hand == own[0]:  # the humanoid's own hand with the ranges the scene gave it: unchanged
            same_scene_model(src, out, sid)
        if hand == "smplx-free":
            assert all(np.allclose(r, [[-np.pi, np.pi]] * 3) for r in ranges.values())
    check_env_steps(tmp_path / f"{which}-smplx-free.h5", sid)


def test_swapping_twice_uses_the_hand_the_humanoid_has_now(synth_h5: Path, tmp_path: Path) -> None:
    """parahome-box on an SMPL-X humanoid, then back to smplx-intermimic: the SMPL-X hand is no longer the
    humanoid's own, so it comes from the synthetic hand; the wrist reference survives both swaps."""
    box, back = tmp_path / "box.h5", tmp_path / "back.h5"
    swap_hands(synth_h5, "synth_default", "parahome-box", box)
    r = swap_hands(box, "synth_default", "smplx-intermimic", back)
    assert r.hand_source.startswith("wristmimic.synth SMPL-X hand") and r.num_fingers == (38, 30)
    assert r.humanoid_id == "synth_h170+parahome-box+smplx-intermimic" and validate(back) == []
    pos, rot = check_wrist_replay(back, synth_h5, "synth_default")
    assert pos < TOL and rot < TOL
    again = swap_hands(back, "synth_default", "parahome-box", tmp_path / "again.h5")
    assert again.hand_source.startswith("ParaHome box hand regenerated")
