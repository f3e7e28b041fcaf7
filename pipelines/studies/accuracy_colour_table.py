"""Colour table: spectral step and grid chosen from measured error, per scene range.

For several (thickness range, angle range) scenes, builds the colour table with the default
targets (spectral error ≤ 0.05 ΔE00 vs 1 nm; interpolation error ≤ 0.05 ΔE00 vs direct
evaluation) and tabulates the chosen spectral step, the grid, the measured errors, the table
size and the build time, with the max ΔE00 of each spectral step against 1 nm.
"""

from __future__ import annotations

from pathlib import Path

from pipelines import Study
from pipelines._shared import best_of, md_table, note

STUDY = Study(
    name="accuracy-colour-table",
    question="Which spectral step and grid does the colour table pick per scene, and how "
             "close to direct evaluation is it?",
    doc=("docs/thin-film-and-colour.md", "accuracy-colour-table"),
    run_time="10 s",
    quick_time="5 s",
)

SCENES = [
    ("very thin film (sub-20 nm)", (0.0, 20.0), (0.0, 26.6)),
    ("SD blue (40-60 nm)", (40.0, 60.0), (0.0, 26.6)),
    ("ND sample (90-170 nm)", (90.0, 170.0), (0.0, 26.6)),
    ("microscope, all first/second order (0-400 nm)", (0.0, 400.0), (0.0, 26.6)),
    ("gonio maps, 0-400 nm, 0-85 deg", (0.0, 400.0), (0.0, 85.0)),
    ("thick films (0-800 nm)", (0.0, 800.0), (0.0, 26.6)),
]


def run(*, quick: bool, out: Path) -> str:
    from microfacet.colour.table import build_colour_table, choose_spectral_step

    rows = []
    for name, d, th in SCENES[:3] if quick else SCENES:
        _, _, errs = choose_spectral_step(thickness_range_nm=d, theta_range_deg=th)
        steps = "/".join(f"{errs[s]:.3f}" if s in errs else "-" for s in (20.0, 10.0, 5.0, 2.0))
        dt, t = best_of(lambda d=d, th=th: build_colour_table(thickness_range_nm=d,
                                                              theta_range_deg=th), 1)
        rows.append([name, f"{d[0]:g}-{d[1]:g}", f"{th[0]:g}-{th[1]:g}",
                     f"{t.spectral_step_nm:g}", f"{t.spectral_error_de00:.3f}", steps,
                     f"{t.theta_deg.size} x {t.thickness_nm.size}",
                     f"{t.theta_step_deg:.3g}, {t.thickness_step_nm:.3g}",
                     f"{t.interp_error_de00:.3f}", f"{dt:.2f}"])
        note(" | ".join(rows[-1]))
    return md_table(["scene", "d range (nm)", "theta range (deg)", "spectral step (nm)",
                     "max dE00 vs 1 nm", "20/10/5/2 nm max dE00", "grid (theta x d)",
                     "steps (deg, nm)", "max interp dE00", "build (s)"], rows)
