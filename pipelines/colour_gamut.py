"""How far the film's colours lie outside the sRGB gamut, and what that did to the thickness
(docs/thin-film-and-colour.md, "The film's colour as the camera records it").

    python -m pipelines.colour_gamut

Per TiO2 set on Ti (Johnson & Christy), over a 0-400 nm × 0-27° table at exposure 1: the
most negative linear sRGB channel, the share of the table whose colour taken straight to
CIELAB differs from the colour an sRGB image records (that channel at 0) by more than
1 ΔE00, the largest difference and the thicknesses at normal incidence where it exceeds 1;
then films of 150-180 nm recorded as an 8-bit sRGB image (spectra on their own 5 nm grid)
read back at the thickness of least ΔE00 by the model as it is (recorded colours) and by
the table's colour taken straight to CIELAB (the model before 2026-11-30).
"""

from __future__ import annotations

import numpy as np

from microfacet.colour.colorimetry import xyz_to_lab
from microfacet.colour.difference import delta_e
from microfacet.colour.model import FilmColourModel
from microfacet.colour.srgb import colours_from_spectra, model_xyz_to_linear_srgb, srgb_to_lab
from microfacet.colour.table import build_colour_table
from microfacet.optics.thinfilm import reflectance

FILMS = ("TiO2_Jolivet2023_amorphous", "TiO2_Devore1951_rutile_o", "TiO2_Siefke2016_ALD")


def _table_row(model) -> str:
    """The gamut's reach over the table (exposure 1)."""
    theta, d = np.linspace(0.0, 27.0, 28)[:, None], np.arange(0.0, 400.0, 1.0)[None, :]
    xyz = model.xyz(theta, d)
    rgb = model_xyz_to_linear_srgb(xyz, white=model.table.white_xyz)
    de = delta_e(model.lab(theta, d), xyz_to_lab(xyz.astype(np.float32), white=model.white))
    off = d[0][de[0] > 1.0]
    span = f"{off.min():.0f}-{off.max():.0f}" if off.size else "-"
    return (f"| {model.table.film} | {float(np.nanmin(rgb)):.3f} | "
            f"{100 * float(np.mean(de > 1.0)):.1f} % | {float(np.nanmax(de)):.2f} | {span} |")


def _read_rows(model) -> list:
    """Recorded 8-bit films of 150-180 nm read at the thickness of least ΔE00."""
    wl, grid = np.arange(380.0, 781.0, 5.0), np.arange(100.0, 250.0, 0.05)
    now = model.lab(0.0, grid)
    before = xyz_to_lab(model.xyz(0.0, grid).astype(np.float32), white=model.white)
    rows = []
    for d0 in np.arange(150.0, 181.0, 5.0):
        r = reflectance(wl, 0.0, d0, model.table.film, model.table.substrate)
        lab = srgb_to_lab(colours_from_spectra(r, wl)[2])
        a, b = delta_e(now, lab), delta_e(before, lab)
        rows.append(f"| {model.table.film} | {d0:.0f} | {grid[np.argmin(a)]:.2f} | "
                    f"{float(a.min()):.2f} | {grid[np.argmin(b)]:.2f} | {float(b.min()):.2f} |")
    return rows


def main() -> None:
    models = [FilmColourModel(build_colour_table(thickness_range_nm=(0.0, 400.0),
                                                 theta_range_deg=(0.0, 27.0), film=f))
              for f in FILMS]
    print("| film | least linear channel | table off > 1 dE00 | max dE00 | "
          "d at 0° off > 1 (nm) |\n|---|---|---|---|---|")
    for m in models:
        print(_table_row(m))
    print("\n| film | recorded (nm) | read now (nm) | misfit (dE00) | read before (nm) | "
          "misfit (dE00) |\n|---|---|---|---|---|---|")
    for m in models:
        print("\n".join(_read_rows(m)))


if __name__ == "__main__":
    main()
