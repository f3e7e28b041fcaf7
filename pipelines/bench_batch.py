"""Throughput of ``microfacet batch``: in-process, local worker processes, Dask LocalCluster.

Generates N synthetic stacks once, then analyses all of them with each executor into a fresh
output folder and prints a table of wall time, stacks per minute and the speed-up against the
in-process run (``--jobs 1``) measured in the same run. Reports are off (``--no-report``) so
the table measures the analysis and the scheduling, not matplotlib.

Run:  python pipelines/bench_batch.py [--n 8] [--size 256] [--slices 16] [--jobs 2]
"""

from __future__ import annotations

import tempfile
from pathlib import Path

from _shared import best_of, md_header, md_row, parser

from microfacet.analysis import AnalysisOptions
from microfacet.workflow.batch import run_batch
from microfacet.forward.synth import generate_stack, preset


def main(argv=None):
    ap = parser(__doc__)
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
        print(md_header(["executor", "wall (s)", "stacks/min", "speed-up vs in-process",
                         "failed"]))
        base = None
        for k, (name, kw) in enumerate(runs):
            dt, res = best_of(lambda k=k, kw=kw: run_batch(
                stacks, tmp / f"out{k}", options=AnalysisOptions(), report=False, **kw), 1)
            base = base or dt
            print(md_row([name, f"{dt:.1f}", f"{60 * args.n / dt:.1f}", f"{base / dt:.2f}×",
                          res.n_failed]), flush=True)


if __name__ == "__main__":
    main()
