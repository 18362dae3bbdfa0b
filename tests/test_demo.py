"""`wristmimic demo --quick`: the whole suite on the built-in synthetic scene, outputs present and valid."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from typer.testing import CliRunner

from wristmimic.cli.main import app
from wristmimic.format.validate import validate


@pytest.mark.slow
def test_quick_demo_end_to_end(tmp_path: Path) -> None:
    out = tmp_path / "demo"
    r = CliRunner().invoke(app, ["demo", "--quick", "-o", str(out), "--trials", "8", "--nthread", "2"])
    assert r.exit_code == 0, r.output
    assert "under 3 minutes" in r.stdout and "report" in r.stdout
    assert validate(out / "demo.h5") == []
    assert (out / "run" / "checkpoint.pt").is_file() and (out / "run" / "metrics.csv").is_file()
    summary = json.loads(next((out / "eval").rglob("summary.json")).read_text())
    assert summary  # the evaluation wrote its summary
    assert (out / "report" / "summary.md").is_file() and list((out / "report").glob("*.png"))
    assert (out / "demo.rrd").stat().st_size > 10_000
    again = CliRunner().invoke(app, ["demo", "--quick", "-o", str(out)])
    assert again.exit_code == 1 and "already holds a demo run" in again.stderr
