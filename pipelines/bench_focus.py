"""Benchmark of the height-from-focus step (microfacet.focus.height).

Writes a synthetic RGB JPEG stack (a random texture blurred by a depth-dependent defocus) of
``--size`` pixels with 10 and 40 slices into a temporary folder, then measures in the same run:

* decode only: ``Stack.read_slice(i, uint8)`` over every slice (what any reader must pay);
* decode + conversion to float32 (what the height step consumes);
* the whole height step (``height_from_focus``: decode, focus measure, running peak, fit,
  reliability, composite) for each operator, with the default options;
* ms per megapixel per slice, and the ratio height-step / decode-only;
* peak memory of the whole height step for 10 and 40 slices, each in a fresh subprocess:
  ``tracemalloc`` peak (Python + NumPy allocations) and the process's max RSS.

Usage::

    python pipelines/bench_focus.py [--size 1024] [--repeat 3] [--json out.json]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np


def make_stack(folder: Path, n: int, size: int, seed: int = 0) -> Path:
    import cv2

    from microfacet.io.stack import write_stack

    rng = np.random.default_rng(seed)
    tex = cv2.GaussianBlur(rng.random((size, size, 3)).astype(np.float32), (0, 0), 1.0)
    tex = (tex - tex.mean()) / tex.std() * 0.15 + 0.5
    yy, xx = np.mgrid[0:size, 0:size]
    height = (n - 1) * (0.5 + 0.4 * np.sin(xx / size * 6.0) * np.cos(yy / size * 4.0))

    def images():
        for k in range(n):
            # two blur levels blended by the distance to focus: cheap space-variant defocus
            d = np.clip(np.abs(k - height) / 4.0, 0, 1).astype(np.float32)[..., None]
            sharp = tex
            blur = cv2.GaussianBlur(tex, (0, 0), 3.0)
            yield np.clip((1 - d) * sharp + d * blur, 0, 1).__mul__(255).round().astype(np.uint8)

    return write_stack(folder, images(), pixel_size_um=0.5, z_step_um=1.0, fmt="jpg")


def time_decode(stack, dtype) -> float:
    t = time.perf_counter()
    for i in range(stack.n_slices):
        stack.read_slice(i, dtype)
    return time.perf_counter() - t


def child_memory(folder: str) -> None:
    """Run in a subprocess: the height step with tracemalloc; print JSON."""
    import resource
    import tracemalloc

    from microfacet.focus.height import height_from_focus
    from microfacet.io.stack import read_stack

    st = read_stack(folder)
    tracemalloc.start()
    height_from_focus(st)
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024
    print(json.dumps({"tracemalloc_peak_mb": peak / 2**20, "max_rss_mb": rss / 2**20}))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", type=int, default=1024, help="image side in pixels")
    ap.add_argument("--repeat", type=int, default=3, help="best of N timings")
    ap.add_argument("--json", type=Path, default=None, help="also write the numbers here")
    ap.add_argument("--child", default=None, help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.child:
        child_memory(args.child)
        return 0

    from microfacet.focus.height import OPERATORS, height_from_focus
    from microfacet.io.stack import read_stack

    out = {"size": args.size, "cpus": os.cpu_count(), "runs": {}}
    with tempfile.TemporaryDirectory() as tmp:
        folders = {}
        for n in (10, 40):
            folders[n] = Path(tmp) / f"s{n}"
            make_stack(folders[n], n, args.size)
        mp = args.size * args.size / 1e6
        rows = []
        for n_sl in (10, 40):
            st = read_stack(folders[n_sl])
            n = st.n_slices
            dec = min(time_decode(st, np.uint8) for _ in range(args.repeat))
            dec_f = min(time_decode(st, np.float32) for _ in range(args.repeat))
            out[f"decode_ms_per_mp_slice_{n}"] = 1e3 * dec / (mp * n)
            out[f"decode_float32_ms_per_mp_slice_{n}"] = 1e3 * dec_f / (mp * n)
            for op in OPERATORS:
                best = None
                for _ in range(args.repeat):
                    t = time.perf_counter()
                    res = height_from_focus(st, operator=op)
                    dt = time.perf_counter() - t
                    if best is None or dt < best[0]:
                        best = (dt, res.timings_s)
                dt, tim = best
                rows.append({"operator": op, "slices": n, "total_s": dt,
                             "ms_per_mp_slice": 1e3 * dt / (mp * n),
                             "ratio_to_decode": dt / dec,
                             "fit_ms_per_mp": 1e3 * tim["fit"] / mp,
                             "streaming_ms_per_mp_slice": 1e3 * (dt - tim["fit"]) / (mp * n)})
        out["operators"] = rows
        mem = {}
        for k, folder in folders.items():
            r = subprocess.run([sys.executable, __file__, "--child", str(folder)],
                               capture_output=True, text=True, check=True)
            mem[k] = json.loads(r.stdout.strip().splitlines()[-1])
        out["memory"] = mem

    print(f"stack: {args.size}x{args.size} RGB JPEG, {os.cpu_count()} CPUs, best of {args.repeat}")
    print()
    print("| slices | step | ms / MP / slice | × decode | of which per-slice streaming "
          "(ms / MP / slice) | peak fit (ms / MP, once) |")
    print("|---|---|---|---|---|---|")
    for n in (10, 40):
        d = out[f"decode_ms_per_mp_slice_{n}"]
        print(f"| {n} | decode only (uint8) | {d:.1f} | 1.00 | | |")
        print(f"| {n} | decode + float32 | {out[f'decode_float32_ms_per_mp_slice_{n}']:.1f} | "
              f"{out[f'decode_float32_ms_per_mp_slice_{n}'] / d:.2f} | | |")
        for r in rows:
            if r["slices"] == n:
                print(f"| {n} | height step, {r['operator']} | {r['ms_per_mp_slice']:.1f} | "
                      f"{r['ratio_to_decode']:.2f} | {r['streaming_ms_per_mp_slice']:.1f} | "
                      f"{r['fit_ms_per_mp']:.0f} |")
    print()
    print("| slices | tracemalloc peak (MB) | max RSS (MB) |")
    print("|---|---|---|")
    for k in (10, 40):
        print(f"| {k} | {mem[k]['tracemalloc_peak_mb']:.1f} | {mem[k]['max_rss_mb']:.1f} |")
    if args.json:
        args.json.write_text(json.dumps(out, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
