"""The height-from-focus step (microfacet.focus.height) against decoding its slices.

Writes a synthetic RGB JPEG stack (a random texture blurred by a depth-dependent defocus) of
``size`` pixels with 10 and 40 slices into ``out``, then measures in the same run:

* decode only: ``Stack.read_slice(i, uint8)`` over every slice (what any reader must pay);
* decode + conversion to float32 (what the height step consumes);
* the whole height step (``height_from_focus``: decode, focus measure, running peak, fit,
  uncertainty, reliability, composite) for each operator, with the default options and with
  the options of the earlier default (``EARLIER_DEFAULT``: Gaussian fit, one 7-px window,
  Pertuz reliability), interleaved so that both see the same machine load;
* ms per megapixel per slice, the ratio height-step / decode-only and new / earlier;
* peak memory of the whole height step for 10 and 40 slices, each in a fresh subprocess:
  ``tracemalloc`` peak (Python + NumPy allocations) and the process's max RSS.

The numbers are also written to ``out/speed-focus.json``.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np

from pipelines import Study
from pipelines._shared import best_of, md_table, note

STUDY = Study(
    name="speed-focus",
    question="What does height from focus cost against decoding the slices, in time and "
             "memory, for the default and the earlier options?",
    doc=("docs/benchmarks.md", "speed-focus"),
    run_time="3 min",
    quick_time="13 s",
    options={"size": (1024, "image side in pixels"),
             "repeat": (3, "timing repeats (the minimum is kept)")},
)

#: The peak memory of one height step, in a fresh interpreter: argv = folder, "earlier" or
#: "default"; prints JSON.
CHILD = r"""
import json, resource, sys, tracemalloc
from microfacet.focus.height import height_from_focus
from microfacet.focus.options import EARLIER_DEFAULT
from microfacet.io.stack import read_stack
st = read_stack(sys.argv[1])
tracemalloc.start()
height_from_focus(st, EARLIER_DEFAULT if sys.argv[2] == "earlier" else None)
peak = tracemalloc.get_traced_memory()[1]
tracemalloc.stop()
rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024
print(json.dumps({"tracemalloc_peak_mb": peak / 2**20, "max_rss_mb": rss / 2**20}))
"""


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


def run(*, quick: bool, out: Path, size=1024, repeat=3) -> str:
    from microfacet.focus.height import height_from_focus
    from microfacet.focus.options import EARLIER_DEFAULT, OPERATORS, FocusOptions
    from microfacet.io.stack import read_stack

    counts = (5, 10) if quick else (10, 40)
    if quick:
        size, repeat = min(size, 128), 1
    res = {"size": size, "cpus": os.cpu_count(), "runs": {}}
    work = out / "stacks"
    shutil.rmtree(work, ignore_errors=True)
    folders = {}
    for n in counts:
        folders[n] = work / f"s{n}"
        make_stack(folders[n], n, size)
    mp = size * size / 1e6
    rows = []
    for n_sl in counts:
        st = read_stack(folders[n_sl])
        n = st.n_slices
        dec, _ = best_of(lambda: decode(st, np.uint8), repeat)
        dec_f, _ = best_of(lambda: decode(st, np.float32), repeat)
        res[f"decode_ms_per_mp_slice_{n}"] = 1e3 * dec / (mp * n)
        res[f"decode_float32_ms_per_mp_slice_{n}"] = 1e3 * dec_f / (mp * n)
        for op in OPERATORS:
            best = {}
            for _ in range(max(1, repeat)):      # interleaved: same load for both
                for label, opts in (("earlier", EARLIER_DEFAULT), ("default", FocusOptions())):
                    opts = opts.replace(operator=op)
                    dt, r = best_of(lambda: height_from_focus(st, opts), 1)
                    if label not in best or dt < best[label][0]:
                        best[label] = (dt, r)
            for label in ("earlier", "default"):
                dt, r = best[label]
                tim = r.timings_s
                rows.append({"operator": op, "options": label, "slices": n, "total_s": dt,
                             "ms_per_mp_slice": 1e3 * dt / (mp * n),
                             "ratio_to_decode": dt / dec,
                             "ratio_to_earlier": dt / best["earlier"][0],
                             "fit_ms_per_mp": 1e3 * tim["fit"] / mp,
                             "streaming_ms_per_mp_slice": 1e3 * (dt - tim["fit"]) / (mp * n)})
            note(f"{n} slices, {op}: default {best['default'][0]:.2f} s, earlier "
                 f"{best['earlier'][0]:.2f} s, decode {dec:.2f} s")
    res["operators"] = rows
    mem = {}
    for k, folder in folders.items():
        for label in ("earlier", "default"):
            r = subprocess.run([sys.executable, "-c", CHILD, str(folder), label],
                               capture_output=True, text=True, check=True)
            mem[(k, label)] = json.loads(r.stdout.strip().splitlines()[-1])
    res["memory"] = {f"{k}-{lab}": v for (k, lab), v in mem.items()}
    (out / "speed-focus.json").write_text(json.dumps(res, indent=2) + "\n")
    shutil.rmtree(work, ignore_errors=True)

    note(f"stack: {size}x{size} RGB JPEG, {os.cpu_count()} CPUs, best of {repeat}")
    body = []
    for n in counts:
        d = res[f"decode_ms_per_mp_slice_{n}"]
        df = res[f"decode_float32_ms_per_mp_slice_{n}"]
        body.append([n, "decode only (uint8)", f"{d:.1f}", "1.00", "", "", ""])
        body.append([n, "decode + float32", f"{df:.1f}", f"{df / d:.2f}", "", "", ""])
        for r in rows:
            if r["slices"] == n:
                body.append([n, f"height step, {r['operator']}, {r['options']}",
                             f"{r['ms_per_mp_slice']:.1f}", f"{r['ratio_to_decode']:.2f}",
                             f"{r['ratio_to_earlier']:.2f}",
                             f"{r['streaming_ms_per_mp_slice']:.1f}",
                             f"{r['fit_ms_per_mp']:.0f}"])
    timing = md_table(["slices", "step", "ms / MP / slice", "× decode", "× earlier",
                       "of which per-slice streaming (ms / MP / slice)",
                       "peak fit (ms / MP, once)"], body)
    memory = md_table(["slices", "options", "tracemalloc peak (MB)", "max RSS (MB)"],
                      [[k, label, f"{v['tracemalloc_peak_mb']:.1f}", f"{v['max_rss_mb']:.1f}"]
                       for (k, label), v in mem.items()])
    return (f"{timing}\n\nPeak memory of the whole height step (fresh subprocess each):\n\n"
            f"{memory}")
