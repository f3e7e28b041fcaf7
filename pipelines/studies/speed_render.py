"""The thin-film Python BSDF against Mitsuba's built-in ``roughconductor`` (Beckmann, the
fitted material's main lobe, visible-normal sampling), same scene, same variant, same run.

The scene is ``microfacet render``'s default (a sphere under the D65 lamp and ambient, the
50 mm camera), 512² at 64 spp in the fastest variant that works here; the scalar variant is
timed on 64² at 16 spp (it calls Python per sample). Renders alternate between the two BSDFs
and the minimum of ``repeat`` warm renders is kept; the first render of each (Dr.Jit tracing
and compiling its kernels) is shown apart. The thin film is also timed in the passes of
``microfacet render`` (:func:`microfacet.workflow.render.passes`), which move its progress bar.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from microfacet.core.distributions import NDFMixture, ThicknessMixture
from microfacet.forward.material import Material
from microfacet.render import bsdf
from microfacet.render.scene import Camera, build_scene
from microfacet.render.variants import available_variants
from microfacet.workflow.render import passes
from pipelines import Study
from pipelines._shared import md_table, note

STUDY = Study(
    name="speed-render",
    question="How fast is the thin-film Python BSDF in Mitsuba against the built-in "
             "roughconductor, same scene and variant?",
    doc=("docs/rendering.md", "speed-render"),
    run_time="1 min",
    quick_time="15 s",
    options={"repeat": (3, "warm renders per BSDF (the minimum is kept)")},
)

#: The fixture's fitted material (README quick start): three thickness populations, two lobes.
G3 = ThicknessMixture([(0.088, 108.4, 0.1), (0.674, 131.5, 1.52), (0.238, 151.1, 3.61)])
F2 = NDFMixture([(0.976, 7.8), (0.024, 55.1)])


def _time(scene, spp, seed):
    import mitsuba as mi

    t0 = time.perf_counter()
    np.asarray(mi.render(scene, spp=spp, seed=seed))
    return time.perf_counter() - t0


def _pair(variant, material_file, size, spp, repeat):
    """(first, best) seconds of the thin-film BSDF and of roughconductor."""
    import mitsuba as mi

    mi.set_variant(variant)
    bsdf.register()
    cam = Camera(width_px=size, height_px=size)
    alpha = float(F2.beckmann_alpha[0])
    specs = {"thin film (Python)": {"type": bsdf.PLUGIN, "filename": str(material_file)},
             "roughconductor": {"type": "roughconductor", "distribution": "beckmann",
                                "alpha": alpha}}
    scenes = {k: mi.load_dict(build_scene(obj="sphere", bsdf=s, camera=cam))
              for k, s in specs.items()}
    first = {k: _time(s, spp, 0) for k, s in scenes.items()}
    ours = scenes["thin film (Python)"]
    split = "thin film, in passes (as microfacet render)"
    first[split] = float("nan")
    best = {k: np.inf for k in (*scenes, split)}
    for r in range(repeat):
        for k, s in scenes.items():
            best[k] = min(best[k], _time(s, spp, r + 1))
        best[split] = min(best[split], sum(_time(ours, n, 100 * r + i)
                                           for i, n in enumerate(passes(spp))))
    return first, best


def run(*, quick: bool, out: Path, repeat=3) -> str:
    if quick:
        repeat = 1
    material_file = Material.build(thickness=G3, ndf=F2).write(out / "material.npz")
    works = available_variants()
    jit, scalar = ((128, 8), (16, 4)) if quick else ((512, 64), (64, 16))
    plan = [(v, *jit) for v in works if not v.startswith("scalar")][:1]
    plan += [("scalar_spectral", *scalar)] if "scalar_spectral" in works else []
    rows = []
    for variant, size, spp in plan:
        first, best = _pair(variant, material_file, size, spp, repeat)
        ours, ref = best["thin film (Python)"], best["roughconductor"]
        for name in best:
            per_sample_us = best[name] / (size * size * spp) * 1e6
            cold = "–" if np.isnan(first[name]) else f"{first[name]:.2f}"
            rows.append([variant, f"{size}² × {spp}", name, cold,
                         f"{best[name]:.2f}", f"{best[name] / ref:.2f}x",
                         f"{per_sample_us:.3g}"])
            note(" | ".join(rows[-1]))
        note(f"{variant}: thin film / roughconductor = {ours / ref:.2f}")
    return md_table(["variant", "image × spp", "BSDF", "first render (s)", "best warm (s)",
                     "ratio to roughconductor", "µs per sample"], rows)
