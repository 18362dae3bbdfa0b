"""The CLI end to end on synthetic data: help, convert, inspect, validate."""

from __future__ import annotations

import json
from pathlib import Path

from typer.testing import CliRunner

from wristmimic.cli.main import app

from synthetic import write_intermimic_folder, write_parahome_folder

runner = CliRunner()


def test_help_lists_commands_and_examples() -> None:
    r = runner.invoke(app, ["--help"])
    assert r.exit_code == 0
    for cmd in ("convert", "inspect", "validate"):
        assert cmd in r.output
    r = runner.invoke(app, ["convert", "intermimic", "--help"])
    assert r.exit_code == 0 and "Example" in r.output and "--hull-cache" in r.output
    r = runner.invoke(app, ["convert", "skillmimic-parahome", "--help"])
    assert r.exit_code == 0 and "--skip-missing" in r.output


def test_convert_inspect_validate(tmp_path: Path) -> None:
    src = write_intermimic_folder(tmp_path / "im")
    out = tmp_path / "im.h5"
    r = runner.invoke(app, ["convert", "intermimic", str(src), "-o", str(out), "--hull-cache", str(tmp_path / "c")])
    assert r.exit_code == 0, r.output
    assert "wrote" in r.stdout and out.exists()
    r = runner.invoke(app, ["validate", str(out)])
    assert r.exit_code == 0 and "valid" in r.stdout
    r = runner.invoke(app, ["inspect", str(out)])
    assert r.exit_code == 0 and "sub1_box_000" in r.stdout and "geometry vs source labels" in r.stdout
    r = runner.invoke(app, ["inspect", str(out), "--json"])
    info = json.loads(r.stdout)
    assert info["sequences"]["sub1_box_000"]["frames"] == 40
    assert info["objects"]["box"]["hulls"] >= 1

    src2 = write_parahome_folder(tmp_path / "ph")
    out2 = tmp_path / "ph.h5"
    r = runner.invoke(
        app, ["convert", "skillmimic-parahome", str(src2), "-o", str(out2), "-q", "--hull-cache", str(tmp_path / "c")]
    )
    assert r.exit_code == 0, r.output
    r = runner.invoke(app, ["inspect", str(out2)])
    assert "static (inferred)" in r.stdout
