"""Benchmark CIEDE2000: microfacet (float64, float32) vs colour-science vs scikit-image.

Usage::

    python pipelines/bench_color.py [--n 1000000] [--repeat 3] [--seed 0]

Prints a markdown table: best-of-``repeat`` wall time scaled to 1e6 pairs, pairs/s,
ratio of each method's time to microfacet float64, and max |ΔE - colour's ΔE| on the
same random Lab pairs (float32 rows: against colour on the float32-rounded inputs).
Half the pairs are near each other (ΔLab ~ N(0, 5)), half independent.
"""

from __future__ import annotations

import argparse
import platform
import time
import warnings

import numpy as np


def _pairs(n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)

    def lab(k):
        return np.column_stack(
            [rng.uniform(0, 100, k), rng.uniform(-128, 128, k), rng.uniform(-128, 128, k)]
        )

    lab1 = lab(n)
    half = n // 2
    lab2 = np.concatenate([lab1[:half] + rng.normal(0, 5, (half, 3)), lab(n - half)])
    return lab1, lab2


def _best(fn, repeat: int) -> tuple[float, np.ndarray]:
    best, out = float("inf"), None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return best, out


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--n", type=int, default=1_000_000, help="number of Lab pairs")
    parser.add_argument("--repeat", type=int, default=3, help="repeats (best is kept)")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)
    if args.n < 1 or args.repeat < 1:
        parser.error("--n and --repeat must be >= 1")

    import colour
    import skimage
    from skimage.color import deltaE_ciede2000

    from microfacet.colour import delta_e_2000

    lab1, lab2 = _pairs(args.n, args.seed)
    lab1_32, lab2_32 = lab1.astype(np.float32), lab2.astype(np.float32)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ref = colour.delta_E(lab1, lab2, method="CIE 2000")
        ref32 = colour.delta_E(
            lab1_32.astype(np.float64), lab2_32.astype(np.float64), method="CIE 2000"
        )

    methods = [
        ("microfacet float64", lambda: delta_e_2000(lab1, lab2), ref),
        ("microfacet float32", lambda: delta_e_2000(lab1_32, lab2_32), ref32),
        (
            f"colour-science {colour.__version__}",
            lambda: colour.delta_E(lab1, lab2, method="CIE 2000"),
            ref,
        ),
        (f"scikit-image {skimage.__version__}", lambda: deltaE_ciede2000(lab1, lab2), ref),
    ]
    rows = []
    for name, fn, reference in methods:
        seconds, out = _best(fn, args.repeat)
        err = float(np.max(np.abs(np.asarray(out, dtype=np.float64) - reference)))
        rows.append((name, seconds, err))

    base = rows[0][1]
    scale = 1e6 / args.n
    print(
        f"n = {args.n} pairs, best of {args.repeat}; numpy {np.__version__}, "
        f"Python {platform.python_version()}, {platform.machine()}"
    )
    print()
    print("| method | ms per 1e6 pairs | pairs/s | time ratio vs microfacet float64 "
          "| max abs(dE - colour dE) |")
    print("|---|---:|---:|---:|---:|")
    for name, seconds, err in rows:
        print(
            f"| {name} | {seconds * 1e3 * scale:.1f} | {args.n / seconds:.3g} | "
            f"{seconds / base:.2f} | {err:.1e} |"
        )


if __name__ == "__main__":
    main()
