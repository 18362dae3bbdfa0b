"""Plausibility of the references against their simulated rollouts, per evaluated scene (``report --plausibility``).

The simulation side comes from files written by ``wristmimic export`` (sequences ``<scene>__sim_<seed>``; their
metrics are averaged per scene), the reference side from the dataset the export names (root attribute
``export.dataset``), else from the dataset the evaluation recorded (``summary.json`` ``policy.dataset``).
Exports beside an evaluation are found without being named (:func:`exports_beside`): every ``*.h5`` directly in
the evaluation folder, its parent folder or the run folder it names whose root ``export`` attribute names the
evaluation's checkpoint (sha256) and scene. Metric definitions: ``docs/plausibility.md``.
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterable
from pathlib import Path

import numpy as np
import pandas as pd

from wristmimic.errors import InputError
from wristmimic.format.reader import open_dataset
from wristmimic.plausibility import SUMMARY_KEYS, plausibility

MARKDOWN_KEYS = {
    "hand_object_depth_max_mm": "hand-object pen. max mm",
    "body_floor_depth_max_mm": "body-floor pen. max mm",
    "object_support_depth_max_mm": "object-support pen. max mm",
    "foot_height_min_mm": "lowest foot mm",
    "foot_skate_mean_cm_s": "foot skating cm/s",
    "object_float_frames": "float frames",
    "hand_gap_mean_mm": "labelled gap mm",
    "body_jerk_mean": "body jerk m/s^3",
    "object_jerk_mean": "object jerk m/s^3",
}
"""Columns of the Markdown table (each cell: reference / simulation); the CSV has every metric."""


def read_export(path: Path) -> tuple[str, dict[str, list[str]]]:
    """The dataset an export file names and its sequence ids per scene; one-line error for another file."""
    with open_dataset(path) as ds:
        raw = ds.attrs.get("export")
        if raw is None:
            raise InputError(path, "/.export", "missing", "a file written by `wristmimic export`")
        try:
            meta = json.loads(raw)
            dataset = str(meta["dataset"])
        except (json.JSONDecodeError, KeyError, TypeError):
            raise InputError(path, "/.export", "not the JSON `wristmimic export` writes (no dataset)") from None
        scenes: dict[str, list[str]] = {}
        for sid in ds.sequence_ids:
            scene = sid.rsplit("__sim_", 1)[0] if "__sim_" in sid else str(meta.get("scene", sid))
            scenes.setdefault(scene, []).append(sid)
    return dataset, scenes


def _export_meta(path: Path) -> dict | None:
    """The root ``export`` attribute of an HDF5 file as a dict; None for any other or unreadable file."""
    import h5py

    try:
        with h5py.File(path, "r") as f:
            raw = f.attrs.get("export")
        meta = json.loads(raw.decode() if isinstance(raw, bytes) else raw) if raw is not None else None
    except (OSError, ValueError, TypeError, AttributeError):
        return None
    return meta if isinstance(meta, dict) else None


def exports_beside(sources: Iterable[dict]) -> list[Path]:
    """Exports of the evaluated policies found next to their evaluations (sorted, each once).

    ``sources``: per evaluation folder ``path``, ``scene``, ``run_dir`` and ``checkpoint_sha256`` (as
    :func:`wristmimic.report.tables.load_evals` lists them). A ``*.h5`` directly in the evaluation folder, in its
    parent or in the run folder is taken when its root ``export`` attribute has the same ``checkpoint_sha256``
    and ``scene``; any other file there (a dataset, another run's export, an unreadable file) is passed over."""
    found: set[Path] = set()
    for src in sources:
        sha, scene = src.get("checkpoint_sha256"), src.get("scene")
        if not sha:
            continue
        d = Path(src["path"])
        folders = {d, d.parent} | ({Path(src["run_dir"])} if src.get("run_dir") else set())
        for folder in folders:
            for f in sorted(folder.glob("*.h5")) if folder.is_dir() else []:
                meta = _export_meta(f)
                if meta and meta.get("checkpoint_sha256") == sha and meta.get("scene") == scene:
                    found.add(f.resolve())
    return sorted(found)


def plausibility_table(scenes: list[str], exports: list[Path], eval_datasets: dict[str, str]) -> pd.DataFrame:
    """One row per scene: ``scene``, ``sim_sequences``, ``reference`` (dataset path) and, for every metric of
    :data:`~wristmimic.plausibility.SUMMARY_KEYS`, ``<metric>_ref`` and ``<metric>_sim`` (mean over the scene's
    exported sequences; NaN without any)."""
    sims: dict[str, list[dict[str, float]]] = {}
    ref_path: dict[str, str] = {}
    for path in exports:
        dataset, per_scene = read_export(Path(path))
        with open_dataset(path) as ds:
            for scene, ids in per_scene.items():
                sims.setdefault(scene, []).extend(plausibility(ds, sid) for sid in ids)
                ref_path.setdefault(scene, dataset)
    rows = []
    for scene in sorted(scenes):
        ref_file = ref_path.get(scene) or eval_datasets.get(scene, "")
        if ref_file and Path(ref_file).is_file():
            with open_dataset(ref_file) as ds:
                ref = plausibility(ds, scene) if scene in ds.sequence_ids else {}
        elif scene in ref_path:
            raise InputError(ref_file, None, f"no such file (the reference of {scene}, named by its export)")
        else:
            ref = {}
        sim = sims.get(scene, [])
        row: dict[str, object] = {"scene": scene, "sim_sequences": len(sim), "reference": ref_file}
        for k in SUMMARY_KEYS:
            row[f"{k}_ref"] = ref.get(k, math.nan)
            vals = np.array([s[k] for s in sim], dtype=np.float64)
            row[f"{k}_sim"] = float(np.nanmean(vals)) if np.isfinite(vals).any() else math.nan
        rows.append(row)
    cols = ["scene", "sim_sequences", "reference", *(f"{k}_{s}" for k in SUMMARY_KEYS for s in ("ref", "sim"))]
    return pd.DataFrame(rows, columns=cols)


def markdown_layout(df: pd.DataFrame) -> pd.DataFrame:
    """The table for summary.md: scene, simulated sequences and one "reference / simulation" cell per metric."""

    def cell(a: float, b: float) -> str:
        f = lambda v: "-" if math.isnan(v) else f"{v:.1f}"  # noqa: E731
        return f"{f(a)} / {f(b)}"

    out = pd.DataFrame({"scene": df["scene"], "simulated": df["sim_sequences"]})
    for k, label in MARKDOWN_KEYS.items():
        out[label] = [cell(a, b) for a, b in zip(df[f"{k}_ref"], df[f"{k}_sim"], strict=True)]
    return out
