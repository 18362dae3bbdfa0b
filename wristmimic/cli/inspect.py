"""``wristmimic inspect FILE``: what a canonical file holds, with contact statistics."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import typer

from wristmimic.cli.errors import user_errors
from wristmimic.format.reader import Dataset, open_dataset


def _agreement(a: np.ndarray, b: np.ndarray) -> dict[str, float]:
    """Share of equal labels and contact (label 1) precision/recall of ``a`` against ``b``."""
    ca, cb = a == 1, b == 1
    tp = float((ca & cb).sum())
    return {
        "equal": float((a == b).mean()) if a.size else float("nan"),
        "contact_precision": tp / max(float(ca.sum()), 1.0),
        "contact_recall": tp / max(float(cb.sum()), 1.0),
    }


def summarize(ds: Dataset) -> dict[str, Any]:
    """A JSON-friendly summary of the file."""
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
        out["sequences"][row["id"]] = info
    return out


def inspect_cmd(
    file: Path = typer.Argument(..., help="Canonical .h5 file."),
    as_json: bool = typer.Option(False, "--json", help="Print the summary as JSON."),
) -> None:
    """Show sequences, frames, humanoids, objects, hull counts and contact statistics (with agreement between
    the source's contact labels and the labels computed from geometry, where the source has labels).

    Example: wristmimic inspect datasets/omomo.h5
    """
    with user_errors(), open_dataset(file) as ds:
        info = summarize(ds)
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
        typer.echo(line)
