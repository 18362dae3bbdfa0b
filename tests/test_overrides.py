"""``--set SECTION.FIELD=VALUE``: overrides reach the run's config, are recorded, and bad ones are refused."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from typer.testing import CliRunner

from wristmimic.cli.main import app
from wristmimic.errors import InputError
from wristmimic.rl.config import preset
from wristmimic.rl.overrides import apply_overrides, parse_override, with_overrides
from wristmimic.rl.train import TrainSpec

from synthetic import converted_intermimic

SID = "sub1_box_000"


def test_parse_reads_json_then_plain_strings() -> None:
    assert parse_override("env.a.b=1500000") == (["env", "a", "b"], 1500000)
    assert parse_override("ppo.actor_hidden=[64, 32]") == (["ppo", "actor_hidden"], [64, 32])
    assert parse_override("env.action_mode=absolute") == (["env", "action_mode"], "absolute")
    assert parse_override("scene_config.object_friction=null") == (["scene_config", "object_friction"], None)
    for bad in ("env", "env.x", "nope.x=1", "env..x=1", "=1"):
        with pytest.raises(InputError, match="--set"):
            parse_override(bad)


def test_apply_sets_nested_fields_and_checks_types() -> None:
    cfg = {"env": {"oc": {"zero": 150000, "gain": 1.0}, "on": True, "mode": "residual"}, "ppo": {"lr": 1e-4}}
    out = apply_overrides(cfg, ["env.oc.zero=2000", "env.oc.gain=2", "ppo.lr=3e-4", "env.mode=absolute"])
    assert out["env"]["oc"] == {"zero": 2000, "gain": 2.0} and isinstance(out["env"]["oc"]["gain"], float)
    assert out["ppo"]["lr"] == 3e-4 and out["env"]["mode"] == "absolute"
    assert cfg["env"]["oc"]["zero"] == 150000  # the input is not modified
    for bad, msg in [
        ("env.oc.zero=1.5", "like the current 150000"),  # float into an int field
        ("env.on=1", "like the current true"),  # int into a bool field
        ("env.oc=3", "like the current"),  # a whole section
        ("env.oc.nope=3", "unknown field env.oc.nope"),
        ("env.mode.x=3", "env.mode is not a section"),
    ]:
        with pytest.raises(InputError, match=msg):
            apply_overrides(cfg, [bad])


def test_with_overrides_rebuilds_the_dataclasses(tmp_path: Path) -> None:
    spec = TrainSpec(tmp_path / "x.h5", SID, ppo=preset("cpu"))
    new = with_overrides(
        spec,
        ["env.object_controller.zero_by_frames=1500000", "ppo.actor_hidden=[64, 32]", "scene_config.substeps=2"],
    )
    assert new.env.object_controller.zero_by_frames == 1_500_000
    assert new.ppo.actor_hidden == (64, 32) and new.scene_config.substeps == 2
    assert new.overrides == (
        "env.object_controller.zero_by_frames=1500000",
        "ppo.actor_hidden=[64, 32]",
        "scene_config.substeps=2",
    )
    assert with_overrides(spec, []) is spec
    with pytest.raises(InputError, match="action_mode"):  # the environment's own check runs
        with_overrides(spec, ["env.action_mode=sideways"])
    with pytest.raises(InputError, match="noise_correlation"):  # and PPOConfig's
        with_overrides(spec, ["ppo.noise_correlation=2.0"])


def test_cli_set_is_used_and_recorded(tmp_path: Path) -> None:
    ds = converted_intermimic(tmp_path, 40)
    common = ["train", str(ds), "-s", SID, "--num-envs", "2", "--max-frames", "8", "--ref-frames", "12", "-q"]
    cli = CliRunner()
    sets = ["--set", "env.residual_scale=0.25", "--set", "ppo.horizon=4", "--set", "ppo.minibatch_size=8"]
    r = cli.invoke(app, [*common, "--nthread", "1", "-o", str(tmp_path / "runs"), *sets])
    assert r.exit_code == 0, r.output
    (run,) = (tmp_path / "runs").iterdir()
    cfg = json.loads((run / "config.json").read_text())
    assert cfg["env"]["residual_scale"] == 0.25 and cfg["ppo"]["horizon"] == 4
    assert cfg["overrides"] == ["env.residual_scale=0.25", "ppo.horizon=4", "ppo.minibatch_size=8"]
    r = cli.invoke(app, [*common, "-o", str(tmp_path / "bad"), "--set", "env.nope=1"])
    assert r.exit_code == 1 and "unknown field env.nope" in r.stderr and not (tmp_path / "bad").exists()
    r = cli.invoke(app, ["train", "--resume", str(run), "--set", "ppo.horizon=8"])
    assert r.exit_code == 1 and "--resume" in r.stderr
