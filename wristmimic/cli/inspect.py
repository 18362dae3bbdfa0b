"""``wristmimic inspect FILE``: what a canonical file holds, with contact statistics and physical plausibility."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import typer

from wristmimic.cli.errors import user_errors
from wristmimic.errors import InputError
from wristmimic.format.reader import Dataset, open_dataset

PLAUSIBILITY_AUTO_MAX = 10
"""Without --plausibility / --no-plausibility / --sequence, files with at most this many sequences get the
plausibility metrics (about 0.2 to 0.7 s per sequence of 150 frames); larger files would take minutes."""


def _agreement(a: np.ndarray, b: np.ndarray) -> dict[str, float]:
    """Share of equal labels and contact (label 1) precision/recall of ``a`` against ``b``."""
    ca, cb = a == 1, b == 1
    tp = float((ca & cb).sum())
    return {
        "equal": float((a == b).mean()) if a.size else float("nan"),
        "contact_precision": tp / max(float(ca.sum()), 1.0),
        "contact_recall": tp / max(float(cb.sum()), 1.0),
    }


def plausibility_of(ds: Dataset, sid: str) -> dict[str, Any]:
    """The plausibility metrics of one sequence (rounded, NaN as None) and the seconds they took, or the
    one-line reason they could not be computed (a sequence that fails the data gate)."""
    from wristmimic.plausibility import measure

    try:
        r = measure(ds, sid)
    except InputError as exc:
        return {"error": str(exc)}
    out: dict[str, Any] = {k: (None if np.isnan(v) else round(v, 2)) for k, v in r.summary().items()}
    out["seconds"] = round(r.seconds, 3)
    return out


def summarize(ds: Dataset, plausibility: list[str] | None = None) -> dict[str, Any]:
    """A JSON-friendly summary of the file; ``plausibility``: sequences to measure (``wristmimic.plausibility``)."""
    attrs = ds.attrs
    out: dict[str, Any] = {
        "file": str(ds.path),
        "schema_version": attrs.get("schema_version"),
        "source": f"{attrs.get('source_dataset')} ({attrs.get('source_format')})",
        "converter_version": attrs.get("converter_version"),
        "created_utc": attrs.get("created_utc"),
        "inputs": len(attrs.get("input_sha256", {})),
        "humanoids": {},
        "objects": {},
        "sequences": {},
    }
    for hid in ds.humanoid_ids:
        h = ds.humanoid(hid)
        out["humanoids"][hid] = {
            "family": h.family,
            "bodies": h.num_bodies,
            "joints": len(h.joint_bodies),
            "fingers": len(h.roles["fingers"]),
            "key_bodies": len(h.roles["key_bodies"]),
        }
        if h.hand:
            out["humanoids"][hid] |= {"hand": h.hand, "hand_source": h.hand_source, "hand_ranges": h.hand_ranges}
    for oid in ds.object_ids:
        o = ds.object(oid)
        out["objects"][oid] = {
            "static": o.static,
            "inferred": o.inferred,
            "vertices": len(o.vertices),
            "hulls": o.num_hulls,
            "max_hull_vertices": int(np.diff(o.hull_vertex_offsets).max()),
            "mass_kg": round(o.mass, 4),
            "mass_method": o.mass_method,
        }
    for row in ds.index():
        s = ds.sequence(row["id"])
        h = ds.humanoid(s.humanoid_id)
        labels = s.array("contacts/labels")
        geo = s.array("contacts/geometric")
        hand = s.array("contacts/hand")
        hands = np.concatenate([h.roles["left_hand"], h.roles["right_hand"]])
        meta = s.contact_meta
        info: dict[str, Any] = {
            "frames": s.num_frames,
            "humanoid": s.humanoid_id,
            "objects": s.object_ids,
            "labels_method": meta.get("labels_method", ""),
            "contact_fraction_left_right": [round(float(x), 3) for x in hand.mean(axis=0)],
            "first_contact_frame": s.array("contacts/first_contact_frame").tolist(),
            "contact_window": s.array("contacts/window").tolist(),
            "label_share_1_0_-1": [round(float((labels == v).mean()), 3) for v in (1, 0, -1)],
        }
        if not meta.get("labels_method", "").startswith("geometry"):
            info["geometric_vs_labels_all"] = {k: round(v, 3) for k, v in _agreement(geo, labels).items()}
            info["geometric_vs_labels_hands"] = {
                k: round(v, 3) for k, v in _agreement(geo[:, hands], labels[:, hands]).items()
            }
            lh, rh = h.roles["left_hand"], h.roles["right_hand"]
            flags_geo = np.stack([(geo[:, lh] == 1).any(1), (geo[:, rh] == 1).any(1)], axis=1)
            info["geometric_vs_labels_hand_flags"] = round(float((flags_geo == hand).mean()), 3)
        if plausibility and row["id"] in plausibility:
            info["plausibility"] = plausibility_of(ds, row["id"])
        out["sequences"][row["id"]] = info
    return out


def _fmt(v: float | None, digits: int = 1) -> str:
    return "-" if v is None else f"{v:.{digits}f}"


def plausibility_lines(p: dict[str, Any]) -> str:
    """The plausibility metrics of one sequence as indented text lines (``docs/plausibility.md``)."""
    from wristmimic.plausibility import PlausibilityParams

    q = PlausibilityParams()
    if "error" in p:
        return f"\n      plausibility: not computed ({p['error']})"
    pen = ", ".join(
        f"{name} {_fmt(p[f'{g}_depth_max_mm'])}/{_fmt(p[f'{g}_depth_mean_mm'])}/{_fmt(p[f'{g}_over_pct'], 0)}%"
        for g, name in (
            ("hand_object", "hand-object"),
            ("body_floor", "body-floor"),
            ("object_support", "object-support"),
        )
    )
    return (
        f"\n      plausibility ({p['seconds']:.2f} s): penetration max/mean mm, frames > {q.penetration_m * 1000:g} mm: {pen}"
        f"\n      feet: lowest {_fmt(p['foot_height_min_mm'])} mm above the floor (median {_fmt(p['foot_height_median_mm'])}),"
        f" on the floor {_fmt(p['foot_stance_pct'], 0)}% of foot-frames, skating mean {_fmt(p['foot_skate_mean_cm_s'])}"
        f" max {_fmt(p['foot_skate_max_cm_s'])} cm/s (> {q.skate_speed_m_s * 100:g} cm/s: {_fmt(p['foot_skate_over_pct'], 0)}%);"
        f" object float {p['object_float_frames']:.0f} frames"
        f"\n      hand-object gap where labelled in contact ({p['hand_gap_pairs']:.0f} body-frames): mean"
        f" {_fmt(p['hand_gap_mean_mm'])} max {_fmt(p['hand_gap_max_mm'])} mm (> {q.gap_m * 1000:g} mm: {_fmt(p['hand_gap_over_pct'], 0)}%);"
        f" jerk m/s^3 body mean {_fmt(p['body_jerk_mean'], 0)} max {_fmt(p['body_jerk_max'], 0)}"
        f" (> {q.jerk_m_s3:.0f}: {_fmt(p['body_jerk_over_pct'])}%), object mean {_fmt(p['object_jerk_mean'], 0)}"
        f" max {_fmt(p['object_jerk_max'], 0)}"
    )


def inspect_cmd(
    file: Path = typer.Argument(..., help="Canonical .h5 file."),
    as_json: bool = typer.Option(False, "--json", help="Print the summary as JSON."),
    plausibility: bool | None = typer.Option(
        None,
        "--plausibility/--no-plausibility",
        help=f"Physical plausibility metrics per sequence (default: on for files of at most {PLAUSIBILITY_AUTO_MAX}"
        " sequences or for --sequence, about 0.5 s each).",
    ),
    sequence: list[str] = typer.Option(
        None, "--sequence", "-s", help="Measure plausibility of this sequence only (repeatable)."
    ),
) -> None:
    """Show sequences, frames, humanoids, objects, hull counts and contact statistics (with agreement between
    the source's contact labels and the labels computed from geometry, where the source has labels), and the
    physical plausibility metrics of docs/plausibility.md: penetration depths, foot height and skating, object
    float, hand-object gap where contact is labelled, jerk.

    Example: wristmimic inspect datasets/omomo.h5

    Example: wristmimic inspect datasets/omomo.h5 -s sub2_largetable_000
    """
    with user_errors(), open_dataset(file) as ds:
        ids = ds.sequence_ids
        for sid in sequence or []:
            ds.sequence(sid)  # one-line error for an unknown id
        if plausibility is False:
            measured: list[str] = []
        elif sequence:
            measured = list(sequence)
        elif plausibility or len(ids) <= PLAUSIBILITY_AUTO_MAX:
            measured = ids
        else:
            measured = []
        info = summarize(ds, measured)
    if as_json:
        typer.echo(json.dumps(info, indent=2))
        return
    typer.echo(
        f"{info['file']}  schema {info['schema_version']}  source {info['source']}  "
        f"converter {info['converter_version']}  created {info['created_utc']}  inputs {info['inputs']}"
    )
    typer.echo(f"\nhumanoids ({len(info['humanoids'])})")
    for hid, h in info["humanoids"].items():
        typer.echo(
            f"  {hid:<24} {h['family']:<9} bodies {h['bodies']}  joints {h['joints']}  "
            f"fingers {h['fingers']}  key bodies {h['key_bodies']}"
            + (f"  hand {h['hand']} ({h['hand_ranges']} ranges; {h['hand_source']})" if "hand" in h else "")
        )
    typer.echo(f"\nobjects ({len(info['objects'])})")
    for oid, o in info["objects"].items():
        kind = "static (inferred)" if o["inferred"] else ("static" if o["static"] else "dynamic")
        typer.echo(
            f"  {oid:<32} {kind:<17} hulls {o['hulls']:>3} (<= {o['max_hull_vertices']} verts)  "
            f"mass {o['mass_kg']:.3f} kg ({o['mass_method']})  vertices {o['vertices']}"
        )
    typer.echo(f"\nsequences ({len(info['sequences'])})")
    for sid, s in info["sequences"].items():
        line = (
            f"  {sid:<32} frames {s['frames']:>4}  humanoid {s['humanoid']:<8} objects {','.join(s['objects'])}\n"
            f"      contact L/R {s['contact_fraction_left_right']}  t_c {s['first_contact_frame']}  "
            f"window {s['contact_window']}  labels 1/0/-1 {s['label_share_1_0_-1']}"
        )
        if "geometric_vs_labels_all" in s:
            a, h = s["geometric_vs_labels_all"], s["geometric_vs_labels_hands"]
            line += (
                f"\n      geometry vs source labels: equal {a['equal']:.3f} (hands {h['equal']:.3f}), "
                f"hand contact precision {h['contact_precision']:.3f} recall {h['contact_recall']:.3f}"
                f"; per-hand contact flag agreement {s['geometric_vs_labels_hand_flags']:.3f}"
            )
        if "plausibility" in s:
            line += plausibility_lines(s["plausibility"])
        typer.echo(line)
    if plausibility is None and not sequence and len(info["sequences"]) > PLAUSIBILITY_AUTO_MAX:
        typer.echo(
            f"\nplausibility not measured ({len(info['sequences'])} sequences; about 0.5 s each): "
            "add --plausibility or --sequence SEQ"
        )
