"""Benchmark of the height-from-focus step (microfacet.focus.height).

Writes a synthetic RGB JPEG stack (a random texture blurred by a depth-dependent defocus) of
``--size`` pixels with 10 and 40 slices into a temporary folder, then measures in the same run:

* decode only: ``Stack.read_slice(i, uint8)`` over every slice (what any reader must pay);
* decode + conversion to float32 (what the height step consumes);
* the whole height step (``height_from_focus``: decode, focus measure, running peak, fit,
  uncertainty, reliability, composite) for each operator, with the default options and with
  the options of the earlier default (``EARLIER_DEFAULT``: Gaussian fit, one 7-px window,
  Pertuz reliability), interleaved so that both see the same machine load;
* ms per megapixel per slice, the ratio height-step / decode-only and new / earlier;
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
from pathlib import Path

import numpy as np
from _shared import best_of, md_header, md_row, parser


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


def decode(stack, dtype) -> None:
    for i in range(stack.n_slices):
        stack.read_slice(i, dtype)


def child_memory(folder: str, earlier: bool) -> None:
    """Run in a subprocess: the height step with tracemalloc; print JSON."""
    import resource
    import tracemalloc

    from microfacet.focus.height import height_from_focus
    from microfacet.focus.options import EARLIER_DEFAULT
    from microfacet.io.stack import read_stack

    st = read_stack(folder)
    tracemalloc.start()
    height_from_focus(st, EARLIER_DEFAULT if earlier else None)
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024
    print(json.dumps({"tracemalloc_peak_mb": peak / 2**20, "max_rss_mb": rss / 2**20}))


def main(argv=None) -> int:
    ap = parser(__doc__, repeat=3)
    ap.add_argument("--size", type=int, default=1024, help="image side in pixels")
    ap.add_argument("--json", type=Path, default=None, help="also write the numbers here")
    ap.add_argument("--child", default=None, help=argparse.SUPPRESS)
    ap.add_argument("--child-earlier", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.child:
        child_memory(args.child, args.child_earlier)
        return 0

    from microfacet.focus.height import height_from_focus
    from microfacet.focus.options import EARLIER_DEFAULT, OPERATORS, FocusOptions
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
            dec, _ = best_of(lambda: decode(st, np.uint8), args.repeat)
            dec_f, _ = best_of(lambda: decode(st, np.float32), args.repeat)
            out[f"decode_ms_per_mp_slice_{n}"] = 1e3 * dec / (mp * n)
            out[f"decode_float32_ms_per_mp_slice_{n}"] = 1e3 * dec_f / (mp * n)
            for op in OPERATORS:
                best = {}
                for _ in range(max(1, args.repeat)):      # interleaved: same load for both
                    for label, opts in (("earlier", EARLIER_DEFAULT),
                                        ("default", FocusOptions())):
                        opts = opts.replace(operator=op)
                        dt, res = best_of(lambda: height_from_focus(st, opts), 1)
                        if label not in best or dt < best[label][0]:
                            best[label] = (dt, res)
                for label in ("earlier", "default"):
                    dt, res = best[label]
                    tim = res.timings_s
                    rows.append({"operator": op, "options": label, "slices": n, "total_s": dt,
                                 "ms_per_mp_slice": 1e3 * dt / (mp * n),
                                 "ratio_to_decode": dt / dec,
                                 "ratio_to_earlier": dt / best["earlier"][0],
                                 "fit_ms_per_mp": 1e3 * tim["fit"] / mp,
                                 "streaming_ms_per_mp_slice": 1e3 * (dt - tim["fit"])
                                 / (mp * n)})
        out["operators"] = rows
        mem = {}
        for k, folder in folders.items():
            for label, extra in (("earlier", ["--child-earlier"]), ("default", [])):
                r = subprocess.run([sys.executable, __file__, "--child", str(folder)] + extra,
                                   capture_output=True, text=True, check=True)
                mem[(k, label)] = json.loads(r.stdout.strip().splitlines()[-1])
        out["memory"] = {f"{k}-{lab}": v for (k, lab), v in mem.items()}

    print(f"stack: {args.size}x{args.size} RGB JPEG, {os.cpu_count()} CPUs, best of {args.repeat}")
    print()
    print(md_header(["slices", "step", "ms / MP / slice", "× decode", "× earlier",
                     "of which per-slice streaming (ms / MP / slice)",
                     "peak fit (ms / MP, once)"]))
    for n in (10, 40):
        d = out[f"decode_ms_per_mp_slice_{n}"]
        df = out[f"decode_float32_ms_per_mp_slice_{n}"]
        print(md_row([n, "decode only (uint8)", f"{d:.1f}", "1.00", "", "", ""]))
        print(md_row([n, "decode + float32", f"{df:.1f}", f"{df / d:.2f}", "", "", ""]))
        for r in rows:
            if r["slices"] == n:
                print(md_row([n, f"height step, {r['operator']}, {r['options']}",
                              f"{r['ms_per_mp_slice']:.1f}", f"{r['ratio_to_decode']:.2f}",
                              f"{r['ratio_to_earlier']:.2f}",
                              f"{r['streaming_ms_per_mp_slice']:.1f}",
                              f"{r['fit_ms_per_mp']:.0f}"]))
    print()
    print(md_header(["slices", "options", "tracemalloc peak (MB)", "max RSS (MB)"]))
    for (k, label), v in mem.items():
        print(md_row([k, label, f"{v['tracemalloc_peak_mb']:.1f}", f"{v['max_rss_mb']:.1f}"]))
    if args.json:
        args.json.write_text(json.dumps(out, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
