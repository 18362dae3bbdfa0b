"""Dataset manifests name real converters, and their layouts match the shared copies."""

from __future__ import annotations

import tomllib
from pathlib import Path

import pytest
from typer.testing import CliRunner

from wristmimic.cli.main import app

from conftest import SHARED_DATA

MANIFESTS = sorted((Path(__file__).resolve().parents[1] / "datasets").glob("*.toml"))


def test_there_is_a_manifest_per_converter() -> None:
    converters = {tomllib.loads(m.read_text())["converter"] for m in MANIFESTS}
    assert converters == {"intermimic", "skillmimic-parahome", "parahome-raw", "omomo-raw"}


@pytest.mark.parametrize("manifest", MANIFESTS, ids=lambda p: p.stem)
def test_manifest_fields_and_command(manifest: Path) -> None:
    m = tomllib.loads(manifest.read_text())
    for key in ("name", "dataset", "source_format", "converter", "licence", "obtain", "convert", "output", "layout"):
        assert key in m, key
    assert m["convert"].startswith(f"wristmimic convert {m['converter']} ")
    r = CliRunner().invoke(app, ["convert", m["converter"], "--help"])
    assert r.exit_code == 0
    if "shared_copy" not in m:
        pytest.skip(f"{manifest.name}: no shared copy of this source")
    shared = SHARED_DATA / m["shared_copy"]
    if not shared.exists():
        pytest.skip(f"shared data not found at {shared}")
    for key in m.get("shared_layout", list(m["layout"])):  # a partial shared copy lists what it holds
        pattern = m["layout"][key]
        assert list(shared.glob(pattern)), f"{manifest.name}: layout.{key} = {pattern!r} matches nothing in {shared}"
