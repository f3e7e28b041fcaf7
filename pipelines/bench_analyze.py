"""Benchmark: `microfacet analyze` against decoding its slices, at 1, 4 and 12 megapixels.

For each size an nd-preset stack of ``--slices`` slices is generated (cached in ``--work``),
then, in one run on the same machine:

- **decode**: reading and decoding every slice alone (``Stack.read_slice``), the baseline;
- **analyze**: the whole ``microfacet analyze STACK --out OUT`` command, report included, in
  a fresh process (imports included), its wall time and peak RSS (``os.wait4``), and the
  per-stage ``timings_s`` of its summary.json.

Ratios to the decode time of the same run are what docs/benchmarks.md quotes (this machine is
shared and noisy); ``--repeat`` keeps the fastest of several runs.

Run::

    python pipelines/bench_analyze.py [--sizes 1,4,12] [--slices 40] [--work DIR] [--repeat 1]
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from _shared import best_of, md_header, md_row, parser

#: The targets of the speed issue (docs/benchmarks.md).
TARGET_STAGES_X = 4.0       # analysis stages together / decode
TARGET_WHOLE_X_1MP = 8.0    # whole analyze, report included / decode, at 1 MP
TARGET_RSS_1MP_MB = 500.0
TARGET_RSS_PER_MP_MB = 150.0
TARGET_12MP_S = 60.0
TARGET_12MP_MB = 3000.0

STAGES = ("height_from_focus", "normals", "colour_and_mask", "colour_table", "thickness_roi",
          "segmentation", "facet_fits", "tilt_per_pixel", "mixtures")


def stack_for(work: Path, mp: float, slices: int) -> Path:
    side = int(round(np.sqrt(mp * 1e6) / 16.0)) * 16
    path = work / f"nd-{side}x{side}-{slices}"
    if not (path / "stack.json").is_file():
        from microfacet.forward.synth import generate_stack, preset
        generate_stack(path, preset("nd", seed=3, height_px=side, width_px=side,
                                    n_slices=slices))
    return path


def decode_time(path: Path) -> float:
    from microfacet.io.limits import Limits
    from microfacet.io.stack import read_stack
    st = read_stack(path, limits=Limits(max_megapixels=100, max_stack_megapixels=2000))

    def decode_all():
        for i in range(st.n_slices):
            st.read_slice(i, dtype=np.uint8)
    t, _ = best_of(decode_all, 2)
    return t


def run_analyze(path: Path, out: Path, extra=()):
    """Wall time (s), peak RSS (MB) and summary of one ``microfacet analyze`` process."""
    if out.exists():
        shutil.rmtree(out)
    cmd = [sys.executable, "-m", "microfacet", "analyze", str(path), "--out", str(out), "-q",
           "--max-megapixels", "100", "--max-stack-megapixels", "2000", *extra]
    t0 = time.perf_counter()
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - t0
    err = proc.stderr.read().decode(errors="replace")
    proc.stderr.close()
    if status != 0:
        raise SystemExit(f"analyze failed on {path}: {err.strip()}")
    summary = json.loads((out / "summary.json").read_text())
    return wall, usage.ru_maxrss / 1024.0, summary


def main(argv=None):
    ap = parser(__doc__)
    ap.add_argument("--sizes", default="1,4,12", help="megapixels, comma-separated")
    ap.add_argument("--slices", type=int, default=40)
    ap.add_argument("--work", type=Path, default=None, help="cache folder for the stacks")
    ap.add_argument("--repeat", type=int, default=1, help="runs per size (fastest kept)")
    args = ap.parse_args(argv)
    sizes = [float(s) for s in args.sizes.split(",")]
    work = args.work or Path(tempfile.mkdtemp(prefix="bench-analyze-"))
    work.mkdir(parents=True, exist_ok=True)

    cols = {}
    for mp in sizes:
        path = stack_for(work, mp, args.slices)
        dec = decode_time(path)
        best = None
        for _ in range(max(1, args.repeat)):
            res = run_analyze(path, work / f"out-{path.name}")
            if best is None or res[0] < best[0]:
                best = res
        wall, rss, summary = best
        t = summary["timings_s"]
        h, w = summary["inputs"]["shape"]
        cols[mp] = dict(mp=h * w / 1e6, decode=dec, wall=wall, rss=rss, t=t,
                        stages=sum(t.get(k, 0.0) for k in STAGES))
        print(f"{path.name}: decode {dec:.2f} s, analyze {wall:.1f} s, peak RSS {rss:.0f} MB",
              file=sys.stderr, flush=True)

    names = [f"{c['mp']:.1f} MP" for c in cols.values()]
    print(f"nd preset, {args.slices} slices, `microfacet analyze` in a fresh process "
          f"(python {sys.version.split()[0]}, {os.cpu_count()} cores)\n")
    print(md_header(["", *[f"{n} (s)" for n in names], *[f"{n} (× decode)" for n in names]]))
    print(md_row(["decode the slices", *[f"{c['decode']:.2f}" for c in cols.values()],
                  *["1.0" for _ in cols]]))
    for k in STAGES + ("write", "report"):
        vals = [c["t"].get(k) for c in cols.values()]
        print(md_row([k, *["" if v is None else f"{v:.2f}" for v in vals],
                      *["" if v is None else f"{v / c['decode']:.2f}"
                        for v, c in zip(vals, cols.values())]]))
    print(md_row(["**analysis stages**", *[f"{c['stages']:.2f}" for c in cols.values()],
                  *[f"{c['stages'] / c['decode']:.1f}" for c in cols.values()]]))
    print(md_row(["**whole command (wall)**", *[f"{c['wall']:.2f}" for c in cols.values()],
                  *[f"{c['wall'] / c['decode']:.1f}" for c in cols.values()]]))
    print(md_row(["peak RSS (MB)", *[f"{c['rss']:.0f}" for c in cols.values()],
                  *["" for _ in cols]]))

    print("\ntargets:")
    c = list(cols.values())
    for col in c:
        ok = col["stages"] / col["decode"] <= TARGET_STAGES_X
        print(f"  {col['mp']:.1f} MP: analysis stages {col['stages'] / col['decode']:.1f}x "
              f"decode (target <= {TARGET_STAGES_X:g}x) {'met' if ok else 'MISSED'}")
    one = min(c, key=lambda x: abs(x["mp"] - 1.0))
    if abs(one["mp"] - 1.0) < 0.2:
        x = one["wall"] / one["decode"]
        print(f"  1 MP: whole command {x:.1f}x decode (target <= {TARGET_WHOLE_X_1MP:g}x) "
              f"{'met' if x <= TARGET_WHOLE_X_1MP else 'MISSED'}")
        print(f"  1 MP: peak RSS {one['rss']:.0f} MB (target <= {TARGET_RSS_1MP_MB:g}) "
              f"{'met' if one['rss'] <= TARGET_RSS_1MP_MB else 'MISSED'}")
    if len(c) > 1:
        slope = np.polyfit([x["mp"] for x in c], [x["rss"] for x in c], 1)[0]
        print(f"  RSS growth {slope:.0f} MB per MP (target <= {TARGET_RSS_PER_MP_MB:g}) "
              f"{'met' if slope <= TARGET_RSS_PER_MP_MB else 'MISSED'}")
    big = max(c, key=lambda x: x["mp"])
    if big["mp"] > 10:
        ok = big["wall"] < TARGET_12MP_S and big["rss"] < TARGET_12MP_MB
        print(f"  {big['mp']:.1f} MP: {big['wall']:.0f} s and {big['rss']:.0f} MB (target < "
              f"{TARGET_12MP_S:g} s and < {TARGET_12MP_MB:g} MB) {'met' if ok else 'MISSED'}")


if __name__ == "__main__":
    main()
