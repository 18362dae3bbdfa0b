"""Reports from crafted evaluation folders: table values and layout, ablations on common scenes, Wilson intervals,
byte-identical reruns, plots, summary.md, and one-line errors for inconsistent inputs."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from wristmimic.errors import InputError
from wristmimic.evaluate.metrics import TRIAL_COLUMNS, wilson_interval
from wristmimic.evaluate.runner import summarize, write_summary
from wristmimic.report import build_report
from wristmimic.report.tables import load_evals, paper_table, per_dataset

# (dataset label, method label, variant, scene, trials, successes, object position error cm)
CASES = [
    ("OMOMO", "WristMimic (Ours)", "wristmimic", "sub2_largetable_000", 20, 19, 5.0),
    ("OMOMO", "WristMimic (Ours)", "wristmimic", "sub8_plasticbox_000", 20, 18, 7.0),
    ("OMOMO", "InterMimic", "intermimic", "sub2_largetable_000", 20, 10, 15.0),
    ("ParaHome", "WristMimic (Ours)", "wristmimic", "s110_move_kettle", 20, 15, 12.0),
    ("ParaHome", "WristMimic (Ours)", "wristmimic", "s29_move_pot", 20, 17, 9.0),
    ("ParaHome", "Decoupled (No Wrist Constraints)", "decoupled", "s110_move_kettle", 20, 0, 50.0),
]


def fake_eval(
    folder: Path, ds: str, method: str, variant: str, scene: str, n: int, s: int, pos: float, protocol: str = "paper"
) -> Path:
    """An evaluation folder as `wristmimic evaluate` writes it, with crafted trials."""
    folder.mkdir(parents=True)
    k = np.arange(n)
    reasons = np.where(k < s, "none", np.where(k % 2 == 0, "object_error", "wrist"))
    df = pd.DataFrame(
        {
            "scene": scene,
            "trial": k,
            "seed": 1000 + k,
            "noise": "actions",
            "success": k < s,
            "terminated": k >= s,
            "termination_reason": reasons,
            "frames_completed": np.where(k < s, 99, 40),
            "frames_total": 99,
            "obj_pos_err_cm": pos + 0.1 * (k - (n - 1) / 2),  # mean exactly pos
            "obj_rot_err_deg": 2 * pos,
            "wrist_pos_err_cm": 3.0,
            "wrist_rot_err_deg": 4.0,
            "contact_ratio": 0.9,
            "obj_pos_err_peak_cm": np.where(k % 4 == 0, 12.0, 8.0),  # every 4th trial once left the 10 cm ball
            "strict_success": (k < s) & (k % 4 != 0),
        }
    )[list(TRIAL_COLUMNS)].astype(TRIAL_COLUMNS)
    df.to_parquet(folder / f"{scene}.parquet", index=False)
    info = {"scene": scene, "dataset": ds.lower(), "dataset_label": ds, "split": "", "method": method,
            "variant": variant, "protocol": protocol, "noise": "actions"}  # fmt: skip
    write_summary(folder, summarize(df, info), {"protocol": protocol}, {"scene": scene, "variant": variant})
    return folder


@pytest.fixture()
def evals(tmp_path: Path) -> Path:
    root = tmp_path / "evals"
    for i, case in enumerate(CASES):
        fake_eval(root / f"e{i}", *case)
    return root


def test_tables_have_the_expected_values_order_and_format(evals: Path, tmp_path: Path) -> None:
    res = build_report([evals], tmp_path / "rep")
    out = res.out
    assert res.scenes == 4 and res.trials == 120
    scene = pd.read_csv(out / "per_scene.csv")
    assert scene[["dataset_label", "method", "scene"]].values.tolist() == [
        ["OMOMO", "InterMimic", "sub2_largetable_000"],
        ["OMOMO", "WristMimic (Ours)", "sub2_largetable_000"],
        ["OMOMO", "WristMimic (Ours)", "sub8_plasticbox_000"],
        ["ParaHome", "Decoupled (No Wrist Constraints)", "s110_move_kettle"],
        ["ParaHome", "WristMimic (Ours)", "s110_move_kettle"],
        ["ParaHome", "WristMimic (Ours)", "s29_move_pot"],
    ]
    row = scene.iloc[1]
    lo, hi = wilson_interval(19, 20)
    assert row["success_pct"] == 95.0 and row["success_ci_low_pct"] == pytest.approx(100 * lo, abs=1e-4)
    assert row["success_ci_high_pct"] == pytest.approx(100 * hi, abs=1e-4) and row["obj_pos_err_cm"] == 5.0
    assert row["strict_pct"] == 70.0 and row["obj_pos_err_peak_cm"] == 9.0  # 19 successes, 5 of them peaked at 12
    text = (out / "per_scene.csv").read_text()
    assert "\r" not in text and "95.0000," in text and text.endswith("\n")
    ds = pd.read_csv(out / "per_dataset.csv")
    wm = ds[(ds["dataset_label"] == "OMOMO") & (ds["method"] == "WristMimic (Ours)")].iloc[0]
    assert (wm["scenes"], wm["trials"], wm["successes"], wm["success_pct"]) == (2, 40, 37, 92.5)
    assert wm["obj_pos_err_cm"] == pytest.approx(6.0)
    paper = pd.read_csv(out / "paper_table.csv", keep_default_na=False)
    assert list(paper.columns) == ["method", "OMOMO", "ParaHome", "Avg."]
    assert paper["method"].tolist() == ["InterMimic", "Decoupled (No Wrist Constraints)", "WristMimic (Ours)"]
    ours = paper.set_index("method").loc["WristMimic (Ours)"]
    assert ours["OMOMO"] == "92.5 / 6.0 / 12.0" and ours["ParaHome"] == "80.0 / 10.5 / 21.0"
    assert ours["Avg."] == "86.2 / 8.2 / 16.5"  # mean over the two datasets (86.25 rounds to even)
    assert paper.set_index("method").loc["InterMimic", "ParaHome"] == "-"
    term = pd.read_csv(out / "terminations.csv")
    assert (
        term["completed"] + term[["fall", "body_error", "object_error", "contact_lost", "wrist"]].sum(axis=1)
        == term["trials"]
    ).all()


def test_tables_of_evaluations_older_than_the_strict_rule_read_with_nan_strict_rates(tmp_path: Path) -> None:
    folder = fake_eval(tmp_path / "old", *CASES[0])
    table = folder / f"{CASES[0][3]}.parquet"
    pd.read_parquet(table).drop(columns=["obj_pos_err_peak_cm", "strict_success"]).to_parquet(table, index=False)
    row = pd.read_csv(build_report([folder], tmp_path / "rep").out / "per_scene.csv").iloc[0]
    assert row["success_pct"] == 95.0 and math.isnan(row["strict_pct"]) and math.isnan(row["obj_pos_err_peak_cm"])


def test_ablations_use_only_the_scenes_every_method_has(evals: Path, tmp_path: Path) -> None:
    out = build_report([evals], tmp_path / "rep").out
    omomo = pd.read_csv(out / "ablation_omomo.csv")
    assert omomo["method"].tolist() == ["InterMimic", "WristMimic (Ours)"] and (omomo["scenes"] == 1).all()
    assert omomo["success_pct"].tolist() == [50.0, 95.0]  # sub8_plasticbox_000 left out: InterMimic lacks it
    para = pd.read_csv(out / "ablation_parahome.csv")
    assert para["variant"].tolist() == ["decoupled", "wristmimic"] and para["success_pct"].tolist() == [0.0, 75.0]


def test_reports_are_byte_identical_and_embed_their_plots(evals: Path, tmp_path: Path) -> None:
    a = build_report([evals], tmp_path / "a", title="t")
    b = build_report([evals / f"e{i}" for i in reversed(range(len(CASES)))], tmp_path / "b", title="t")
    assert a.files == b.files
    for name in a.files:
        assert (a.out / name).read_bytes() == (b.out / name).read_bytes(), name
    md = (a.out / "summary.md").read_text()
    for png in ("success_per_scene.png", "error_distributions.png", "termination_reasons.png"):
        assert f"]({png})" in md and (a.out / png).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert "| WristMimic (Ours) | 92.5 / 6.0 / 12.0 | 80.0 / 10.5 / 21.0 |" in md
    assert "98.9 / 7.3 / 12.2" in md  # the paper's numbers beside ours
    assert "no training curves" in md  # no run logs in crafted folders


def test_training_curves_come_from_the_run_logs(tmp_path: Path) -> None:
    run = tmp_path / "run"
    ev = fake_eval(run / "eval" / "paper", *CASES[0])
    doc = json.loads((ev / "summary.json").read_text())
    doc["policy"]["run_dir"] = str(run)
    (ev / "summary.json").write_text(json.dumps(doc))
    (run / "metrics.csv").write_text(
        "iteration,frames,reward_mean,episode_length_mean\n1,2048,0.1,5.0\n2,4096,0.2,9.5\n"
    )
    res = build_report([run], tmp_path / "rep")
    assert "training_curves.png" in res.files and "![training curves]" in (res.out / "summary.md").read_text()


def test_inconsistent_inputs_fail_with_one_line(evals: Path, tmp_path: Path) -> None:
    fake_eval(tmp_path / "dup", *CASES[0])
    with pytest.raises(InputError, match="WristMimic \\(Ours\\) on sub2_largetable_000 is also in"):
        load_evals([evals, tmp_path / "dup"])
    fake_eval(tmp_path / "quick", "OMOMO", "WristMimic (Ours)", "wristmimic", "sub2_largetable_001", 4, 4, 1.0, "quick")
    with pytest.raises(InputError, match="different protocols \\(paper, quick\\)"):
        load_evals([evals, tmp_path / "quick"])
    (tmp_path / "empty").mkdir()
    with pytest.raises(InputError, match="no evaluation found") as e:
        build_report([tmp_path / "empty"], tmp_path / "rep")
    assert "\n" not in str(e.value)


def test_paper_table_without_a_second_dataset_repeats_the_single_column(evals: Path) -> None:
    t = load_evals([evals / "e0", evals / "e1"]).trials
    assert per_dataset(t)["trials"].tolist() == [40]
    p = paper_table(t)
    assert list(p.columns) == ["method", "OMOMO", "Avg."] and p.iloc[0]["Avg."] == p.iloc[0]["OMOMO"]


def test_a_split_keeps_its_scenes_and_reports_what_is_missing(evals: Path, tmp_path: Path) -> None:
    res = build_report([evals], tmp_path / "rep", splits=["omomo20"])
    assert res.scenes == 2 and "coverage.csv" in res.files
    cov = pd.read_csv(res.out / "coverage.csv")
    assert cov[["split", "method", "listed", "evaluated"]].values.tolist() == [
        ["omomo20", "InterMimic", 20, 1],
        ["omomo20", "WristMimic (Ours)", 20, 2],
    ]
    assert "sub8_plasticbox_000" in cov.loc[0, "missing"] and "sub2_largetable_000" not in cov.loc[0, "missing"]
    assert "## Coverage of the splits" in (res.out / "summary.md").read_text()
    assert list(pd.read_csv(res.out / "paper_table.csv").columns) == ["method", "OMOMO", "Avg."]
    with pytest.raises(InputError, match="unknown split 'nope'"):
        build_report([evals], tmp_path / "rep2", splits=["nope"])


def test_hands_table_when_evaluations_differ_by_hand(tmp_path: Path) -> None:
    """Evaluations of swapped hands (paper Table 4): one row per hand; the method label carries the hand, so the
    per-scene tables keep them apart."""
    from wristmimic.evaluate.runner import method_label

    root = tmp_path / "evals"
    cases = [("smplx-intermimic", 18, 8.0), ("smplx-free", 15, 12.0), ("parahome-box", 14, 16.0), ("", 16, 10.0)]
    for i, (hand, s, pos) in enumerate(cases):
        d = fake_eval(root / f"e{i}", "ParaHome", method_label("wristmimic", {}, hand), "wristmimic",
                      "s110_move_kettle", 20, s, pos)  # fmt: skip
        if hand:  # as the runner writes it for a humanoid with a swapped hand
            doc = json.loads((d / "summary.json").read_text())
            doc["scenes"][0]["hand"] = hand
            (d / "summary.json").write_text(json.dumps(doc))
    res = build_report([root], tmp_path / "rep")
    t = pd.read_csv(res.out / "hands.csv")
    assert t["hand"].tolist() == ["smplx-intermimic", "smplx-free", "parahome-box", "(source hand)"]
    assert t["method"].unique().tolist() == ["WristMimic (Ours)"] and t["success_pct"].tolist() == [90, 75, 70, 80]
    assert t["cell"].tolist()[:2] == ["90.0 / 8.0 / 16.0", "75.0 / 12.0 / 24.0"]
    md = (res.out / "summary.md").read_text()
    assert "## Hand morphology" in md and "| hand | ParaHome |" in md and "| parahome-box | 70.0 / 16.0 / 32.0 |" in md
    scene = pd.read_csv(res.out / "per_scene.csv")
    assert "WristMimic (Ours) [hand smplx-free]" in scene["method"].tolist() and len(scene) == 4


def test_no_hands_table_without_swapped_hands(evals: Path, tmp_path: Path) -> None:
    res = build_report([evals], tmp_path / "rep")
    assert not (res.out / "hands.csv").exists() and "Hand morphology" not in (res.out / "summary.md").read_text()
