"""The self-check's renderer applied to the true surface, against the self-check and the
scene (docs/accuracy.md, "One width for the lobes and the self-check").

    python -m pipelines.self_check_oracle [--max N] OUT:WORK [OUT:WORK ...]

Each ``OUT:WORK`` is one ``accuracy-sweep --set mode=joint --set work=WORK --out OUT`` run; of
its scenes with focus texture (``OUT/generalization.csv``) the first ``N`` (default all) are
taken. Per scene, the joint analysis of ``WORK/stacks/NAME`` with the default options, and four
ratios to the truth's RMS slope below the acceptance (the facets' per-pixel tilts,
``truth/tilt_deg.npy`` off ``truth/feature.npy``):

* ``scene``: the facet planes' RMS slope, noise removed
  (:func:`~microfacet.analysis.self_check.measured_rms_slope`): what the stack lets through;
* ``oracle``: :func:`~microfacet.analysis.self_check.rendered_width_ratio` of the **true**
  heights: the self-check's renderer and plane fits on the scene's own geometry;
* ``self_check``: the self-check's width transfer (its own injected surface);
* ``ndf``: the reported lobes' RMS slope (``lobe_rms_ratio``), and ``ndf_fitted`` the lobes
  before the self-check's width correction.

Printed: one row per scene, the medians, and Spearman's ρ of ``oracle`` and ``self_check``
with ``scene`` and with ``ndf_fitted``: whether the renderer reproduces what the real stack
does to the width, and whether the injected surface does; and how often the fitted lobes
over each, as a correction, would land within 15 % and more than 25 % off.
"""

from __future__ import annotations

import csv
import math
import sys
from pathlib import Path

import numpy as np


def scene_ratios(stack: Path) -> dict | None:
    """The four ratios of one stack folder with a ``truth/`` (None without facet planes)."""
    from microfacet.analysis.options import AnalysisOptions
    from microfacet.analysis.pipeline import analyse_stack
    from microfacet.analysis.self_check import (
        Conditions,
        measured_rms_slope,
        rendered_width_ratio,
        slice_noise_sd,
    )
    from microfacet.io.stack import read_stack

    from ._scoring import facet_tilts, lobe_rms_ratio

    st = read_stack(stack)
    r = analyse_stack(st, options=AnalysisOptions(mode="joint"))
    if r.joint is None or r.self_check is None or r.ndf_fit is None:
        return None
    lim = r.scene.max_tilt_deg
    tilt = facet_tilts(stack / "truth")
    seen = tilt[np.isfinite(tilt) & (tilt < lim)]
    true = math.sqrt(float(np.mean(np.tan(np.radians(seen)) ** 2))) if seen.size else 0.0
    planes = measured_rms_slope(r.joint, lim)
    if not planes or true <= 0:
        return None
    cond = Conditions(np.asarray(st.z_um, np.float64), r.scene.pixel_size_um,
                      r.scene.numerical_aperture, slice_noise_sd(st, r.focus), r.scene.seed)
    oracle = rendered_width_ratio(r.focus, r.joint.facets, np.load(stack / "truth" /
                                                                    "height_um.npy"),
                                  tilt, conditions=cond, max_tilt_deg=lim,
                                  focus_options=r.options.focus, joint=r.options.joint)
    lobes = r.ndf_fit.mixture.components
    fitted = (r.ndf_fit.info.get("width_correction") or {}).get("uncorrected")
    fitted = lobes if fitted is None else [(c["weight"], c["sd_deg"]) for c in fitted]
    return {"scene": planes / true, "oracle": oracle,
            "self_check": r.self_check.width_transfer,
            "ndf": lobe_rms_ratio(lobes, tilt, lim),
            "ndf_fitted": lobe_rms_ratio(fitted, tilt, lim)}


def _rho(a, b) -> float:
    from scipy.stats import spearmanr
    a, b = np.asarray(a, float), np.asarray(b, float)
    ok = np.isfinite(a) & np.isfinite(b)
    return float(spearmanr(a[ok], b[ok])[0]) if ok.sum() > 2 else math.nan


def main(argv) -> None:
    n_max = None
    if argv[:1] == ["--max"]:
        n_max, argv = int(argv[1]), argv[2:]
    if not argv:
        raise SystemExit(__doc__)
    keys = ("scene", "oracle", "self_check", "ndf", "ndf_fitted")
    rows = []
    print("| scene | " + " | ".join(keys) + " |\n|" + "---|" * (len(keys) + 1))
    for spec in argv:
        out, work = (Path(p) for p in spec.split(":"))
        with open(out / "generalization.csv", newline="") as f:
            names = [r["name"] for r in csv.DictReader(f)
                     if r["textured"] == "True" and r["status"] == "done"]
        for name in names[:n_max]:
            got = scene_ratios(work / "stacks" / name)
            if got is None:
                continue
            rows.append(got)
            cells = " | ".join(f"{got[k]:.2f}" for k in keys)
            print(f"| {out.parent.name}/{name} | {cells} |", flush=True)
    if not rows:
        raise SystemExit("no scene with facet planes and a self-check")
    cols = {k: np.array([r[k] for r in rows], float) for k in keys}
    print(f"| **median** ({len(rows)} scenes) | "
          + " | ".join(f"{np.nanmedian(cols[k]):.2f}" for k in keys) + " |")
    for k in ("oracle", "self_check"):
        over = cols["ndf_fitted"] / cols[k]
        over = over[np.isfinite(over)]
        print(f"Spearman ρ of {k}: with the scene's {_rho(cols[k], cols['scene']):.2f}, "
              f"with the fitted NDF's {_rho(cols[k], cols['ndf_fitted']):.2f}; the fitted "
              f"NDF's ratio over it within 15 % on {np.mean(np.abs(over - 1) <= 0.15):.0%}, "
              f"off by more than 25 % on {np.mean(np.abs(over - 1) > 0.25):.0%}")


if __name__ == "__main__":
    main(sys.argv[1:])
