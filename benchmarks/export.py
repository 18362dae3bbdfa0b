"""Export time against evaluate time for the same seeded trials of a trained run, measured in one process.

Usage:  python benchmarks/export.py RUN [--trials 1000] [--num-envs 256] [--nthread N] [--repeat 1]

Runs ``evaluate_policy`` (paper protocol, sampled actions: its Parquet parts, table and summaries into a temporary
folder) and ``export_rollouts`` (the same trials, every one written as a canonical sequence into a temporary .h5)
with the same worlds and threads, ``--repeat`` times each, alternating, and prints the best wall time of each and
their ratio (target: export <= 1.3x evaluate), the process CPU time of each (all threads; on a shared machine the
wall times follow the load, the CPU times much less), the exported file's size and the bytes per frame.

Measured (synth_default run h120, 1,000 trials of 52 frames, 256 worlds, --nthread 2, on the 2-core machine while
training ran beside it at normal priority and this at nice 19; ratios only, the absolute times are the load's):
before this version 1.17x (258.6 MiB); with ``source_body_pos`` and ``contacts/geometric`` written once as hard
links (228.9 MiB) and a background writer 1.15x and 1.42x; this version (hard links, no writer thread) 0.93x wall
(while the process got about 5 % of a core, so the wall times say nothing) and 1.15x in CPU time. Writing costs about 10 ms of CPU per 52-frame sequence (6 ms of it gzip, 4 ms creating
its 21 datasets), 11-14 ms per trial in all against about 70 ms of evaluation: CPU-time ratio 1.13-1.20 over
768 trials. A background writer thread (building and writing trials while the rollout steps) was measured and
dropped: over 768 trials it took 63.0 and 65.6 s of CPU against 62.2 and 64.0 s written inline, and no less
wall time (75.9 against 74.1 s), since the process got about one core here.

Quiet machine (2026-12-02, training paused with SIGSTOP, nothing else running; load average 1.6 after the run):
a synth_high_table policy that succeeds (1,000 trials of 139 frames, 256 worlds, --nthread 2): evaluate 100.0 s,
export 122.5 s (520.6 MiB, 3,899 bytes/frame): **1.22x** wall, 1.14x CPU time.
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
    c_eval, c_export = float("inf"), float("inf")
    with tempfile.TemporaryDirectory() as tmp:
        for k in range(args.repeat):
            t0, c0 = time.perf_counter(), time.process_time()
            ev = evaluate_policy(policy, proto, Path(tmp) / f"eval{k}", **kw)
            t_eval, c_eval = min(t_eval, time.perf_counter() - t0), min(c_eval, time.process_time() - c0)
            out = Path(tmp) / f"export{k}.h5"
            t0, c0 = time.perf_counter(), time.process_time()
            ex = export_rollouts(policy, out, protocol=proto, **kw)
            t_export, c_export = min(t_export, time.perf_counter() - t0), min(c_export, time.process_time() - c0)
            size = out.stat().st_size
    s = ev.summary
    print(
        f"{s['scene']}: {args.trials:,} trials on {min(args.num_envs, args.trials)} worlds, {args.nthread} threads, "
        f"best of {args.repeat}; success {100 * s['success_rate']:.1f} %, {ev.frames:,} trial frames\n"
        f"  evaluate {t_eval:8.2f} s  ({args.trials / t_eval:,.1f} trials/s), CPU {c_eval:8.2f} s\n"
        f"  export   {t_export:8.2f} s  ({args.trials / t_export:,.1f} trials/s), CPU {c_export:8.2f} s, "
        f"{len(ex.sequences):,} sequences, {size / 2**20:,.1f} MiB "
        f"({size / max(ex.frames + len(ex.sequences), 1):,.0f} bytes/frame)\n"
        f"  ratio export / evaluate {t_export / t_eval:5.2f}x  (target <= 1.3x), CPU time {c_export / c_eval:5.2f}x"
    )


if __name__ == "__main__":
    main()
