"""Is the synthetic image textured enough to focus on? Grooves vs per-facet thickness offsets.

For the nd preset (160x160 px, 24 slices, noise-free), the fraction of all pixels whose
sharpest slice — by an independent focus measure, the 9x9 local grey-level variance — lies
within 2 slices of the slice nearest their true height. Compared: the default (dark grooves
at the facet steps, no per-facet thickness offset) and no grooves with per-facet thickness
offsets of 0.8, 1.5 and 2.5 nm (docs/synthetic-stacks.md quotes the numbers).
"""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np

from pipelines import Study
from pipelines._shared import md_table, note

STUDY = Study(
    name="accuracy-focus-texture",
    question="Do the synthetic stacks carry enough texture to focus on, with grooves or "
             "with per-facet thickness offsets?",
    doc=None,
    run_time="5 s",
    quick_time="5 s",
    options={"size": (160, "image side, px"), "slices": (24, "slices per stack")},
)

CASES = [
    ("grooves (default), no facet offset", dict()),
    ("no grooves, facet offset 0.8 nm", dict(groove_wall_deg=0.0, thickness_facet_sd_nm=0.8)),
    ("no grooves, facet offset 1.5 nm", dict(groove_wall_deg=0.0, thickness_facet_sd_nm=1.5)),
    ("no grooves, facet offset 2.5 nm", dict(groove_wall_deg=0.0, thickness_facet_sd_nm=2.5)),
]


def within_two(folder, p, z_um):
    import cv2

    h = np.load(folder / "truth" / "height_um.npy")
    fm = []
    for k in range(p.n_slices):
        g = cv2.imread(str(folder / "slices" / f"{k:03d}.png"), cv2.IMREAD_GRAYSCALE)
        g = g.astype(np.float32)
        m = cv2.blur(g, (9, 9))
        fm.append(cv2.blur(g * g, (9, 9)) - m * m)
    best = np.argmax(fm, axis=0)
    true_k = np.abs(z_um[:, None, None] - h[None]).argmin(axis=0)
    return float(np.mean(np.abs(best - true_k) <= 2))


def run(*, quick: bool, out: Path, size=160, slices=24) -> str:
    from microfacet.forward.synth import generate_stack, preset

    if quick:
        size, slices = min(size, 64), min(slices, 12)
    rows = []
    for i, (name, kw) in enumerate(CASES):
        folder = out / f"case{i}"
        p = preset("nd", seed=4, height_px=size, width_px=size, n_slices=slices,
                   full_well_e=None, read_noise=0.0, **kw)
        r = generate_stack(folder, p, overwrite=True)
        rows.append([name, f"{within_two(folder, p, r.z_um):.2f}"])
        shutil.rmtree(folder, ignore_errors=True)
        note(" | ".join(rows[-1]))
    return md_table(["synthetic image", "pixels whose sharpest slice is within 2 of the truth"],
                    rows)
