"""The fixture's fitted material on a bent sheet under D65, in the spirit of seed Fig. 11:
what the two distributions change.

The bundled fixture is analysed (as the README's quick start does) and its material rendered
by ``microfacet render`` on the bent sheet, three ways, same camera, light and exposure:

1. one thickness — the thickness mixture's mean — with the fitted NDF: every facet shows the
   film at its own incidence (the half-vector model's colours, spread by the lobes);
2. the fitted thickness mixture with the fitted NDF: the measured material;
3. the fitted thickness mixture with a near-mirror NDF (one 1° lobe): what the roughness
   does.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from microfacet.core.distributions import NDFMixture
from microfacet.forward.material import Material
from microfacet.render.scene import luminance_cd_m2
from microfacet.workflow.analyse import analyse_to_folder
from microfacet.workflow.render import RenderOptions, render_to_folder
from pipelines import ROOT, Study
from pipelines._shared import md_table, note

STUDY = Study(
    name="gallery-render",
    question="What do the thickness mixture and the NDF change in a rendered sheet of the "
             "fixture's material?",
    doc=("docs/rendering.md", "gallery-render"),
    run_time="1 min",
    quick_time="30 s",
    options={"width": (360, "image width, px"), "spp": (256, "samples per pixel")},
    doc_files={"render-sheets.png": "docs/img/render-sheets.png"},
)

FIXTURE = ROOT / "fixtures" / "stacks" / "nd-fixture"


def _panels(results: Path):
    fitted = Material.from_results(results)
    mean = float(fitted.thickness.mean_nm)
    smooth = NDFMixture([(1.0, 1.0)])
    return [
        (f"one thickness {mean:.1f} nm, fitted NDF",
         Material.build(thickness=mean, ndf=fitted.ndf, film=fitted.film,
                        substrate=fitted.substrate)),
        ("fitted thickness mixture and NDF", fitted),
        ("fitted thickness mixture, 1° NDF",
         Material.build(thickness=fitted.thickness, ndf=smooth, film=fitted.film,
                        substrate=fitted.substrate)),
    ]


def _figure(images, titles, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(images), figsize=(3.3 * len(images), 2.6), dpi=150)
    for ax, img, title in zip(axes, images, titles):
        ax.imshow(img)
        ax.set_title(title, fontsize=8)
        ax.axis("off")
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def run(*, quick: bool, out: Path, width=360, spp=256) -> str:
    import mitsuba as mi

    if quick:
        width, spp = min(width, 120), min(spp, 16)
    results = out / "nd"
    analyse_to_folder(FIXTURE, results, overwrite=True, report=False)
    # a shorter exposure than the default keeps the fitted lobe's highlight below saturation
    options = RenderOptions.from_dict({"scene": "sheet", "spp": spp,
                                       "camera": {"width_px": width, "shutter_s": 1 / 60},
                                       "light": {"sky_fraction": 0.3}})
    rows, images, titles = [], [], []
    for k, (title, material) in enumerate(_panels(results)):
        path = material.write(out / f"material-{k}.npz")
        done = render_to_folder(out / f"render-{k}", material=path, options=options,
                                overwrite=True)
        linear = np.asarray(mi.Bitmap(str(out / f"render-{k}" / "render.exr")), np.float64)
        images.append(np.asarray(mi.Bitmap(str(out / f"render-{k}" / "render.png"))))
        titles.append(title)
        y = luminance_cd_m2(linear)
        lobes = ", ".join(f"{sd:.1f}° ({w:.0%})" for w, sd in material.ndf.components)
        rows.append([title, lobes, f"{np.percentile(y, 50):.1f}", f"{y.max():.0f}",
                     f"{done.saturated_fraction:.3f}", done.variant, f"{done.seconds:.1f}"])
        note(" | ".join(rows[-1]))
    _figure(images, titles, out / "render-sheets.png")
    note(f"wrote {out / 'render-sheets.png'}")
    return md_table(["panel", "NDF lobes", "median Y (cd/m²)", "max Y (cd/m²)",
                     "saturated", "variant", "render (s)"], rows)
