"""Record an exported rollout (a sequence ``<scene>__sim_<seed>`` of ``wristmimic export``) beside its reference.

The sequence's provenance (``extra["export"]``: ``dataset``, ``dataset_sha256``, ``scene``, ``ref_frames``,
``ended``, ``termination_reason``) names the reference; the recording is the one of a policy rollout (``/sim``
blue beside a translucent orange ``/ref``, errors, contacts, the end of an episode that ended early) plus the
per-frame plausibility of both (:func:`wristmimic.plausibility.plausibility_series`) under
``/metrics/plausibility``. There is no reward: an export does not store one.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from wristmimic.errors import InputError
from wristmimic.format.reader import Dataset, open_dataset
from wristmimic.format.validate import check_sequence
from wristmimic.humanoid.skeleton import load_skeleton
from wristmimic.view.geometry import humanoid_geoms
from wristmimic.view.record import RecordingSummary, write_recording
from wristmimic.view.tracks import ReferenceTrack, SimTrack, reference_from_dataset


def export_provenance(ds: Dataset, sequence_id: str) -> dict[str, Any] | None:
    """The ``export`` provenance of a sequence written by ``wristmimic export``, None for any other sequence."""
    prov = ds.sequence(sequence_id).extra.get("export")
    return prov if isinstance(prov, dict) and prov.get("scene") and prov.get("dataset") else None


def _source(path: Path, sequence_id: str, prov: dict[str, Any], dataset: Path | None) -> Path:
    from wristmimic.safe_io import sha256_file

    src = Path(dataset if dataset is not None else prov["dataset"])
    if not src.is_file():
        raise InputError(src, None, f"reference dataset of {sequence_id} not found", "the file it names (or --dataset)")
    want = prov.get("dataset_sha256")
    if want and sha256_file(src) != want:
        raise InputError(src, None, f"is not the dataset {path.name} was exported from (sha256 differs)", "that file")
    return src


def sim_track_from_export(ds: Dataset, sequence_id: str, ref: ReferenceTrack, prov: dict[str, Any]) -> SimTrack:
    """The exported frames 0..n-1 as a :class:`SimTrack` (dynamic objects in scene order; touches from the
    simulated contact labels; no reward)."""
    s = ds.sequence(sequence_id).load()
    n = int(s.body_pos.shape[0])
    dyn = [k for k, o in enumerate(ref.objects) if o.dynamic]
    ended = str(prov.get("ended", ""))
    reason = str(prov.get("termination_reason", ""))
    end = f"terminated: {reason}" if prov.get("terminated") else ("truncated" if not ended else ended)
    return SimTrack(
        frames=np.arange(n, dtype=np.int64),
        body_pos=s.body_pos.astype(np.float32),
        body_quat=s.body_quat.astype(np.float32),
        obj_pos=s.object_pos[:, dyn].astype(np.float32),
        obj_quat=s.object_quat[:, dyn].astype(np.float32),
        contact_obj=s.contact_labels > 0,
        reward=np.full(n, np.nan),
        end_reason=end,
        info={
            "export": str(ds.path),
            "sequence": sequence_id,
            "run": str(prov.get("run", "")),
            "actions": str(prov.get("actions", "")),
            "seed": str(prov.get("seed")),
            "success": str(prov.get("success")),
            "ended": ended,
        },
    )


def record_export(
    path: str | Path,
    sequence_id: str,
    out: str | Path,
    *,
    dataset: str | Path | None = None,
    hulls: bool = False,
    plausibility: bool = True,
) -> RecordingSummary:
    """Record exported sequence ``sequence_id`` of ``path`` beside its reference (``dataset``: the reference
    dataset if it moved; same sha256) with the plausibility series of both."""
    from wristmimic.env.config import WindowConfig, env_config_from_dict
    from wristmimic.plausibility import plausibility_series

    path = Path(path)
    with open_dataset(path) as ds:
        check_sequence(ds, sequence_id)
        prov = export_provenance(ds, sequence_id)
        if prov is None:
            raise InputError(path, sequence_id, "is no exported rollout (no export provenance)", "a <scene>__sim_ id")
        src = _source(path, sequence_id, prov, Path(dataset) if dataset is not None else None)
        hid = ds.sequence(sequence_id).humanoid_id
        skel = load_skeleton(ds.humanoid(hid).mjcf, f"{ds.path}:humanoids/{hid}")
        with open_dataset(src) as ref_ds:
            scene = str(prov["scene"])
            check_sequence(ref_ds, scene)
            ref = reference_from_dataset(ref_ds, scene, prov.get("ref_frames"))
            ref_series = plausibility_series(ref_ds, scene) if plausibility else {}
        sim = sim_track_from_export(ds, sequence_id, ref, prov)
        sim_series = plausibility_series(ds, sequence_id) if plausibility else {}
    if sim.body_pos.shape[1] != len(ref.body_names):
        raise InputError(path, sequence_id, f"{sim.body_pos.shape[1]} bodies", f"{len(ref.body_names)} (its reference)")
    env = prov.get("env")
    window = env_config_from_dict(env).window if isinstance(env, dict) else WindowConfig()
    series = {"ref": {k: v[: ref.num_frames] for k, v in ref_series.items()}, "sim": sim_series}
    geoms = humanoid_geoms(skel.model, np.arange(1, skel.num_bodies + 1))
    return write_recording(
        out, ref, geoms, sim=sim, window=window, hulls=hulls, plausibility=series if plausibility else None
    )
