"""Benchmark: `microfacet analyze` per-stage time on a 1-megapixel, 40-slice stack.

Generates an nd-preset stack (--size, --slices), times decoding its slices alone (the
baseline "reading the stack"), then runs the analysis in both modes and prints the
per-stage table (the same numbers go to summary.json's timings_s). Goal: the whole analysis
well under a minute; the colour stages (everything after height from focus) compared with
reading the stack.

Run:  python pipelines/bench_analyze.py [--size 1024] [--slices 40]
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

import numpy as np
from _shared import best_of, md_header, md_row, parser


def main(argv=None):
    ap = parser(__doc__)
    ap.add_argument("--size", type=int, default=1024)
    ap.add_argument("--slices", type=int, default=40)
    args = ap.parse_args(argv)

    from microfacet.analysis import AnalysisOptions, analyze_stack, write_results
    from microfacet.forward.synth import generate_stack, preset
    from microfacet.io.stack import read_stack
    from microfacet.report import write_report

    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "s"
        generate_stack(path, preset("nd", seed=3, height_px=args.size, width_px=args.size,
                                    n_slices=args.slices))
        st = read_stack(path)

        def decode_all():
            for i in range(st.n_slices):
                st.read_slice(i, dtype=np.uint8)
        decode, _ = best_of(decode_all, 1)
        rows = {}
        for mode in ("seed", "joint"):
            t0 = time.perf_counter()
            r = analyze_stack(path, AnalysisOptions(mode=mode))
            t1 = time.perf_counter()
            res_dir = write_results(r, Path(tmp) / f"out-{mode}")
            write_report(res_dir, png_dir=res_dir)  # a separate step since the restructuring
            rows[mode] = dict(r.timings_s, write_and_report=time.perf_counter() - t1,
                              wall=time.perf_counter() - t0)
    stages = [k for k in rows["joint"] if k not in ("total", "wall", "write_and_report")]
    stages += [k for k in rows["seed"] if k not in stages and k not in ("total", "wall",
                                                                       "write_and_report")]
    print(f"nd preset, {args.size}x{args.size} px, {args.slices} slices; decoding the slices "
          f"alone: {decode:.2f} s\n")
    print(md_header(["stage", "seed mode (s)", "joint mode (s)"]))
    for k in stages + ["total", "write_and_report", "wall"]:
        print(md_row([k] + ["" if rows[m].get(k) is None else f"{rows[m][k]:.2f}"
                            for m in ("seed", "joint")]))
    for mode in ("seed", "joint"):
        colour = rows[mode]["total"] - rows[mode]["height_from_focus"]
        print(f"\n{mode}: colour stages {colour:.2f} s = {colour / decode:.1f}x reading the stack")


if __name__ == "__main__":
    main()
