"""Command-line options shared by several verbs."""

from __future__ import annotations

from typing import Any

import typer


def backend_option() -> Any:
    """``--backend cpu|warp`` (train, evaluate)."""
    return typer.Option(
        "cpu", "--backend", help="Physics: cpu (MuJoCo threads) or warp (MuJoCo Warp: GPU worlds, torch on the GPU)."
    )


def device_option() -> Any:
    """``--device`` of the warp backend."""
    return typer.Option(None, "--device", help="Warp device: cuda, cuda:N or cpu (default: a GPU if any).")
