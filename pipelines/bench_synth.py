"""Benchmark: synthetic-stack generation time and peak memory against the slice count.

Generates a preset at --size (default 1024x1024, 1 MP) with 10 and 40 slices, each in a fresh
subprocess, and prints wall time, time per slice and peak RSS. The goal: 1 MP x 40 slices in
under 20 s on this 2-core machine, and peak memory independent of the slice count.

Run:  python pipelines/bench_synth.py [--preset nd] [--size 1024x1024] [--slices 10 40]
"""

from __future__ import annotations

import json
import subprocess
import sys
import tempfile

from _shared import md_header, md_row, parser

CHILD = r"""
import json, resource, sys, time
from microfacet.forward.synth import generate_stack, preset
name, h, w, k, out = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), int(sys.argv[4]), sys.argv[5]
t0 = time.perf_counter()
r = generate_stack(out, preset(name, seed=1, height_px=h, width_px=w, n_slices=k))
dt = time.perf_counter() - t0
rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
print(json.dumps({"total_s": dt, "scene_s": r.timings_s["scene"], "slices_s": r.timings_s["slices"],
                  "peak_rss_mb": rss}))
"""


def main(argv=None):
    ap = parser(__doc__)
    ap.add_argument("--preset", default="nd")
    ap.add_argument("--size", default="1024x1024")
    ap.add_argument("--slices", type=int, nargs="+", default=[10, 40])
    args = ap.parse_args(argv)
    h, w = (int(v) for v in args.size.split("x"))
    print(f"preset {args.preset}, {h}x{w} px\n")
    print(md_header(["slices", "total (s)", "scene (s)", "slices (s)", "per slice (ms)",
                     "peak RSS (MB)"]))
    for k in args.slices:
        with tempfile.TemporaryDirectory() as tmp:
            out = subprocess.run([sys.executable, "-c", CHILD, args.preset, str(h), str(w), str(k),
                                  f"{tmp}/s"], capture_output=True, text=True, check=True)
        r = json.loads(out.stdout.strip().splitlines()[-1])
        print(md_row([k, f"{r['total_s']:.2f}", f"{r['scene_s']:.2f}", f"{r['slices_s']:.2f}",
                      f"{1000 * r['slices_s'] / k:.0f}", f"{r['peak_rss_mb']:.0f}"]), flush=True)


if __name__ == "__main__":
    main()
