"""``wristmimic export``: rollouts of a tiny trained run written as a canonical file that validates, reopens,
replays, trains; seeded trials as evaluate runs them, an evaluation's rows by seed, and bad input refused."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import torch
from typer.testing import CliRunner

from wristmimic.cli.main import app
from wristmimic.env.config import EnvConfig
from wristmimic.env.vec_env import WristMimicEnv
from wristmimic.evaluate import export as export_mod
from wristmimic.evaluate import load_eval_policy
from wristmimic.evaluate.export import export_rollouts, parse_rows, replay_sequence
from wristmimic.evaluate.noise import trial_seeds
from wristmimic.format import schema
from wristmimic.format.reader import open_dataset
from wristmimic.format.validate import validate
from wristmimic.safe_io import sha256_file

from conftest import temporaries
from synthetic import converted_intermimic

SID = "sub1_box_000"
REF_FRAMES = 20
REPLAY_BODY_M, REPLAY_BODY_MEAN_M = 0.10, 0.02
"""Bounds on the joint-angle PD replay's body position error (max, mean over bodies and frames). Measured on this
module's run (8 trials, each 5 frames: the tiny policy's wrist reset ends them): max 0.043-0.059 m, mean 0.010-0.012
m. The replay starts with finite-difference velocities and tracks angles, not the policy's targets, so it drifts:
on the synth_default run's 140-frame mean trial, mean 0.049 m and max 0.43 m at the end."""
REPLAY_OBJECT_M, REPLAY_OBJECT_MEAN_M = 0.06, 0.03
"""The same for the object: measured max 0.029-0.031 m, mean 0.015 m."""


@pytest.fixture(scope="module")
def run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A tiny trained run (a few PPO iterations) on a 30-frame synthetic sequence, 20 reference frames."""
    from wristmimic.rl import TrainSpec, preset, start_run

    tmp = tmp_path_factory.mktemp("export")
    dataset = converted_intermimic(tmp, T=30)
    tiny = dict(num_envs=4, horizon=8, minibatch_size=16, epochs=1, actor_hidden=(32,), critic_hidden=(32,))
    spec = TrainSpec(dataset, SID, "wristmimic", 0, "cpu", preset("cpu", **tiny, max_frames=64), ref_frames=REF_FRAMES)
    return start_run(spec, tmp / "run", nthread=1, progress=False).run_dir


@pytest.fixture(scope="module")
def lenient(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A protocol whose success needs only completion (any object error, any contact)."""
    p = tmp_path_factory.mktemp("proto") / "lenient.toml"
    p.write_text(
        'name = "lenient"\ntrials = 8\nstart_frame = 0\nnoise = "actions"\nbase_seed = 3\n'
        "[success]\nmax_object_position_error_m = 10.0\nmin_contact_ratio = 0.0\n"
    )
    return p


def _export(*args: str) -> tuple[int, str]:
    r = CliRunner().invoke(app, ["export", *args, "--nthread", "1", "-q"])
    return r.exit_code, r.output


def test_default_export_is_a_valid_canonical_file_of_the_policy_mean(run: Path, tmp_path: Path) -> None:
    out = tmp_path / "mean.h5"
    code, text = _export(str(run), "-o", str(out))
    assert code == 0, text
    assert validate(out) == []
    policy = load_eval_policy(run)
    src_path = Path(policy.metadata["dataset"])
    with open_dataset(out) as ds, open_dataset(src_path) as src:
        assert ds.sequence_ids == [f"{SID}__sim_mean"]
        a = ds.attrs
        assert a["schema_version"] == schema.SCHEMA_VERSION == "1.2.0" and a["converter"] == "export"
        assert a["source_dataset"] == src.attrs["source_dataset"]
        s = ds.sequence(ds.sequence_ids[0])
        src_seq = src.sequence(SID)
        h, hs = ds.humanoid(s.humanoid_id), src.humanoid(src_seq.humanoid_id)
        assert s.humanoid_id == src_seq.humanoid_id and h.mjcf == hs.mjcf and h.body_names == hs.body_names
        assert s.object_ids == src_seq.object_ids
        for oid in s.object_ids:
            assert np.array_equal(ds.object(oid).hull_vertices, src.object(oid).hull_vertices)
        rec = s.load()
        T, B = rec.num_frames, len(h.body_names)
        assert 2 <= T <= REF_FRAMES
        assert rec.optional["sim/actions"].shape == rec.optional["sim/pd_targets"].shape == (T, 3 * (B - 1))
        assert rec.optional["sim/contact_force"].shape == (T, B, 3)
        assert np.array_equal(rec.root_pos, rec.body_pos[:, 0])  # the root body's position is the free joint's
        ref0 = src_seq.load(slice(0, 1))  # frame 0 is the reference's frame 0 (no perturbation for the mean)
        assert np.allclose(rec.joint_angles[0], ref0.joint_angles[0], atol=1e-6)
        assert np.allclose(rec.body_pos[0], ref0.body_pos[0], atol=1e-5)
        assert set(np.unique(rec.contact_labels)) <= {0, 1} and np.array_equal(
            rec.contact_geometric, rec.contact_labels
        )
        for k, side in enumerate(("left_hand", "right_hand")):  # per-hand contact from the simulated labels
            assert np.array_equal(rec.hand_contact[:, k], (rec.contact_labels[:, h.roles[side]] == 1).any(1))
        e = s.extra["export"]
        for key in ("run", "checkpoint_sha256", "dataset_sha256", "seed", "backend", "physics", "success",
                    "terminated", "termination_reason", "ended", "frames", "obj_pos_err_cm", "contact_ratio"):  # fmt: skip
            assert key in e, key
        assert e["checkpoint_sha256"] == sha256_file(run / "checkpoint.pt")
        assert e["dataset_sha256"] == sha256_file(src_path) and e["run"] == str(run.resolve())
        assert e["seed"] is None and e["mode"] == "mean" and e["backend"] == "cpu" and e["frames"] == T
        assert e["physics"]["substeps"] == 4 and T == e["frames_completed"] + 1
        assert e["ended"] == (f"terminated ({e['termination_reason']})" if e["terminated"] else "end of the reference")
        root = json.loads(a["export"])
        assert root["trials"] == 1 and root["sequences"] == 1 and root["checkpoint_sha256"] == e["checkpoint_sha256"]
    import h5py

    with h5py.File(out, "r") as f:  # repeated arrays are written once, as hard links (the same HDF5 object)
        g = f["sequences"][f"{SID}__sim_mean"]
        assert g["source_body_pos"] == g["body_pos"] and g["contacts/geometric"] == g["contacts/labels"]
        assert g["body_quat"] != g["body_pos"] and g["body_pos"].compression == "gzip"
        assert np.array_equal(g["source_body_pos"][()], g["body_pos"][()])


def test_round_trip_replays_the_recorded_poses(run: Path, tmp_path: Path) -> None:
    out = tmp_path / "rt.h5"
    assert _export(str(run), "-o", str(out), "--trials", "2", "--num-envs", "2")[0] == 0
    with open_dataset(out) as ds:
        sids = ds.sequence_ids
        recs = {sid: ds.sequence(sid).load() for sid in sids}
    policy = load_eval_policy(run)
    for sid in sids:
        # joint angles through the PD controller in the exported sequence's own scene
        err = replay_sequence(out, sid)
        assert err.body_pos_m < REPLAY_BODY_M and err.object_pos_m < REPLAY_OBJECT_M, (sid, err)
        assert err.body_pos_mean_m < REPLAY_BODY_MEAN_M and err.object_pos_mean_m < REPLAY_OBJECT_MEAN_M, (sid, err)
        # the recorded PD targets from the run's start state reproduce the recorded poses exactly
        r = recs[sid]
        env = WristMimicEnv.from_file(policy.metadata["dataset"], SID, 1, config=EnvConfig(), nthread=1,
                                      max_frames=REF_FRAMES)  # fmt: skip
        env.reset(start_frames=torch.zeros(1, dtype=torch.long))
        ctrl, worst = env._ctrl.clone(), 0.0
        for t in range(r.num_frames - 1):
            ctrl[0, env._act_cols] = torch.as_tensor(r.optional["sim/pd_targets"][t])
            env.backend.step(ctrl, env.scene.config.substeps)
            s = env.sim_state()
            worst = max(worst, float((s.body_pos[0] - torch.as_tensor(r.body_pos[t + 1])).abs().max()))
            worst = max(worst, float((s.obj_pos[0] - torch.as_tensor(r.object_pos[t + 1, :1])).abs().max()))
        env.close()
        assert worst == 0.0, (sid, worst)


class _ZeroMean:
    """A stand-in policy: mean action 0 (the reference's targets in residual mode), sigma 0.05."""

    def __init__(self, meta: dict, action_size: int):
        self.metadata, self.action_size = meta, action_size

    def act(self, obs: torch.Tensor, deterministic: bool = True) -> torch.Tensor:
        return torch.zeros(obs.shape[0], self.action_size)

    @property
    def sigma(self) -> torch.Tensor:
        return torch.full((self.action_size,), 0.05)


def test_trials_are_evaluates_and_successful_only_keeps_its_successes(run: Path, lenient: Path, tmp_path: Path) -> None:
    from wristmimic.env.config import TerminationConfig
    from wristmimic.evaluate import evaluate_policy, load_protocol
    from wristmimic.evaluate.trials import make_env

    # trials that reach the end (the tiny run's all end early): a stand-in policy, no early terminations
    no_end = EnvConfig(wrist_resets=False, termination=TerminationConfig(fall_height=-1e9, body_error=1e9,
                       object_error=1e9, contact_lost_frames=10**6))  # fmt: skip
    meta = {"scene": SID, "variant": "wristmimic", "dataset": load_eval_policy(run).metadata["dataset"], "env": no_end}
    probe = make_env(meta, 1, nthread=1)
    policy = _ZeroMean(meta, probe.action_size)
    probe.close()
    kw = dict(trials=6, num_envs=4, nthread=1, progress=False)
    table = pd.read_parquet(evaluate_policy(policy, load_protocol(lenient), tmp_path / "ev", **kw).parquet)
    errs = np.sort(table["obj_pos_err_cm"].to_numpy())  # a threshold between them: some succeed, some fail
    strict = tmp_path / "strict.toml"
    strict.write_text(lenient.read_text().replace("= 10.0", f"= {float(errs[2] + errs[3]) / 200.0!r}"))
    proto = load_protocol(strict)
    table = pd.read_parquet(evaluate_policy(policy, proto, tmp_path / "ev2", **kw).parquet)
    assert 0 < table["success"].sum() < 6

    out = tmp_path / "all.h5"
    res = export_rollouts(policy, out, protocol=proto, **kw)
    assert validate(out) == [] and res.successes == table["success"].sum() and len(res.sequences) == 6
    seeds = trial_seeds(3, torch.arange(6)).tolist()
    with open_dataset(out) as ds:
        assert sorted(ds.sequence_ids) == sorted(f"{SID}__sim_{s}" for s in seeds)
        for row in table.itertuples():  # the same trials as evaluate's, bit for bit
            s = ds.sequence(f"{SID}__sim_{row.seed}")
            e = s.extra["export"]
            assert e["trial"] == row.trial and e["seed"] == row.seed and e["success"] == row.success
            assert e["obj_pos_err_cm"] == row.obj_pos_err_cm and e["contact_ratio"] == row.contact_ratio
            assert s.num_frames == row.frames_completed + 1 == e["frames"] == 30
            assert e["action_sigma"] == pytest.approx(0.05) and e["noise"] == "actions" and e["base_seed"] == 3
    ok = tmp_path / "ok.h5"
    export_rollouts(policy, ok, protocol=proto, successful_only=True, **kw)
    with open_dataset(ok) as ds:
        assert sorted(ds.sequence_ids) == sorted(f"{SID}__sim_{s}" for s in table.loc[table["success"], "seed"])
    code, text = _export(str(run), "-o", str(tmp_path / "none.h5"), "-n", "2", "--successful-only")
    assert code == 1 and text.count("\n") == 1 and "none of the 2 trials succeeded" in text  # the tiny run's
    assert not (tmp_path / "none.h5").exists()


def test_from_eval_reruns_chosen_rows_by_their_seeds(run: Path, lenient: Path, tmp_path: Path) -> None:
    ev = tmp_path / "ev"
    r = CliRunner().invoke(app, ["evaluate", str(run), "-p", str(lenient), "-n", "6", "--num-envs", "4",
                                 "--nthread", "1", "-q", "-o", str(ev)])  # fmt: skip
    assert r.exit_code == 0, r.output
    table = pd.read_parquet(ev / f"{SID}.parquet").set_index("trial")
    out = tmp_path / "rows.h5"
    code, text = _export(str(run), "-o", str(out), "--from-eval", str(ev), "--rows", "1,3-4", "--num-envs", "2")
    assert code == 0, text
    assert validate(out) == []
    full = tmp_path / "full.h5"
    assert _export(str(run), "-o", str(full), "-p", str(lenient), "--trials", "6")[0] == 0
    with open_dataset(out) as ds, open_dataset(full) as fd:
        assert sorted(ds.sequence_ids) == sorted(f"{SID}__sim_{table.loc[t, 'seed']}" for t in (1, 3, 4))
        for sid in ds.sequence_ids:
            e = ds.sequence(sid).extra["export"]
            row = table.loc[e["trial"]]
            assert e["seed"] == row["seed"] and e["success"] == e["eval_success"] == row["success"]
            assert e["obj_pos_err_cm"] == row["obj_pos_err_cm"] and e["from_eval"] == str(ev.resolve())
            # a trial is a pure function of its seed: re-run alone (other worlds, other batch) it is the same
            assert np.array_equal(ds.sequence(sid).array("body_pos"), fd.sequence(sid).array("body_pos"))
    code, text = _export(str(run), "-o", str(tmp_path / "x.h5"), "--from-eval", str(ev), "--rows", "99")
    assert code == 1 and text.count("\n") == 1 and "no trial 99" in text
    assert parse_rows("0-2, 5,1") == [0, 1, 2, 5]


def test_bad_input_fails_with_one_line_and_writes_nothing(run: Path, tmp_path: Path) -> None:
    out = tmp_path / "o.h5"
    dataset = Path(load_eval_policy(run).metadata["dataset"])
    changed = tmp_path / "changed.h5"
    shutil.copy(dataset, changed)
    with open(changed, "ab") as f:
        f.write(b"\0")
    not_policy = tmp_path / "notes.pt"
    not_policy.write_text("not a checkpoint\n")
    cases = {
        "moved": ([str(run), "--dataset", str(tmp_path / "gone.h5")], "dataset of the run not found"),
        "changed": ([str(run), "--dataset", str(changed)], "differs from the run's dataset"),
        "not a policy": ([str(not_policy)], "notes.pt"),
        "a dataset, not a policy": ([str(dataset)], str(dataset.name)),
        "rows without eval": ([str(run), "--rows", "1"], "--from-eval"),
    }
    for name, (args, words) in cases.items():
        code, text = _export(*args, "-o", str(out))
        assert code == 1 and text.count("\n") == 1 and text.startswith("error: ") and words in text, (name, text)
        assert "Traceback" not in text and not out.exists(), name
    out.write_text("keep")
    code, text = _export(str(run), "-o", str(out))
    assert code == 1 and text.count("\n") == 1 and "already exists" in text and out.read_text() == "keep"
    assert temporaries(tmp_path) == []


def test_moved_dataset_of_a_run_is_refused_before_writing(run: Path, tmp_path: Path) -> None:
    policy = load_eval_policy(run)
    policy.metadata["dataset"] = str(tmp_path / "moved" / "im.h5")
    with pytest.raises(Exception, match="dataset of the run not found") as exc:
        export_rollouts(policy, tmp_path / "o.h5", nthread=1, progress=False)
    assert "\n" not in str(exc.value) and not (tmp_path / "o.h5").exists()


def test_ctrl_c_during_an_export_leaves_nothing(run: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    policy = load_eval_policy(run)
    real = export_mod._SequenceBuilder.__call__
    calls = []

    def interrupt(self, a, extra):  # noqa: ANN001, ANN202
        calls.append(1)
        if len(calls) == 2:
            raise KeyboardInterrupt
        return real(self, a, extra)

    monkeypatch.setattr(export_mod._SequenceBuilder, "__call__", interrupt)
    with pytest.raises(KeyboardInterrupt):
        export_rollouts(policy, tmp_path / "o.h5", trials=4, num_envs=2, nthread=1, progress=False)
    assert not (tmp_path / "o.h5").exists() and temporaries(tmp_path) == []


def test_an_exported_file_trains(run: Path, tmp_path: Path) -> None:
    from wristmimic.rl import TrainSpec, preset, start_run

    out = tmp_path / "demo.h5"
    assert _export(str(run), "-o", str(out))[0] == 0
    tiny = dict(num_envs=2, horizon=4, minibatch_size=8, epochs=1, actor_hidden=(16,), critic_hidden=(16,))
    spec = TrainSpec(out, f"{SID}__sim_mean", "wristmimic", 0, "cpu", preset("cpu", **tiny, max_frames=8))
    res = start_run(spec, tmp_path / "trained", nthread=1, progress=False)
    assert (res.run_dir / "checkpoint.pt").is_file()
    r = CliRunner().invoke(app, ["evaluate", str(res.run_dir), "-p", "quick", "-n", "2", "--num-envs", "2",
                                 "--nthread", "1", "-q"])  # fmt: skip
    assert r.exit_code == 0, r.output
