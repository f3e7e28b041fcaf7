"""Colour table: spectral step and grid chosen from measured error, per scene range.

For several (thickness range, angle range) scenes, builds the colour table with the default
targets (spectral error ≤ 0.05 ΔE00 vs 1 nm; interpolation error ≤ 0.05 ΔE00 vs direct
evaluation) and prints the chosen spectral step, the grid, the measured errors, the table
size and the build time. Also prints the max ΔE00 of each spectral step against 1 nm.

Run:  python pipelines/colour_table_error.py
"""

from __future__ import annotations

from _shared import best_of, md_header, md_row

from microfacet.colour.table import build_colour_table, choose_spectral_step

SCENES = [
    ("very thin film (sub-20 nm)", (0.0, 20.0), (0.0, 26.6)),
    ("SD blue (40-60 nm)", (40.0, 60.0), (0.0, 26.6)),
    ("ND sample (90-170 nm)", (90.0, 170.0), (0.0, 26.6)),
    ("microscope, all first/second order (0-400 nm)", (0.0, 400.0), (0.0, 26.6)),
    ("gonio maps, 0-400 nm, 0-85 deg", (0.0, 400.0), (0.0, 85.0)),
    ("thick films (0-800 nm)", (0.0, 800.0), (0.0, 26.6)),
]


def main():
    print(md_header(["scene", "d range (nm)", "theta range (deg)", "spectral step (nm)",
                     "max dE00 vs 1 nm", "20/10/5/2 nm max dE00", "grid (theta x d)",
                     "steps (deg, nm)", "max interp dE00", "build (s)"]))
    for name, d, th in SCENES:
        _, _, errs = choose_spectral_step(thickness_range_nm=d, theta_range_deg=th)
        steps = "/".join(f"{errs[s]:.3f}" if s in errs else "-" for s in (20.0, 10.0, 5.0, 2.0))
        dt, t = best_of(lambda d=d, th=th: build_colour_table(thickness_range_nm=d,
                                                              theta_range_deg=th), 1)
        print(md_row([name, f"{d[0]:g}-{d[1]:g}", f"{th[0]:g}-{th[1]:g}",
                      f"{t.spectral_step_nm:g}", f"{t.spectral_error_de00:.3f}", steps,
                      f"{t.theta_deg.size} x {t.thickness_nm.size}",
                      f"{t.theta_step_deg:.3g}, {t.thickness_step_nm:.3g}",
                      f"{t.interp_error_de00:.3f}", f"{dt:.2f}"]), flush=True)


if __name__ == "__main__":
    main()
