"""scripts/body_only.py: the body-only copy keeps the humanoid's reference, parks the objects and clears contacts."""

from __future__ import annotations

import runpy
from pathlib import Path

import h5py
import numpy as np
import pytest
import torch

from wristmimic.env.config import variant_config
from wristmimic.env.vec_env import WristMimicEnv
from wristmimic.errors import InputError
from wristmimic.synth.generate import generate

SID = "synth_default"
SCRIPT = runpy.run_path(str(Path(__file__).parents[1] / "scripts" / "body_only.py"))


@pytest.fixture(scope="module")
def synth(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return generate(tmp_path_factory.mktemp("body_only") / "synth.h5", seed=0, variants=("default",))


def test_copy_parks_objects_and_clears_contacts(synth: Path, tmp_path: Path) -> None:
    out = tmp_path / "body.h5"
    SCRIPT["body_only_copy"](synth, SID, out, park=15.0)
    with h5py.File(synth, "r") as a, h5py.File(out, "r") as b:
        sa, sb = a[f"sequences/{SID}"], b[f"sequences/{SID}"]
        for key in ("root_pos", "root_quat", "joint_angles", "body_pos"):
            np.testing.assert_array_equal(sa[key][:], sb[key][:])
        pos = sb["object_pos"][:]
        np.testing.assert_allclose(pos, np.broadcast_to(sa["object_pos"][:1] + [15.0, 0.0, 0.0], pos.shape), atol=1e-5)
        assert (sb["object_quat"][:] == sb["object_quat"][:1]).all()
        assert sa["contacts/hand"][:].any() and not sb["contacts/hand"][:].any()
        assert (sb["contacts/labels"][:] <= 0).all() and (sb["contacts/window"][:] == -1).all()
        assert "body_only" in b.attrs
    env = WristMimicEnv.from_file(out, SID, 2, variant_config("wristmimic"), nthread=1, seed=0)
    env.reset(start_frames=torch.tensor([0, 10]))
    _, _, term, _, _ = env.step(torch.zeros(2, env.action_size))
    assert not term.any()
    assert not env.ref.hand.any()


def test_observations_of_parked_objects_carry_no_denormals(synth: Path, tmp_path: Path) -> None:
    """The interaction graph of an object parked 20 m away: exp(-5 d) lies below float32's normal range, and a
    denormal observation slows every matmul of the policy ~25x; such features are exactly 0."""
    out = tmp_path / "body.h5"
    SCRIPT["body_only_copy"](synth, SID, out)  # default: 20 m
    env = WristMimicEnv.from_file(out, SID, 2, variant_config("wristmimic"), nthread=1, seed=0)
    env.reset(start_frames=torch.tensor([0, 10]))
    obs, *_ = env.step(torch.zeros(2, env.action_size))
    ig = obs[:, env.obs_layout["state"]][:, -3 * env.scene.skeleton.num_bodies :]
    assert (ig == 0).all()
    assert not ((obs != 0) & (obs.abs() < torch.finfo(torch.float32).tiny)).any()


def test_bad_input_leaves_nothing(synth: Path, tmp_path: Path) -> None:
    out = tmp_path / "body.h5"
    with pytest.raises(InputError, match="sequences/nope"):
        SCRIPT["body_only_copy"](synth, "nope", out)
    with pytest.raises(InputError, match="--park"):
        SCRIPT["body_only_copy"](synth, SID, out, park=float("nan"))
    assert list(tmp_path.iterdir()) == []
    assert SCRIPT["main"]([str(synth), "--scene", "nope", "-o", str(out)]) == 2


def test_a_body_only_stage_warm_starts_the_scene_with_its_object(synth: Path, tmp_path: Path) -> None:
    """The staged curriculum: train on the body-only copy, then ``init_from`` it on the scene with its object. The
    warm start's observation statistics come from the scene's own observations, not the parked object's."""
    from dataclasses import replace

    from wristmimic.rl import TrainSpec, preset, start_run
    from wristmimic.rl.checkpoint import load_checkpoint

    body = tmp_path / "body.h5"
    SCRIPT["body_only_copy"](synth, SID, body)
    tiny = dict(num_envs=4, horizon=8, minibatch_size=16, actor_hidden=(32,), critic_hidden=(32,), max_frames=64)
    spec = TrainSpec(body, SID, "wristmimic", 0, "cpu", preset("cpu", **tiny))
    start_run(spec, tmp_path / "stage1", nthread=1, progress=False)
    start_run(
        replace(spec, dataset=synth, init_from=tmp_path / "stage1"), tmp_path / "stage2", nthread=1, progress=False
    )
    parked = load_checkpoint(tmp_path / "stage1")["policy"]["normalizer.mean"]
    scene = load_checkpoint(tmp_path / "stage2")["policy"]["normalizer.mean"]
    assert parked.abs().max() > 10.0 and scene.abs().max() < 5.0  # the object 20 m away in stage 1, near in 2


def test_keep_window_keeps_the_grasp_phase_and_its_wrist_reset_but_asks_for_no_contact(
    synth: Path, tmp_path: Path
) -> None:
    out = tmp_path / "body.h5"
    SCRIPT["body_only_copy"](synth, SID, out, keep_window=True)
    with h5py.File(synth, "r") as a, h5py.File(out, "r") as b:
        ca, cb = a[f"sequences/{SID}/contacts"], b[f"sequences/{SID}/contacts"]
        first = ca["first_contact_frame"][:]
        assert (first >= 0).any() and (cb["first_contact_frame"][:] == first).all()
        assert (cb["window"][:] == ca["window"][:]).all() and (cb["labels"][:] <= 0).all()
        hand = cb["hand"][:]
        assert hand.sum() == (first >= 0).sum() and all(hand[first[h], h] for h in range(2) if first[h] >= 0)
    env = WristMimicEnv.from_file(out, SID, 1, variant_config("wristmimic"), nthread=1, seed=0)
    full = WristMimicEnv.from_file(synth, SID, 1, variant_config("wristmimic"), nthread=1, seed=0)
    assert env.ref.t_c == full.ref.t_c >= 0 and torch.equal(env.ref.grasp_hands, full.ref.grasp_hands)
    full.close()
    # zero actions through the grasp phase: nothing ends on contact_lost; a wrist pushed away ends on `wrist`
    env.reset(start_frames=torch.tensor([env.ref.t_c - 1]))
    reasons = set()
    for _ in range(14):
        _, _, term, trunc, info = env.step(torch.zeros(1, env.action_size))
        reasons |= {env.reason_name(int(r)) for r in info["termination_reason"][term]}
        if term.any() or trunc.any():
            break
    assert "contact_lost" not in reasons
    # the same push of every hinge at the first contact frame: the grasp phase's 7 cm / 0.2 rad wrist reset ends
    # the episode in the copy with its window, and nothing ends it in the plain body-only copy
    plain = tmp_path / "plain.h5"
    SCRIPT["body_only_copy"](synth, SID, plain)
    for path, want in ((out, {"wrist"}), (plain, set())):
        e = WristMimicEnv.from_file(path, SID, 1, variant_config("wristmimic"), nthread=1, seed=0)
        e.reset(start_frames=torch.tensor([env.ref.t_c]))
        got = set()
        for _ in range(12):
            _, _, term, _, info = e.step(torch.full((1, e.action_size), 0.3))
            got |= {e.reason_name(int(r)) for r in info["termination_reason"][term]}
            if term.any():
                break
        assert got == want
        e.close()
    env.close()
