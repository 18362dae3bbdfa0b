"""Evaluation: counter-based noise, metrics and the success rule, protocols and splits as data, replayable trials,
interrupt-safe resume with identical results, and the ``evaluate`` / ``report`` commands on a trained run."""

from __future__ import annotations

import json
import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import torch
from typer.testing import CliRunner

from wristmimic.cli.main import app
from wristmimic.convert.common import ConvertOptions
from wristmimic.convert.intermimic import convert_intermimic
from wristmimic.env.config import EnvConfig, TerminationConfig
from wristmimic.errors import InputError
from wristmimic.evaluate import EvalInterrupted, evaluate_policy, load_protocol, load_split, wilson_interval
from wristmimic.evaluate import runner as eval_runner
from wristmimic.evaluate.metrics import TRIAL_COLUMNS, TrialSums, is_strict_success, is_success
from wristmimic.evaluate.noise import normal, splitmix64, trial_seeds, uniform
from wristmimic.evaluate.policy import act_rows
from wristmimic.evaluate.trials import TrialSettings, make_env, run_trials

from conftest import SHARED_DATA
from synthetic import write_intermimic_folder

SID = "sub1_box_000"
# lax base terminations: trials last 8-15 frames with the stand-in policy (a mix of reasons), no wrist resets
# absolute actions: a random stand-in policy then makes trials end at different frames (residual actions around
# the reference keep every trial of such a short clip alive to its end)
LAX = EnvConfig(
    wrist_resets=False, termination=TerminationConfig(body_error=1.0, object_error=1.0), action_mode="absolute"
)
NO_END = EnvConfig(
    wrist_resets=False,
    termination=TerminationConfig(fall_height=-1e9, body_error=1e9, object_error=1e9, contact_lost_frames=10**6),
)


@pytest.fixture(scope="module")
def dataset(tmp_path_factory: pytest.TempPathFactory) -> Path:
    tmp = tmp_path_factory.mktemp("eval")
    out = tmp / "im.h5"
    opts = ConvertOptions(hull_cache_dir=tmp / "c", show_progress=False)
    convert_intermimic(write_intermimic_folder(tmp / "im", T=30), out, options=opts)
    return out


class StandIn:
    """A randomly initialised MLP policy with a fixed sigma, as evaluation sees a trained one."""

    def __init__(self, obs_size: int, action_size: int, meta: dict, seed: int = 0):
        g = torch.Generator().manual_seed(seed)
        self.w1 = torch.randn(obs_size, 64, generator=g) / obs_size**0.5
        self.w2 = torch.randn(64, action_size, generator=g) * 0.3
        self.metadata = meta
        self._sigma = torch.full((action_size,), 0.2)

    def act(self, obs: torch.Tensor, deterministic: bool = True) -> torch.Tensor:
        return torch.nn.functional.silu(obs @ self.w1) @ self.w2

    @property
    def sigma(self) -> torch.Tensor:
        return self._sigma


def _policy(dataset: Path, env_cfg: EnvConfig = LAX, variant: str = "decoupled") -> StandIn:
    meta = {"scene": SID, "variant": variant, "dataset": str(dataset), "env": env_cfg}
    env = make_env(meta, 1, nthread=1)
    obs, _ = env.reset()
    env.close()
    return StandIn(obs.shape[1], env.action_size, meta)


def _records(env, policy, settings, start: int, stop: int) -> pd.DataFrame:
    recs: list[dict] = []
    run_trials(env, policy, settings, start, stop, recs.append)
    cols = {k: np.concatenate([r[k] for r in recs]) for k in recs[0]}
    return pd.DataFrame(cols).sort_values("trial").reset_index(drop=True)


# ----------------------------------------------------------------------------------------------- noise


def _splitmix64_int(x: int) -> int:
    """Reference splitmix64 on Python integers (mod 2^64)."""
    m = (1 << 64) - 1
    z = (x + 0x9E3779B97F4A7C15) & m
    z = ((z ^ (z >> 30)) * 0xBF58476D1CE4E5B9) & m
    z = ((z ^ (z >> 27)) * 0x94D049BB133111EB) & m
    return z ^ (z >> 31)


def test_splitmix64_matches_the_integer_definition() -> None:
    xs = [0, 1, 2, 12345, 2**62 + 7, -1, -(2**63)]
    got = splitmix64(torch.tensor(xs, dtype=torch.int64)).tolist()
    want = [_splitmix64_int(x % (1 << 64)) for x in xs]
    assert [g % (1 << 64) for g in got] == want


def test_noise_is_a_pure_function_of_seed_step_and_index() -> None:
    seeds = trial_seeds(0, torch.arange(6))
    assert (seeds >= 0).all() and len(set(seeds.tolist())) == 6
    steps = torch.tensor([0, 3, 9, 0, 1, 2])
    batch = normal(seeds, steps, 11)
    for i in range(6):  # one row alone, or inside a reversed batch, gives the same bits
        assert torch.equal(normal(seeds[i : i + 1], steps[i : i + 1], 11)[0], batch[i])
    assert torch.equal(normal(seeds.flip(0), steps.flip(0), 11).flip(0), batch)
    assert not torch.equal(normal(seeds, steps + 1, 11), batch)  # the step matters
    assert not torch.equal(normal(seeds, steps, 11, stream=1), batch)  # so does the stream
    assert not torch.equal(trial_seeds(1, torch.arange(6)), seeds)


def test_noise_is_standard_normal_and_uniforms_stay_inside_the_unit_interval() -> None:
    z = normal(trial_seeds(3, torch.arange(2000)), torch.zeros(2000, dtype=torch.long), 100).double()
    assert abs(z.mean().item()) < 0.01 and abs(z.std().item() - 1.0) < 0.01
    assert abs((z.abs() < 1.959964).double().mean().item() - 0.95) < 0.003
    u = uniform(trial_seeds(0, torch.arange(100)), torch.arange(100), 1000)
    assert u.min() > 0.0 and u.max() < 1.0


# --------------------------------------------------------------------------------------------- metrics


def test_wilson_interval_known_values() -> None:
    lo, hi = wilson_interval(8, 10)
    assert lo == pytest.approx(0.4902, abs=1e-4) and hi == pytest.approx(0.9433, abs=1e-4)
    lo, hi = wilson_interval(0, 64)
    assert lo == 0.0 and hi == pytest.approx(0.0566, abs=1e-4)
    lo, hi = wilson_interval(64, 64)
    assert hi == 1.0 and lo == pytest.approx(1 - 0.0566, abs=1e-4)
    assert all(math.isnan(v) for v in wilson_interval(0, 0))


def test_success_needs_completion_object_error_and_contact() -> None:
    term = torch.tensor([False, True, False, False, False, False])
    done = torch.tensor([True, False, False, True, True, True])
    err = torch.tensor([0.05, 0.05, 0.05, 0.10, 0.05, 0.0999], dtype=torch.float64)
    ratio = torch.tensor([0.8, 1.0, 1.0, 1.0, 0.79, 0.9], dtype=torch.float64)
    got = is_success(term, done, err, ratio, 0.10, 0.8).tolist()
    assert got == [True, False, False, False, False, True]


def test_strict_success_also_needs_the_object_within_the_threshold_in_every_frame() -> None:
    # a box left on the table while the reference lifts it 14 cm for a few frames: mean 2 cm, peak 14 cm
    success = torch.tensor([True, True, True, False])
    peak = torch.tensor([0.14, 0.0999, 0.10, 0.01], dtype=torch.float64)
    assert is_strict_success(success, peak, 0.10).tolist() == [False, True, False, False]


def test_trial_sums_average_errors_and_count_kept_hand_contact() -> None:
    sums = TrialSums.zeros(2)
    ref = torch.tensor([[True, False], [True, True]])
    for k, sim in enumerate(
        (torch.tensor([[True, True], [False, True]]), torch.tensor([[False, False], [True, True]]))
    ):
        sums.add(
            {
                "obj_pos": torch.tensor([0.1, 0.2 * k]),
                "obj_rot": torch.tensor([math.pi / 2, 0.0]),
                "wrist_pos": torch.tensor([0.01, 0.03]),
                "wrist_rot": torch.tensor([0.0, math.pi]),
                "sim_hand": sim,
                "ref_hand": ref,
            }
        )
    m = sums.means(torch.tensor([0, 1]), ref_contact=4)
    assert m["obj_pos_err_cm"].tolist() == pytest.approx([10.0, 10.0])
    assert m["obj_rot_err_deg"].tolist() == pytest.approx([90.0, 0.0])
    assert m["wrist_rot_err_deg"].tolist() == pytest.approx([0.0, 180.0])
    assert m["contact_ratio"].tolist() == pytest.approx([1 / 4, 3 / 4])
    assert m["obj_pos_err_peak_cm"].tolist() == pytest.approx([10.0, 20.0])
    sums.clear(torch.tensor([0]))
    assert sums.frames.tolist() == [0, 2] and sums.obj_pos_peak[0] == 0
    assert sums.means(torch.tensor([1]), ref_contact=0)["contact_ratio"].tolist() == [1.0]  # no reference contact


def test_policy_rows_do_not_depend_on_the_batch() -> None:
    pol = StandIn(300, 40, {})
    obs = torch.randn(70, 300, generator=torch.Generator().manual_seed(1))
    full = act_rows(pol, obs)
    for i in (0, 33, 69):
        assert torch.equal(act_rows(pol, obs[i : i + 1])[0], full[i])


# ----------------------------------------------------------------------------------- protocols, splits


def test_paper_and_quick_protocols() -> None:
    p = load_protocol("paper")
    assert (p.trials, p.start_frame, p.noise, p.base_seed) == (10000, 0, "actions", 0)
    assert (p.max_object_position_error_m, p.min_contact_ratio) == (0.10, 0.8)
    q = load_protocol("quick")
    assert q.trials == 64 and q.max_object_position_error_m == 0.10
    assert load_protocol(p.path) == p  # by path too


def test_splits_list_20_unique_scenes_named_as_the_converters_name_them() -> None:
    ph, om = load_split("parahome20"), load_split("omomo20")
    assert (ph.dataset, om.dataset) == ("parahome", "omomo")
    for s in (ph, om):
        assert len(s.ids) == 20 and len(set(s.ids)) == 20
    assert {"s110_move_kettle", "s29_move_pot", "s114_move_pan", "s79_move_cup"} <= set(ph.ids)
    assert all(sc.end - sc.start > 0 for sc in ph.scenes)
    shared = [f"sub2_largetable_{i:03d}" for i in range(6)] + [f"sub8_plasticbox_{i:03d}" for i in range(3)]
    assert set(shared) <= set(om.ids)
    motions = SHARED_DATA / "skillmimic_parahome" / "motions"
    for f in sorted(motions.rglob("*.pt")) if motions.is_dir() else []:
        assert f.stem[4:] in ph.ids  # the shared clip files' ids are in the split
    for f in sorted((SHARED_DATA / "intermimic_omomo" / "motions").glob("*.pt")):
        assert f.stem in om.ids  # and every shared OMOMO sequence


BAD_PROTOCOLS = {
    "trials = 0": ("trials", "expected an integer >= 1"),
    'noise = "dropout"': ("noise", "one of actions, initial-state"),
    "start_frame = 5": ("start_frame", "expected 0"),
    "color = 1": ("color", "unknown key"),
    'trials = "many"': ("trials", "is a str"),
}
GOOD = 'trials = 8\nstart_frame = 0\nnoise = "actions"\nbase_seed = 0\n[success]\nmax_object_position_error_m = 0.1\nmin_contact_ratio = 0.8\n'


@pytest.mark.parametrize("line", list(BAD_PROTOCOLS))
def test_bad_protocols_fail_with_one_line(tmp_path: Path, line: str) -> None:
    key = line.split(" =")[0]
    text = "\n".join(x for x in GOOD.splitlines() if not x.startswith(key + " ")) if key in GOOD else GOOD
    f = tmp_path / "p.toml"
    f.write_text(line + "\n" + text)
    with pytest.raises(InputError) as e:
        load_protocol(f)
    msg = str(e.value)
    assert "\n" not in msg and all(part in msg for part in BAD_PROTOCOLS[line]), msg


def test_bad_splits_and_unknown_names_fail_with_one_line(tmp_path: Path) -> None:
    f = tmp_path / "s.toml"
    f.write_text('dataset = "omomo"\n[[scenes]]\nid = "a"\n[[scenes]]\nid = "a"\n')
    with pytest.raises(InputError, match=r"scenes\[1\]\.id.*repeated"):
        load_split(f)
    with pytest.raises(InputError, match="unknown protocol 'nope'.*paper, quick"):
        load_protocol("nope")
    with pytest.raises(InputError, match="missing"):
        (tmp_path / "p.toml").write_text("trials = 3\n")
        load_protocol(tmp_path / "p.toml")


# ---------------------------------------------------------------------------------------------- trials


@pytest.mark.parametrize("noise", ["actions", "initial-state"])
def test_a_trial_replayed_alone_reproduces_its_batch_metrics(dataset: Path, noise: str) -> None:
    policy = _policy(dataset)
    settings = TrialSettings(7, noise, 0.10, 0.8)
    env = make_env(policy.metadata, 5, nthread=2)
    batch = _records(env, policy, settings, 0, 16)
    env.close()
    assert batch["trial"].tolist() == list(range(16))
    assert batch["frames_completed"].nunique() > 1  # trials differ
    one = make_env(policy.metadata, 1, nthread=1)
    for k in (0, 6, 15):
        alone = _records(one, policy, settings, k, k + 1)
        pd.testing.assert_frame_equal(alone, batch.iloc[[k]].reset_index(drop=True), check_exact=True)
    one.close()


def test_every_trial_succeeds_without_terminations_and_lenient_thresholds(dataset: Path) -> None:
    policy = _policy(dataset, NO_END)
    policy.w2.zero_()  # mean action 0: the noise alone moves the humanoid, the simulation stays calm
    policy.metadata["ref_frames"] = 12  # a short task
    env = make_env(policy.metadata, 2, nthread=2)
    T = env.ref.num_frames
    lenient = _records(env, policy, TrialSettings(0, "actions", 100.0, 0.0), 0, 2)
    strict = _records(env, policy, TrialSettings(0, "actions", 0.10, 0.8), 0, 2)
    env.close()
    assert lenient["success"].all() and (lenient["termination_reason"] == "none").all()
    assert (lenient["frames_completed"] == T - 1).all() and (lenient["frames_total"] == T - 1).all()
    want = (strict["obj_pos_err_cm"] < 10.0) & (strict["contact_ratio"] >= 0.8)
    assert strict["success"].tolist() == want.tolist()
    assert (lenient["obj_pos_err_peak_cm"] >= lenient["obj_pos_err_cm"]).all()
    assert lenient["strict_success"].tolist() == (lenient["obj_pos_err_peak_cm"] < 10_000.0).tolist()
    assert ((strict["contact_ratio"] >= 0) & (strict["contact_ratio"] <= 1)).all()


def test_interrupted_evaluation_resumes_to_identical_results(dataset: Path, tmp_path: Path, monkeypatch) -> None:
    policy = _policy(dataset)
    proto = replace(load_protocol("quick"), trials=24)
    full = evaluate_policy(policy, proto, tmp_path / "a", num_envs=5, nthread=1, chunk=4, progress=False)
    assert full.trials_run == 24

    real = eval_runner.run_trials

    def interrupted(env, pol, settings, start, stop, sink):
        seen = [0]

        def sink2(rec):
            sink(rec)
            seen[0] += len(rec["trial"])
            if seen[0] >= 11:
                raise KeyboardInterrupt

        return real(env, pol, settings, start, stop, sink2)

    monkeypatch.setattr(eval_runner, "run_trials", interrupted)
    with pytest.raises(EvalInterrupted) as e:
        evaluate_policy(policy, proto, tmp_path / "b", num_envs=5, nthread=1, chunk=4, progress=False)
    kept = e.value.completed
    assert 0 < kept < 24 and not (tmp_path / "b" / f"{SID}.parquet").exists()
    monkeypatch.setattr(eval_runner, "run_trials", real)
    resumed = evaluate_policy(policy, proto, tmp_path / "b", num_envs=3, nthread=2, chunk=4, progress=False)
    assert resumed.trials_run == 24 - kept
    a, b = pd.read_parquet(full.parquet), pd.read_parquet(resumed.parquet)
    pd.testing.assert_frame_equal(a, b, check_exact=True)
    assert list(a.columns) == list(TRIAL_COLUMNS) and a["trial"].tolist() == list(range(24))
    for name in (f"{SID}.parquet", "summary.csv", "summary.json", "eval.json"):
        assert (tmp_path / "a" / name).read_bytes() == (tmp_path / "b" / name).read_bytes(), name
    again = evaluate_policy(policy, proto, tmp_path / "b", progress=False)  # complete: nothing to run
    assert again.trials_run == 0 and again.summary == full.summary
    s = json.loads((tmp_path / "a" / "summary.json").read_text())["scenes"][0]
    assert s["trials"] == 24 and s["successes"] == int(a["success"].sum())
    assert sum(s[f"terminated_{r}"] for r in eval_runner.TERMINATION_NAMES) == int(a["terminated"].sum())


def test_other_settings_in_the_same_folder_are_refused(dataset: Path, tmp_path: Path) -> None:
    policy = _policy(dataset)
    proto = replace(load_protocol("quick"), trials=3)
    evaluate_policy(policy, proto, tmp_path, num_envs=3, nthread=1, progress=False)
    with pytest.raises(InputError, match="other settings \\(base_seed\\)") as e:
        evaluate_policy(policy, proto, tmp_path, seed=5, num_envs=3, nthread=1, progress=False)
    assert "\n" not in str(e.value)
    with pytest.raises(InputError, match="--noise"):
        evaluate_policy(policy, proto, tmp_path / "x", noise="bogus", progress=False)
    with pytest.raises(InputError, match="not in split 'parahome20'"):
        evaluate_policy(policy, proto, tmp_path / "y", split="parahome20", progress=False)


# ------------------------------------------------------------------------------------------------- CLI


def test_evaluate_and_report_commands_on_a_trained_run(dataset: Path, tmp_path: Path) -> None:
    from wristmimic.rl import TrainSpec, preset, start_run

    tiny = dict(num_envs=4, horizon=8, minibatch_size=16, epochs=1, actor_hidden=(32,), critic_hidden=(32,))
    spec = TrainSpec(dataset, SID, "wristmimic", 0, "cpu", preset("cpu", **tiny, max_frames=64), ref_frames=20)
    run = start_run(spec, tmp_path / "run", nthread=1, progress=False).run_dir
    cli = CliRunner()
    r = cli.invoke(app, ["evaluate", str(run), "-p", "quick", "-n", "6", "--num-envs", "4", "--nthread", "1", "-q"])
    assert r.exit_code == 0, r.output
    out = run / "eval" / "quick"
    assert "success" in r.output and (out / f"{SID}.parquet").is_file() and (out / "summary.csv").is_file()
    summary = json.loads((out / "summary.json").read_text())
    assert summary["policy"]["run_dir"] == str(run.resolve()) and summary["settings"]["ref_frames"] == 20
    assert summary["scenes"][0]["frames_total"] == 19 and summary["scenes"][0]["method"] == "WristMimic (Ours)"
    assert summary["settings"]["action_sigma"] == pytest.approx(0.003)  # the CPU recipe's deployed sigma
    args = ["evaluate", str(run), "-p", "quick", "-n", "2", "--nthread", "1", "-q", "-o", str(tmp_path / "wide")]
    assert cli.invoke(app, [*args, "--deploy-std", "0"]).exit_code == 0  # 0: the training sigma
    wide = json.loads((tmp_path / "wide" / "eval.json").read_text())
    assert wide["action_sigma"] == pytest.approx(0.1, rel=0.02)
    r = cli.invoke(app, ["report", str(run), "-o", str(tmp_path / "rep")])
    assert r.exit_code == 0, r.output
    assert (tmp_path / "rep" / "training_curves.png").is_file() and "training_curves.png" in (
        tmp_path / "rep" / "summary.md"
    ).read_text()
    r = cli.invoke(app, ["evaluate", str(tmp_path / "nothing")])
    assert r.exit_code == 1 and r.output.count("\n") == 1 and "no checkpoint found" in r.output
    for cmd in ("evaluate", "report"):
        assert "Example: wristmimic " + cmd in cli.invoke(app, [cmd, "--help"]).output
