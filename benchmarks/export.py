"""Export time against evaluate time for the same seeded trials of a trained run, measured in one process.

Usage:  python benchmarks/export.py RUN [--trials 1000] [--num-envs 256] [--nthread N] [--repeat 1]

Runs ``evaluate_policy`` (paper protocol, sampled actions: its Parquet parts, table and summaries into a temporary
folder) and ``export_rollouts`` (the same trials, every one written as a canonical sequence into a temporary .h5)
with the same worlds and threads, ``--repeat`` times each, alternating, and prints the best wall time of each and
their ratio (target: export <= 1.3x evaluate), the exported file's size and the bytes per frame.
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path

from wristmimic.evaluate import evaluate_policy, load_eval_policy, load_protocol
from wristmimic.evaluate.export import export_rollouts


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("run", type=Path, help="a training run folder or checkpoint")
    ap.add_argument("--trials", type=int, default=1000)
    ap.add_argument("--num-envs", type=int, default=256)
    ap.add_argument("--nthread", type=int, default=os.cpu_count() or 1)
    ap.add_argument("--repeat", type=int, default=1)
    args = ap.parse_args()
    proto = load_protocol("paper")
    policy = load_eval_policy(args.run)
    kw = dict(trials=args.trials, num_envs=args.num_envs, nthread=args.nthread, progress=False)
    t_eval, t_export = float("inf"), float("inf")
    with tempfile.TemporaryDirectory() as tmp:
        for k in range(args.repeat):
            t0 = time.perf_counter()
            ev = evaluate_policy(policy, proto, Path(tmp) / f"eval{k}", **kw)
            t_eval = min(t_eval, time.perf_counter() - t0)
            out = Path(tmp) / f"export{k}.h5"
            t0 = time.perf_counter()
            ex = export_rollouts(policy, out, protocol=proto, **kw)
            t_export = min(t_export, time.perf_counter() - t0)
            size = out.stat().st_size
    s = ev.summary
    print(
        f"{s['scene']}: {args.trials:,} trials on {min(args.num_envs, args.trials)} worlds, {args.nthread} threads, "
        f"best of {args.repeat}; success {100 * s['success_rate']:.1f} %, {ev.frames:,} trial frames\n"
        f"  evaluate {t_eval:8.2f} s  ({args.trials / t_eval:,.1f} trials/s)\n"
        f"  export   {t_export:8.2f} s  ({args.trials / t_export:,.1f} trials/s), {len(ex.sequences):,} sequences, "
        f"{size / 2**20:,.1f} MiB ({size / max(ex.frames + len(ex.sequences), 1):,.0f} bytes/frame)\n"
        f"  ratio export / evaluate {t_export / t_eval:5.2f}x  (target <= 1.3x)"
    )


if __name__ == "__main__":
    main()
