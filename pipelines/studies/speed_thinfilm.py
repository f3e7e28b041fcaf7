"""Thin-film reflectance throughput and accuracy: microfacet against colour-science and tmm.

One grid: 81 wavelengths (380-780 nm) × 90 angles (0-89°) × 301 thicknesses (0-600 nm), film
the default anodic TiO2, substrate Ti (Johnson & Christy). Every method is timed in the same
run (best of ``repeat``) and compared against ``tmm.coh_tmm`` on a random subsample of grid
points (tmm is a per-point Python loop, so it is timed on the subsample and its throughput
extrapolated). The one-thread row limits microfacet's pool with
:func:`microfacet.core.threads.limited_threads`.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from pipelines import Study
from pipelines._shared import best_of, md_table, note

STUDY = Study(
    name="speed-thinfilm",
    question="How fast and how exact is microfacet's thin-film reflectance against "
             "colour-science and tmm?",
    doc=("docs/benchmarks.md", "speed-thinfilm"),
    run_time="1 min",
    quick_time="5 s",
    options={"repeat": (5, "timing repeats (the minimum is kept)"),
             "tmm_points": (2000, "random grid points evaluated by tmm"),
             "seed": (0, "seed of the tmm subsample")},
)


def run(*, quick: bool, out: Path, repeat=5, tmm_points=2000, seed=0) -> str:
    import colour
    import colour.phenomena
    import tmm

    from microfacet.core.threads import limited_threads, num_threads
    from microfacet.optics import DEFAULT_FILM, DEFAULT_SUBSTRATE, optical_constants
    from microfacet.optics.thinfilm import reflectance

    if quick:
        repeat, tmm_points = 1, min(tmm_points, 200)
    wl = np.linspace(380.0, 780.0, 81)
    theta = np.linspace(0.0, 89.0, 90)
    d = np.linspace(0.0, 600.0, 61 if quick else 301)
    n1 = optical_constants(DEFAULT_FILM, wl)
    n2 = optical_constants(DEFAULT_SUBSTRATE, wl)
    n_evals = wl.size * theta.size * d.size
    rng = np.random.default_rng(seed)
    pick = np.stack([rng.integers(0, s, tmm_points) for s in (wl.size, theta.size, d.size)], 1)

    def run_tmm():
        out_ = np.empty(len(pick))
        for j, (i, a, t) in enumerate(pick):
            layers = [1.0, n1[i], n2[i]], [np.inf, d[t], np.inf]
            rs = tmm.coh_tmm("s", *layers, np.deg2rad(theta[a]), wl[i])["R"]
            rp = tmm.coh_tmm("p", *layers, np.deg2rad(theta[a]), wl[i])["R"]
            out_[j] = 0.5 * (rs + rp)
        return out_

    def run_microfacet(dtype=np.float64):
        return reflectance(wl[:, None, None], theta[None, :, None], d[None, None, :],
                           n1[:, None, None], n2[:, None, None], dtype=dtype)

    def run_microfacet_1thread():
        with limited_threads(1):
            return run_microfacet()

    n_stack = np.stack([np.ones_like(n1), n1, n2])  # (3, W)

    def run_colour():
        R, _ = colour.phenomena.thin_film_tmm(n_stack, d, wl, theta)  # (W, A, T, 2)
        return R.mean(axis=-1)

    note(f"tmm on {len(pick)} points …")
    t_tmm, r_tmm = best_of(run_tmm, 1)
    ours = "microfacet.optics.thinfilm.reflectance"
    rows = []
    for name, fn in [
        (f"{ours} (float64, 1 thread)", run_microfacet_1thread),
        (f"{ours} (float64, {num_threads()} threads)", run_microfacet),
        (f"{ours} (float32 out)", lambda: run_microfacet(np.float32)),
        (f"colour.phenomena.thin_film_tmm {colour.__version__}", run_colour),
    ]:
        t, R = best_of(fn, repeat)
        sub = R[pick[:, 0], pick[:, 1], pick[:, 2]]
        rows.append((name, t, n_evals / t, float(np.max(np.abs(sub - r_tmm)))))
        note(f"{name}: {t:.3f} s")
    rows.append(("tmm.coh_tmm (s + p, per point)", t_tmm * n_evals / len(pick),
                 len(pick) / t_tmm, None))
    base = rows[3][2]  # colour-science throughput
    note(f"grid: {wl.size} wavelengths × {theta.size} angles × {d.size} thicknesses = "
         f"{n_evals:,} unpolarised evaluations; film {DEFAULT_FILM}, substrate "
         f"{DEFAULT_SUBSTRATE}; max |dR| vs tmm on {len(pick)} random grid points")
    return md_table(["method", "time for grid (s)", "evaluations/s",
                     "throughput vs colour-science", "max abs dR vs tmm"],
                    [[name, f"{t:.3f}", f"{rate:,.0f}", f"{rate / base:.3g}x",
                      "(reference)" if err is None else f"{err:.1e}"]
                     for name, t, rate, err in rows])
