"""Pipelines: a tiny synthetic convert -> train pipeline runs once, then a second run does no work; a changed
parameter re-runs only what depends on it; evaluate and report follow the trained runs."""

from __future__ import annotations

from pathlib import Path

import pandas as pd
import pytest
from typer.testing import CliRunner

from wristmimic.cli.main import app
from wristmimic.errors import InputError
from wristmimic.pipeline import STAGES, load_spec, run_pipeline

from synthetic import tiny_ppo_toml, write_intermimic_folder

REPO = Path(__file__).resolve().parents[1]


def _write_spec(tmp: Path, seed: int = 0, extra: str = "") -> Path:
    src = write_intermimic_folder(tmp / "src", T=30)
    spec = tmp / "tiny.toml"
    spec.write_text(
        f"""
[pipeline]
name = "tiny"
work_dir = "{tmp / "work"}"

[convert]
format = "intermimic"
source = "{src}"
output = "{tmp / "data" / "tiny.h5"}"
hull_cache = "{tmp / "hulls"}"

[train]
scenes = "all"
seed = {seed}
{tiny_ppo_toml(16)}
{extra}
"""
    )
    return spec


def _statuses(ctx) -> dict[str, str]:
    return dict(ctx.summary)


def test_second_run_does_no_work_and_a_changed_seed_retrains_only(tmp_path: Path) -> None:
    spec = _write_spec(tmp_path)
    first = run_pipeline(spec, progress=False, nthread=1, echo=lambda s: None)
    assert set(_statuses(first).values()) == {"ran"} and len(first.summary) == 2
    h5, (run_dir,) = tmp_path / "data" / "tiny.h5", first.outputs["runs"]
    stamps = {p: p.stat().st_mtime_ns for p in (h5, run_dir / "checkpoint.pt", run_dir / "metrics.csv")}
    second = run_pipeline(spec, progress=False, nthread=1, echo=lambda s: None)
    assert set(_statuses(second).values()) == {"up to date"}
    assert {p: p.stat().st_mtime_ns for p in stamps} == stamps
    _write_spec(tmp_path, seed=1)
    third = _statuses(run_pipeline(spec, progress=False, nthread=1, echo=lambda s: None))
    assert [s for u, s in third.items() if u.startswith("convert")] == ["up to date"]
    assert [s for u, s in third.items() if u.startswith("train")] == ["ran"]


def test_a_changed_output_is_redone(tmp_path: Path) -> None:
    spec = _write_spec(tmp_path)
    run_pipeline(spec, progress=False, nthread=1, echo=lambda s: None)
    (tmp_path / "data" / "tiny.h5").write_bytes(b"overwritten")
    again = _statuses(run_pipeline(spec, progress=False, nthread=1, echo=lambda s: None))
    assert [s for u, s in again.items() if u.startswith("convert")] == ["ran"]


def test_full_pipeline_with_evaluate_and_report_by_the_command(tmp_path: Path) -> None:
    """convert -> train -> evaluate -> report through `wristmimic run`; a second run does no work."""
    spec = _write_spec(
        tmp_path,
        extra=f'[evaluate]\nprotocol = "quick"\ntrials = 4\nnum_envs = 2\n[report]\noutput = "{tmp_path / "report"}"\n',
    )
    r = CliRunner().invoke(app, ["run", str(spec), "-q", "--nthread", "1"])
    assert r.exit_code == 0, r.output
    assert "4 ran, 0 up to date" in r.output
    assert (tmp_path / "report" / "summary.md").is_file()
    evals = list((tmp_path / "work" / "runs").glob("*/eval/quick"))
    assert len(evals) == 1 and any(evals[0].iterdir())
    r = CliRunner().invoke(app, ["run", str(spec), "-q", "--nthread", "1"])
    assert "0 ran, 4 up to date" in r.output, r.output


def test_bad_pipeline_files_fail_with_one_line(tmp_path: Path) -> None:
    bad = tmp_path / "bad.toml"
    bad.write_text("[deploy]\n")
    with pytest.raises(InputError, match="unknown stage"):
        load_spec(bad)
    bad.write_text("[train]\nlearning_rate = 1\n")
    with pytest.raises(InputError, match="unknown key"):
        load_spec(bad)
    bad.write_text("[train\n")
    with pytest.raises(InputError, match="not valid TOML"):
        load_spec(bad)
    r = CliRunner().invoke(app, ["run", str(tmp_path / "missing.toml")])
    assert r.exit_code == 1 and "file not found" in r.output


@pytest.mark.parametrize("name", ["omomo", "parahome", "hands"])
def test_shipped_pipelines_parse(name: str) -> None:
    spec = load_spec(REPO / "pipelines" / f"{name}.toml")
    assert set(spec) - {"pipeline"} <= set(STAGES) and spec["train"]["preset"] == "cpu"
    assert Path(spec["convert"]["source"]).name in ("intermimic_omomo", "skillmimic_parahome")


def test_hands_pipeline_trains_evaluates_and_reports_one_scene_per_hand(tmp_path: Path) -> None:
    """hands -> train -> evaluate -> report on the synthetic scene: one swapped file, run and evaluation per hand,
    the report's hands table has one row per hand; a second run does no work."""
    from wristmimic.synth import generate

    src = generate(tmp_path / "synth.h5", variants=("default",))
    spec = tmp_path / "hands.toml"
    spec.write_text(
        f"""
[pipeline]
work_dir = "{tmp_path / "work"}"
[hands]
dataset = "{src}"
scene = "synth_default"
hands = ["smplx-intermimic", "parahome-box"]
[train]
ref_frames = 12
{tiny_ppo_toml(16)}
[evaluate]
protocol = "quick"
trials = 2
num_envs = 2
[report]
output = "{tmp_path / "report"}"
"""
    )
    ctx = run_pipeline(spec, progress=False, nthread=1, echo=lambda s: None)
    assert [p.name for p in ctx.outputs["datasets"]] == [
        "synth_default-smplx-intermimic.h5",
        "synth_default-parahome-box.h5",
    ]
    assert set(_statuses(ctx).values()) == {"ran"} and len(ctx.summary) == 7  # 2 hands, 2 trains, 2 evals, report
    hands = pd.read_csv(tmp_path / "report" / "hands.csv")
    assert hands["hand"].tolist() == ["smplx-intermimic", "parahome-box"] and (hands["trials"] == 2).all()
    assert "## Hand morphology" in (tmp_path / "report" / "summary.md").read_text()
    again = run_pipeline(spec, progress=False, nthread=1, echo=lambda s: None)
    assert set(_statuses(again).values()) == {"up to date"}


def test_jobs_cover_every_dataset_of_a_stage_before_train(tmp_path: Path) -> None:
    """outputs["datasets"] (e.g. one file per swapped hand) gives one job per (dataset, scene), with distinct
    cache units and run folders; without it the one dataset keeps today's unit names."""
    from wristmimic.convert.common import ConvertOptions
    from wristmimic.convert.intermimic import convert_intermimic
    from wristmimic.pipeline import Context, plan_jobs

    files = []
    for name, T in (("left", 30), ("right", 32)):
        src = write_intermimic_folder(tmp_path / name, ("sub1_box_000", "sub2_box_001"), T=T)
        out = tmp_path / f"{name}.h5"
        convert_intermimic(src, out, options=ConvertOptions(hull_cache_dir=tmp_path / "hulls", show_progress=False))
        files.append(out)
    ctx = Context(tmp_path / "p.toml", tmp_path / "work", outputs={"datasets": files, "dataset": files[0]})
    jobs = plan_jobs(ctx, {"scenes": "all", "seed": 2})
    assert [j.unit for j in jobs] == [
        f"train {d}/{s}" for d in ("left", "right") for s in ("sub1_box_000", "sub2_box_001")
    ]
    assert len({j.run_dir for j in jobs}) == 4 and all(j.spec.seed == 2 and "-seed2-" in j.run_dir.name for j in jobs)
    assert [j.spec.dataset for j in jobs] == [files[0]] * 2 + [files[1]] * 2
    one = plan_jobs(
        Context(tmp_path / "p.toml", tmp_path / "work"),
        {"dataset": str(files[1]), "scenes": ["sub2_box_001"], "seed": 2},
    )
    assert [(j.unit, j.run_dir) for j in one] == [("train sub2_box_001", jobs[3].run_dir)]


def _export_spec(tmp: Path, seed: int = 0, trials: int = 2) -> Path:
    evaluate = '[evaluate]\nprotocol = "quick"\ntrials = 4\nnum_envs = 2\n'
    export = f'[export]\ntrials = {trials}\nnum_envs = 2\noutput = "{tmp / "sim"}"\n'
    return _write_spec(tmp, seed=seed, extra=evaluate + export)


def test_export_stage_writes_a_valid_file_per_scene_cached_by_content(tmp_path: Path) -> None:
    """convert -> train -> evaluate -> export: <output>/<scene>.h5 validates and replays the evaluation's first
    rows by their seeds; a second run does no work; another trial count re-exports only; a retrained checkpoint
    (another seed) re-exports the same file."""
    import json

    from wristmimic.format.reader import open_dataset
    from wristmimic.format.validate import validate

    spec = _export_spec(tmp_path)
    first = run_pipeline(spec, progress=False, nthread=1, echo=lambda s: None)
    assert _statuses(first) == {
        f"convert {tmp_path / 'data' / 'tiny.h5'}": "ran",
        "train sub1_box_000": "ran",
        f"evaluate {first.outputs['runs'][0].name}": "ran",
        "export sub1_box_000": "ran",
    }
    out = tmp_path / "sim" / "sub1_box_000.h5"
    assert first.outputs["exports"] == [out] and validate(out) == []
    table = pd.read_parquet(first.outputs["evals"][0] / "sub1_box_000.parquet")
    with open_dataset(out) as ds:
        assert set(ds.sequence_ids) == {f"sub1_box_000__sim_{s}" for s in table["seed"][table["trial"] < 2]}
        prov = json.loads(ds.attrs["export"])
    assert prov["mode"] == "from-eval" and prov["trials"] == 2 and prov["from_eval"].endswith("eval/quick")
    assert prov["checkpoint_sha256"] and Path(prov["run"]).name == first.outputs["runs"][0].name
    stamp = out.stat().st_mtime_ns
    second = run_pipeline(spec, progress=False, nthread=1, echo=lambda s: None)
    assert set(_statuses(second).values()) == {"up to date"} and out.stat().st_mtime_ns == stamp
    _export_spec(tmp_path, trials=3)
    third = _statuses(run_pipeline(spec, progress=False, nthread=1, echo=lambda s: None))
    assert [u for u, s in third.items() if s == "ran"] == ["export sub1_box_000"]
    with open_dataset(out) as ds:
        assert len(ds.sequence_ids) == 3
    _export_spec(tmp_path, seed=1, trials=3)
    fourth = run_pipeline(spec, progress=False, nthread=1, echo=lambda s: None)
    assert [s for u, s in _statuses(fourth).items() if not u.startswith("convert")] == ["ran"] * 3
    with open_dataset(out) as ds:
        assert json.loads(ds.attrs["export"])["train_seed"] == 1 and validate(out) == []


def test_export_stage_errors_are_one_line(tmp_path: Path) -> None:
    bad = tmp_path / "bad.toml"
    bad.write_text("[export]\nrows = 1\n")
    with pytest.raises(InputError, match="unknown key"):
        load_spec(bad)
    spec = _write_spec(tmp_path, extra='[evaluate]\nprotocol = "quick"\n[export]\nseed = 3\n')
    from wristmimic.pipeline import Context, export_stage

    ctx = Context(spec, tmp_path / "work", spec=load_spec(spec))
    with pytest.raises(InputError, match="no trained run"):
        export_stage(ctx, {})
    ctx.outputs["jobs"] = ["a planned job"]  # the settings are checked before any job is looked at
    with pytest.raises(InputError, match="given with an evaluation to replay"):
        export_stage(ctx, {"seed": 3})
    with pytest.raises(InputError, match="an integer >= 1"):
        export_stage(ctx, {"trials": 0})
