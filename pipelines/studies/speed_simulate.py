"""An in-plane 90 x 90 angular map (spectra + Lab + sRGB) with a 3-component thickness mixture
and a 2-lobe NDF, for the microfacet BRDF and seed eq. 6.

Baseline (measured in the same run): naive per-pair evaluation — for each (light, view)
pair, the thin-film reflectance over all the thickness nodes (and, for eq. 6, all tilt
terms) in one vectorised call per pair, no table reuse. It is timed on a subset of pairs
and extrapolated to 8100; the table gives the largest relative difference from the fast
path on that subset.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from microfacet.core.distributions import NDFMixture, ThicknessMixture
from microfacet.forward.angular import simulate_map
from microfacet.forward.brdf import default_wavelengths, microfacet_geometry, thickness_nodes
from microfacet.forward.eq6 import theta_m_grid
from microfacet.forward.halfvector import in_plane_directions
from microfacet.optics import DEFAULT_FILM, DEFAULT_SUBSTRATE
from microfacet.optics.thinfilm import reflectance
from pipelines import Study
from pipelines._shared import best_of, md_table, note

STUDY = Study(
    name="speed-simulate",
    question="How fast is a 90 × 90 angular map of the forward models against naive "
             "per-pair evaluation?",
    doc=("docs/benchmarks.md", "speed-simulate"),
    run_time="1 min",
    quick_time="5 s",
    options={"repeat": (5, "timing repeats (the minimum is kept)"),
             "subset": (180, "pairs timed for the naive baseline")},
)

G3 = ThicknessMixture([(0.3, 112.0, 3.0), (0.45, 130.0, 3.0), (0.25, 149.0, 3.0)])
F2 = NDFMixture([(0.6, 3.0), (0.4, 9.0)])
N_LOBE = 50.0


def naive_microfacet(tl, tv, wl):
    d, w = thickness_nodes(G3)
    out = []
    for a, b in zip(tl, tv):
        light, view = in_plane_directions(a, b)
        geom, th_d = microfacet_geometry(light, view, F2)
        R = reflectance(wl, float(th_d), d[:, None], DEFAULT_FILM, DEFAULT_SUBSTRATE)
        out.append(math.pi * float(geom) * (w @ R))
    return np.array(out)


def naive_eq6(tl, tv, wl, step=0.5):
    d, w = thickness_nodes(G3)
    tm, f, step = theta_m_grid(F2, step)
    out = []
    for a, b in zip(tl, tv):
        alpha = a + tm
        ci = np.maximum(np.cos(np.deg2rad(alpha)), 0)
        co = np.maximum(np.cos(np.deg2rad(b - tm)), 0)
        cl = np.maximum(np.cos(np.deg2rad(b - a - 2 * tm)), 0)
        ok = (np.abs(alpha) < 90) & (ci * co * cl > 0)
        R = reflectance(wl, np.abs(alpha[ok])[:, None, None], d[None, :, None], DEFAULT_FILM,
                        DEFAULT_SUBSTRATE)
        wt = f[ok] * np.deg2rad(step) * ci[ok] * co[ok] * cl[ok] ** N_LOBE
        out.append(np.einsum("m,k,mkn->n", wt, w, R))
    return np.array(out)


def run(*, quick: bool, out: Path, repeat=5, subset=180) -> str:
    if quick:
        repeat, subset = 1, min(subset, 20)
    t = np.arange(90.0)
    wl = default_wavelengths()
    simulate_map(model="microfacet", thickness=G3, ndf=F2, theta_light_deg=t[:3],
                 theta_view_deg=t[:3])  # warm-up
    rng = np.random.default_rng(0)
    idx = rng.choice(8100, subset, replace=False)
    tl_s, tv_s = t[idx // 90], t[idx % 90]
    rows = []
    for model, naive in (("microfacet", naive_microfacet), ("eq6", naive_eq6)):
        best, m = best_of(lambda model=model: simulate_map(
            model=model, thickness=G3, ndf=F2, n=N_LOBE, theta_light_deg=t, theta_view_deg=t),
            repeat)
        tim = m.meta["timings_s"]
        t_naive, ref = best_of(lambda naive=naive: naive(tl_s, tv_s, wl), 1)
        t_naive *= 8100 / subset
        fast = m.spectra.reshape(8100, -1)[idx]
        err = float(np.max(np.abs(fast - ref)) / np.max(np.abs(ref)))
        rows.append([model, f"{best:.3f}", f"{tim['spectra']:.3f} / {tim['colour']:.3f}",
                     f"{t_naive:.2f}", f"{t_naive / best:.0f}x", f"{err:.1e}"])
        note(" | ".join(rows[-1]))
    return md_table(["model", "fast map (s)", "of which spectra / colour (s)",
                     "naive per-pair (s, extrapolated)", "speed-up", "max rel. diff"], rows)
