"""Body-only copy of one sequence: can the recipe track the humanoid's motion when there is no object to carry?

Usage:  python scripts/body_only.py DATASET.h5 --scene SEQ -o BODY_ONLY.h5 [--park 20.0] [--keep-window]

Writes a copy of ``DATASET.h5`` (atomically) in which sequence ``SEQ`` keeps its humanoid reference unchanged, while
every dynamic object's reference stays at its first-frame pose moved ``--park`` metres along +x (far from
everything, so it rests on the floor where its reference says it is), and every contact label says "no contact"
(``labels`` / ``geometric`` at most 0, ``distance`` inf, no hand or object contact, no first-contact frame or
window). Trained with the unchanged recipe (``wristmimic train BODY_ONLY.h5 --scene SEQ``), the policy then tracks
the body alone: the object and contact terms are satisfied trivially, the contact-window modulation and the
grasp-phase wrist thresholds never apply, and every episode end is a body termination (``body_error`` / ``fall``).

``--keep-window`` keeps the contact window, its phases and its grasping hands (each hand's first-contact frame, where
its hand-contact flag stays set for that one frame, as the format requires; every other frame says "no contact"), so
the grasp-phase wrist thresholds and the window's reward modulation apply as on the real scene while no contact is
asked for long enough to end an episode (``contact_lost`` needs more than ``contact_lost_frames`` frames in a row).
That is the body stage of a staged curriculum: ``wristmimic train DATASET.h5 --scene SEQ --init-from BODY_RUN``.

A diagnostic, not a dataset: the copy says so in its root attribute ``body_only`` (JSON: source file, sequence,
park distance). See ``reports/README.md`` for what it found on ``sub2_largetable_000``.
"""

from __future__ import annotations

import argparse
import json
import shutil
import sys
from pathlib import Path

import h5py
import numpy as np

from wristmimic.errors import InputError
from wristmimic.format.validate import validate
from wristmimic.safe_io import atomic_output


def body_only_copy(src: Path, scene: str, out: Path, park: float = 20.0, keep_window: bool = False) -> None:
    """Write ``out``: ``src`` with sequence ``scene``'s objects parked ``park`` m along +x and its contacts
    cleared, or all but the contact window (``keep_window``; see the module docstring); raises
    :class:`InputError` for a missing sequence or bad ``park``."""
    if not np.isfinite(park) or park <= 0.0:
        raise InputError(None, "--park", f"got {park}", "a finite distance > 0 m")
    with h5py.File(src, "r") as f:
        if f"sequences/{scene}" not in f:
            raise InputError(src, f"sequences/{scene}", "no such sequence")
    with atomic_output(out, suffix=".h5") as tmp:
        shutil.copyfile(src, tmp)
        with h5py.File(tmp, "r+") as f:
            s = f[f"sequences/{scene}"]
            pos, quat = s["object_pos"][:], s["object_quat"][:]
            pos[:] = pos[:1] + np.asarray([park, 0.0, 0.0], dtype=pos.dtype)
            quat[:] = quat[:1]
            s["object_pos"][:], s["object_quat"][:] = pos, quat
            c = s["contacts"]
            for key in ("labels", "geometric"):
                c[key][:] = np.minimum(c[key][:], 0)
            c["distance"][:] = np.inf
            first = c["first_contact_frame"][:]
            hand = np.zeros_like(c["hand"][:])
            c["object"][:] = False
            if keep_window:
                for h in np.flatnonzero(first >= 0):
                    hand[first[h], h] = True  # the format's rule: a first contact frame has hand contact
            else:
                c["first_contact_frame"][:] = -1
                c["window"][:] = -1
            c["hand"][:] = hand
            f.attrs["body_only"] = json.dumps(
                {"source_file": str(src), "sequence": scene, "park_m": park, "keep_window": keep_window}
            )
        problems = validate(tmp)
        if problems:
            raise InputError(out, None, f"the body-only copy does not validate: {problems[0]}")


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("dataset", type=Path)
    p.add_argument("--scene", required=True, help="sequence id")
    p.add_argument("-o", "--out", type=Path, required=True, help="the body-only copy (.h5)")
    p.add_argument("--park", type=float, default=20.0, help="m along +x the objects are moved (default 20)")
    p.add_argument("--keep-window", action="store_true", help="keep the contact window and its wrist thresholds")
    a = p.parse_args(argv)
    try:
        body_only_copy(a.dataset, a.scene, a.out, a.park, a.keep_window)
    except InputError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    print(f"{a.out}: {a.scene} without its objects (parked {a.park:g} m along +x) and contacts")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
