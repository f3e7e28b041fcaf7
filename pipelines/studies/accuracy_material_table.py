"""The exported material's film table against the exact Airy reflectance, per grid, and what
building it component by component costs and changes.

Single films (60, 150, 300 nm: the hardest case, no thickness spread to smooth the fringes),
random (θ_d, λ) with cos θ_d uniform over (0, 1] and λ over the grid: the table's bilinear value
(:meth:`Material.film_reflectance`, what the Mitsuba plugin looks up) minus the exact value,
in units of R. Past the last node (89.75° on the default grid) the table holds its last value
while R rises to 1 at 90°: the largest errors are there, so they are also given without it.

Then the fixture's three-population mixture is built at the default grid two ways: one
thickness quadrature for the whole mixture (:meth:`FilmAverage.build` on the mixture) and
the component-by-component build of :meth:`Material.build`.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from microfacet.core.distributions import NDFMixture, ThicknessMixture
from microfacet.forward.brdf import FilmAverage
from microfacet.forward.material import Material
from microfacet.optics.constants import DEFAULT_FILM, DEFAULT_SUBSTRATE
from microfacet.optics.thinfilm import reflectance
from pipelines import Study
from pipelines._shared import md_table, note

STUDY = Study(
    name="accuracy-material-table",
    question="How far is the exported film table from the exact Airy reflectance, per grid, "
             "and what does the component-wise build cost?",
    doc=("docs/rendering.md", "accuracy-material-table"),
    run_time="40 s",
    quick_time="10 s",
    options={"points": (2000, "random (θ_d, λ) per film")},
)

G3 = ThicknessMixture([(0.088, 108.4, 0.1), (0.674, 131.5, 1.52), (0.238, 151.1, 3.61)])
NDF = NDFMixture([(1.0, 8.0)])
GRIDS = [(0.5, 5.0), (0.25, 1.0), (0.1, 1.0)]


def _errors(thickness_nm, grid, points, rng):
    m = Material.build(thickness=thickness_nm, ndf=NDF, theta_step_deg=grid[0],
                       wavelength_step_nm=grid[1])
    th = np.degrees(np.arccos(rng.uniform(1e-4, 1.0, points)))
    wl = rng.uniform(m.wavelength_nm[0], m.wavelength_nm[-1], points)
    exact = np.array([reflectance(np.array([w]), t, thickness_nm, DEFAULT_FILM,
                                  DEFAULT_SUBSTRATE)[0] for w, t in zip(wl, th)])
    err = np.abs(m.film_reflectance(th, wl) - exact)
    return err, th, m.film_average.nbytes


def run(*, quick: bool, out: Path, points=2000) -> str:
    if quick:
        points = min(points, 200)
    rng = np.random.default_rng(0)
    rows = []
    for d in (60.0, 150.0, 300.0):
        for grid in GRIDS:
            err, th, nbytes = _errors(d, grid, points, rng)
            rows.append([f"{d:g} nm", f"{grid[0]:g}° × {grid[1]:g} nm", f"{nbytes / 1e6:.2f}",
                         f"{err.max():.1e}", f"{th[np.argmax(err)]:.1f}",
                         f"{err[th <= 89.0].max():.1e}", f"{np.percentile(err, 99):.1e}"])
            note(" | ".join(rows[-1]))
    table = md_table(["film", "grid (θ_d × λ)", "table (MB)", "max |ΔR|", "at θ_d (°)",
                      "max |ΔR|, θ_d ≤ 89°", "99 % of |ΔR|"], rows)
    ref = Material.build(thickness=51.0, ndf=NDF)           # the grid, once
    th, wl = ref.theta_d_deg, ref.wavelength_nm
    t0 = time.perf_counter()
    whole = FilmAverage.build(th, G3, wavelength_nm=wl).spectra
    t_whole = time.perf_counter() - t0
    t0 = time.perf_counter()
    parts = Material.build(thickness=G3, ndf=NDF).film_average
    t_parts = time.perf_counter() - t0
    build = md_table(["fixture mixture, default grid", "seconds", "max |ΔR| between the two"],
                     [["one quadrature for the mixture", f"{t_whole:.2f}", ""],
                      ["component by component (Material.build)", f"{t_parts:.2f}",
                       f"{np.abs(parts - whole).max():.1e}"]])
    return table + "\n\n" + build
