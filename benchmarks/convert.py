"""Conversion time per sequence and per object (coacd hulls) on the shared data.

Usage:  python benchmarks/convert.py [--shared ../shared/data] [--cold]

``--cold`` decomposes every object with coacd into a fresh temporary cache (minutes: the kettle's 80 hulls
take about 3 min on 2 cores); without it the user hull cache is used, as a second conversion would.
Times are also printed in units of the raw MuJoCo ``mj_step`` time of the same humanoid, measured in the
same run, so the figures compare across machines.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import mujoco
import numpy as np

from wristmimic.convert.common import ConvertOptions
from wristmimic.convert.intermimic import convert_intermimic
from wristmimic.convert.skillmimic_parahome import convert_skillmimic_parahome

REPO = Path(__file__).resolve().parents[1]


def mj_step_seconds(xml: str, steps: int = 3000) -> float:
    """Mean wall time of one raw ``mj_step`` of the humanoid standing on its floor."""
    model = mujoco.MjModel.from_xml_string(xml)
    data = mujoco.MjData(model)
    data.qpos[2] = 1.0
    for _ in range(100):
        mujoco.mj_step(model, data)
    t0 = time.perf_counter()
    for _ in range(steps):
        mujoco.mj_step(model, data)
    return (time.perf_counter() - t0) / steps


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--shared", type=Path, default=REPO.parent / "shared" / "data")
    ap.add_argument("--cold", action="store_true", help="empty hull cache: time the coacd decompositions")
    args = ap.parse_args()
    step = mj_step_seconds((args.shared / "intermimic_omomo" / "omomo.xml").read_text())
    print(f"raw mj_step (omomo.xml humanoid, 1 thread): {step * 1e6:.1f} us  ({1 / step:,.0f} steps/s)")
    with tempfile.TemporaryDirectory() as tmp:
        cache = Path(tmp) / "hulls" if args.cold else None
        opts = ConvertOptions(hull_cache_dir=cache, show_progress=False)
        runs = [
            ("intermimic_omomo", convert_intermimic),
            ("skillmimic_parahome", convert_skillmimic_parahome),
        ]
        for name, fn in runs:
            t0 = time.perf_counter()
            r = fn(args.shared / name, Path(tmp) / f"{name}.h5", options=opts)
            total = time.perf_counter() - t0
            print(f"\n{name}: {len(r.sequences)} sequences, total {total:.1f} s")
            for oid, s in r.seconds_per_object.items():
                hit = "cache hit" if r.hull_cache_hits[oid] else "coacd"
                print(f"  object {oid:<12} {s:8.2f} s  ({hit})")
            for sid, s in r.seconds_per_sequence.items():
                print(f"  sequence {sid:<28} {s:6.2f} s  = {s / step:10,.0f} mj_step")
            seq = np.array(list(r.seconds_per_sequence.values()))
            print(f"  per sequence: mean {seq.mean():.2f} s, max {seq.max():.2f} s")


if __name__ == "__main__":
    main()
