"""Throughput of ``microfacet batch``: in-process, local worker processes, Dask LocalCluster.

Generates N synthetic stacks once, then analyses all of them with each executor into a fresh
output folder and prints a table of wall time, stacks per minute and the speed-up against the
in-process run (``--jobs 1``) measured in the same run. Reports are off (``--no-report``) so
the table measures the analysis and the scheduling, not matplotlib.

Run:  python pipelines/bench_batch.py [--n 8] [--size 256] [--slices 16] [--jobs 2]
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

from microfacet.analysis.pipeline import AnalysisOptions
from microfacet.batch.runner import run_batch
from microfacet.forward.synth import generate_stack, preset


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=8, help="stacks (default 8)")
    ap.add_argument("--size", type=int, default=256)
    ap.add_argument("--slices", type=int, default=16)
    ap.add_argument("--jobs", type=int, default=2, help="workers for the parallel runs")
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        stacks = []
        for i in range(args.n):
            p = preset(("nd", "sd")[i % 2], seed=i, height_px=args.size, width_px=args.size,
                       n_slices=args.slices)
            generate_stack(tmp / "stacks" / f"s{i}", p)
            stacks.append(tmp / "stacks" / f"s{i}")
        runs = [("in-process (--jobs 1)", dict(jobs=1)),
                (f"loky processes (--jobs {args.jobs})", dict(jobs=args.jobs)),
                (f"Dask LocalCluster ({args.jobs} workers)",
                 dict(scheduler="local", jobs=args.jobs))]
        print(f"{args.n} stacks of {args.size}x{args.size} px x {args.slices} slices, "
              f"no report\n")
        print("| executor | wall (s) | stacks/min | speed-up vs in-process | failed |")
        print("|---|---|---|---|---|")
        base = None
        for k, (name, kw) in enumerate(runs):
            t0 = time.perf_counter()
            res = run_batch(stacks, tmp / f"out{k}", options=AnalysisOptions(), report=False,
                            **kw)
            dt = time.perf_counter() - t0
            base = base or dt
            print(f"| {name} | {dt:.1f} | {60 * args.n / dt:.1f} | {base / dt:.2f}× | "
                  f"{res.n_failed} |", flush=True)


if __name__ == "__main__":
    main()
