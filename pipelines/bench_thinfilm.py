"""Benchmark: thin-film reflectance throughput and accuracy, microfacet vs colour-science vs tmm.

One grid: 81 wavelengths (380-780 nm) x 90 angles (0-89 deg) x 301 thicknesses (0-600 nm),
film = the default anodic TiO2, substrate = Ti (Johnson & Christy). Every method is timed
in the same run (best of --repeat) and compared against ``tmm.coh_tmm`` on a random
subsample of grid points (tmm is a per-point Python loop, so it is timed on the subsample
and its throughput extrapolated).

Run:  python pipelines/bench_thinfilm.py [--repeat 3] [--tmm-points 2000]
Prints a markdown table (copy it into docs/benchmarks.md).
"""

from __future__ import annotations

import os

import numpy as np
from _shared import best_of, md_header, md_row, parser


def main(argv=None):
    ap = parser(__doc__, repeat=3)
    ap.add_argument("--tmm-points", type=int, default=2000)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)

    import colour.phenomena
    import tmm

    from microfacet.optics import DEFAULT_FILM, DEFAULT_SUBSTRATE, optical_constants
    from microfacet.optics.thinfilm import num_threads, reflectance

    wl = np.linspace(380.0, 780.0, 81)
    theta = np.linspace(0.0, 89.0, 90)
    d = np.linspace(0.0, 600.0, 301)
    n1 = optical_constants(DEFAULT_FILM, wl)
    n2 = optical_constants(DEFAULT_SUBSTRATE, wl)
    n_evals = wl.size * theta.size * d.size

    rng = np.random.default_rng(args.seed)
    pick = np.stack([rng.integers(0, s, args.tmm_points) for s in (wl.size, theta.size, d.size)], 1)

    def run_tmm():
        out = np.empty(len(pick))
        for j, (i, a, t) in enumerate(pick):
            rs = tmm.coh_tmm("s", [1.0, n1[i], n2[i]], [np.inf, d[t], np.inf],
                             np.deg2rad(theta[a]), wl[i])["R"]
            rp = tmm.coh_tmm("p", [1.0, n1[i], n2[i]], [np.inf, d[t], np.inf],
                             np.deg2rad(theta[a]), wl[i])["R"]
            out[j] = 0.5 * (rs + rp)
        return out

    def run_microfacet():
        return reflectance(wl[:, None, None], theta[None, :, None], d[None, None, :],
                           n1[:, None, None], n2[:, None, None])

    def run_microfacet_1thread():
        old = os.environ.get("MICROFACET_NUM_THREADS")
        os.environ["MICROFACET_NUM_THREADS"] = "1"
        try:
            return run_microfacet()
        finally:
            if old is None:
                del os.environ["MICROFACET_NUM_THREADS"]
            else:
                os.environ["MICROFACET_NUM_THREADS"] = old

    def run_microfacet_f32():
        return reflectance(wl[:, None, None], theta[None, :, None], d[None, None, :],
                           n1[:, None, None], n2[:, None, None], dtype=np.float32)

    n_stack = np.stack([np.ones_like(n1), n1, n2])  # (3, W)

    def run_colour():
        R, _ = colour.phenomena.thin_film_tmm(n_stack, d, wl, theta)  # (W, A, T, 2)
        return R.mean(axis=-1)

    t_tmm, r_tmm = best_of(run_tmm, 1)
    rows = []
    ours = "microfacet.optics.thinfilm.reflectance"
    for name, fn in [
        (f"{ours} (float64, 1 thread)", run_microfacet_1thread),
        (f"{ours} (float64, {num_threads()} threads)", run_microfacet),
        (f"{ours} (float32 out)", run_microfacet_f32),
        (f"colour.phenomena.thin_film_tmm {colour.__version__}", run_colour),
    ]:
        t, R = best_of(fn, args.repeat)
        sub = R[pick[:, 0], pick[:, 1], pick[:, 2]]
        rows.append((name, t, n_evals / t, float(np.max(np.abs(sub - r_tmm)))))
    rows.append(("tmm.coh_tmm (s + p, per point)", t_tmm * n_evals / len(pick),
                 len(pick) / t_tmm, None))

    base = rows[3][2]  # colour-science throughput
    print(f"grid: {wl.size} wavelengths x {theta.size} angles x {d.size} thicknesses = "
          f"{n_evals:,} unpolarised evaluations; film {DEFAULT_FILM}, substrate "
          f"{DEFAULT_SUBSTRATE}; max |dR| vs tmm on {len(pick)} random grid points\n")
    print(md_header(["method", "time for grid (s)", "evaluations/s",
                     "throughput vs colour-science", "max abs dR vs tmm"]))
    for name, t, rate, err in rows:
        err_s = "(reference)" if err is None else f"{err:.1e}"
        print(md_row([name, f"{t:.3f}", f"{rate:,.0f}", f"{rate / base:.3g}x", err_s]))


if __name__ == "__main__":
    main()
