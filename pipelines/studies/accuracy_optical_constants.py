"""How much the choice of optical-constant set moves the predicted colours.

For films of several thicknesses at normal incidence (D65, CIE 1931 2°, 1 nm), the CIEDE2000
difference from the colours of the default film/substrate when the film or the substrate set
is swapped, and the thickness of the first-order blue (hue angle nearest 270°, 30-80 nm) for
each combination.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from pipelines import Study
from pipelines._shared import lab_direct, md_table, note

STUDY = Study(
    name="accuracy-optical-constants",
    question="How far do the colours move when another optical-constant set is chosen for "
             "the film or the substrate?",
    doc=("docs/optical-constants.md", "accuracy-optical-constants"),
    run_time="4 s",
    quick_time="5 s",
)

FILMS = ["TiO2_Jolivet2023_amorphous", "TiO2_Sarkar2019_amorphous", "TiO2_Franta2015_amorphous",
         "TiO2_Jolivet2023_anatase", "TiO2_Devore1951_rutile_o"]
SUBSTRATES = ["Ti_JohnsonChristy1974", "Ti_Palm2018", "Ti_Rakic1998_LorentzDrude"]
THICKNESS_NM = [20.0, 40.0, 51.0, 80.0, 120.0, 140.0, 180.0]


def lab(d, film, substrate):
    """Normal incidence, D65, 2°, 1 nm."""
    return lab_direct(0.0, np.asarray(d), 1.0, film=film, substrate=substrate)


def blue_nm(film, substrate, step=0.1):
    d = np.arange(30.0, 80.0 + step / 2, step)
    L = lab(d, film, substrate)
    hue = np.rad2deg(np.arctan2(L[:, 2], L[:, 1])) % 360
    return float(d[np.argmin(np.abs(hue - 270))])


def run(*, quick: bool, out: Path) -> str:
    from microfacet.colour.difference import delta_e
    from microfacet.optics import DEFAULT_FILM, DEFAULT_SUBSTRATE

    ref = lab(THICKNESS_NM, DEFAULT_FILM, DEFAULT_SUBSTRATE)
    note(f"default: film {DEFAULT_FILM}, substrate {DEFAULT_SUBSTRATE}; normal incidence, "
         "D65, 2 deg, 1 nm")
    combos = [(f, DEFAULT_SUBSTRATE) for f in FILMS] + [(DEFAULT_FILM, s) for s in SUBSTRATES[1:]]
    rows = []
    for film, sub in combos:
        de = delta_e(lab(THICKNESS_NM, film, sub), ref, method="CIEDE2000")
        rows.append([film, sub] + [f"{v:.1f}" for v in de]
                    + [f"{blue_nm(film, sub, 0.5 if quick else 0.1):.1f}"])
    return md_table(["film", "substrate"] + [f"dE00 @{d:g} nm" for d in THICKNESS_NM]
                    + ["first-order blue (nm)"], rows)
