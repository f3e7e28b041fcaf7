"""A flat sample of the fixture's material rendered in Mitsuba (a D65 beam and an orthographic
camera in the plane of incidence: ``render.scene.gonio_scene``) against ``simulate``'s
microfacet map at the same angles, ΔE00.

The render's XYZ is divided by the Y of a white Lambertian sample rendered the same way, which
makes it the reflectance factor π f_r that ``simulate`` reports; both go to CIELAB under D65.
The difference holds the film table's interpolation, Mitsuba's continuous wavelength sampling
(360-830 nm against simulate's 380-780 nm in 5 nm steps) and Monte Carlo colour noise.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from microfacet.colour.colorimetry import xyz_to_lab
from microfacet.colour.difference import delta_e_2000
from microfacet.colour.srgb import linear_srgb_to_xyz
from microfacet.core.distributions import NDFMixture, ThicknessMixture
from microfacet.forward.angular import simulate_map
from microfacet.forward.material import Material
from microfacet.render import bsdf
from microfacet.render.scene import gonio_scene
from microfacet.render.variants import available_variants
from pipelines import Study
from pipelines._shared import md_table, note

STUDY = Study(
    name="accuracy-render",
    question="Does a rendered flat sample have simulate's colours (ΔE00), in each variant?",
    doc=("docs/rendering.md", "accuracy-render"),
    run_time="1 min",
    quick_time="20 s",
    options={"spp": (256, "samples per pixel (8 × 8 px)")},
)

#: The fixture's fitted material (README quick start).
G3 = ThicknessMixture([(0.088, 108.4, 0.1), (0.674, 131.5, 1.52), (0.238, 151.1, 3.61)])
F2 = NDFMixture([(0.976, 7.8), (0.024, 55.1)])
ANGLES = [(0.0, 10.0), (0.0, 40.0), (20.0, 20.0), (30.0, 50.0), (45.0, 20.0), (45.0, 45.0),
          (60.0, 65.0), (70.0, 80.0)]


def _xyz(scene_dict, spp, seed):
    import mitsuba as mi

    img = mi.render(mi.load_dict(scene_dict), spp=spp, seed=seed)
    rgb = np.asarray(img, dtype=np.float64).reshape(-1, 3).mean(axis=0)
    return linear_srgb_to_xyz(rgb)


def run(*, quick: bool, out: Path, spp=256) -> str:
    import mitsuba as mi

    if quick:
        spp = min(spp, 32)
    path = Material.build(thickness=G3, ndf=F2).write(out / "material.npz")
    spec = {"type": bsdf.PLUGIN, "filename": str(path)}
    white = {"type": "diffuse", "reflectance": 1.0}
    rows = []
    for variant in available_variants():
        mi.set_variant(variant)
        bsdf.register()
        n = spp
        des = []
        for k, (tl, tv) in enumerate(ANGLES):
            ref = simulate_map(model="microfacet", thickness=G3, ndf=F2,
                               theta_light_deg=[tl], theta_view_deg=[tv]).lab[0, 0]
            kw = dict(theta_light_deg=tl, theta_view_deg=tv, spp=n)
            xyz = _xyz(gonio_scene(bsdf=spec, **kw), n, k)
            y_white = _xyz(gonio_scene(bsdf=white, **kw), n, k)[1]
            de = float(delta_e_2000(xyz_to_lab(xyz / y_white), ref))
            des.append(de)
            rows.append([variant, f"8² × {n}", f"{tl:g}", f"{tv:g}", f"{ref[0]:.1f}",
                         f"{de:.2f}"])
            note(" | ".join(rows[-1]))
        note(f"{variant}: max dE00 {max(des):.2f}, median {np.median(des):.2f}")
    return md_table(["variant", "pixels × spp", "θ light (°)", "θ view (°)",
                     "simulate L*", "ΔE00 render vs simulate"], rows)
