"""Synthetic-stack generation: time and peak memory against the slice count.

Generates a preset at ``size`` (default 1024x1024, 1 MP) with 10 and 40 slices, each in a
fresh subprocess, and tabulates wall time, time per slice and peak RSS. The goal: 1 MP × 40
slices in under 20 s on the 2-core development machine, and peak memory independent of the
slice count.
"""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

from pipelines import Study
from pipelines._shared import md_table, note

STUDY = Study(
    name="speed-synth",
    question="How long does a synthetic stack take to generate, and does its memory grow "
             "with the slices?",
    doc=("docs/benchmarks.md", "speed-synth"),
    run_time="30 s",
    quick_time="10 s",
    options={"preset": ("nd", "synthetic preset"),
             "size": ("1024x1024", "HxW in px"),
             "slices": ("10,40", "slice counts, comma-separated")},
)

CHILD = r"""
import json, resource, sys, time
from microfacet.forward.synth import generate_stack, preset
name, h, w, k, out = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), int(sys.argv[4]), sys.argv[5]
t0 = time.perf_counter()
r = generate_stack(out, preset(name, seed=1, height_px=h, width_px=w, n_slices=k))
dt = time.perf_counter() - t0
rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
print(json.dumps({"total_s": dt, "scene_s": r.timings_s["scene"],
                  "slices_s": r.timings_s["slices"], "peak_rss_mb": rss}))
"""


def run(*, quick: bool, out: Path, preset="nd", size="1024x1024", slices="10,40") -> str:
    h, w = (int(v) for v in size.lower().split("x"))
    counts = [int(k) for k in slices.split(",")]
    if quick:
        h, w, counts = min(h, 128), min(w, 128), [4, 8]
    note(f"preset {preset}, {h}x{w} px")
    rows = []
    for k in counts:
        folder = out / f"stack-{k}"
        shutil.rmtree(folder, ignore_errors=True)
        res = subprocess.run([sys.executable, "-c", CHILD, preset, str(h), str(w), str(k),
                              str(folder)], capture_output=True, text=True, check=True)
        shutil.rmtree(folder, ignore_errors=True)
        r = json.loads(res.stdout.strip().splitlines()[-1])
        rows.append([k, f"{r['total_s']:.2f}", f"{r['scene_s']:.2f}", f"{r['slices_s']:.2f}",
                     f"{1000 * r['slices_s'] / k:.0f}", f"{r['peak_rss_mb']:.0f}"])
        note(" | ".join(map(str, rows[-1])))
    return md_table(["slices", "total (s)", "scene (s)", "slices (s)", "per slice (ms)",
                     "peak RSS (MB)"], rows)
