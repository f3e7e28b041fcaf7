"""Self-check against truth on a folder of synthetic stacks (issue 22 work in progress; not yet
a registered study): per scene, the measured/true RMS facet slope and the self-check's
transfer (``analysis.self_check``), the scene's world (faceted, sparse, measured: see
``pipelines.studies.accuracy_sweep``), and the censored fraction against the truly-past-limit
area.

    python -m pipelines.self_check_sweep STACKS_DIR

STACKS_DIR holds stacks with ``truth/tilt_deg.npy`` (e.g. the stacks folder of
``python -m pipelines run accuracy-sweep``). Prints one JSON line per scene.
"""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path

import numpy as np

from microfacet.analysis import AnalysisOptions, analyse_stack
from microfacet.analysis import self_check as sc
from microfacet.analysis.options import FitOptions, JointOptions
from microfacet.analysis.planes import fit_facet_planes
from microfacet.focus.options import FocusOptions
from pipelines.studies.accuracy_sweep import world_of


def _actual_gain(r, true_height_um) -> float | None:
    """Gain of the analysis' facet-plane slopes projected on the planes fitted to the true
    heights over the same facets (area-weighted, facets below the acceptance)."""
    pl = r.joint.slope_planes
    true = fit_facet_planes(r.joint.facets, true_height_um, height_sigma_um=1.0,
                            reliable=np.isfinite(true_height_um),
                            pixel_size_um=r.scene.pixel_size_um, min_pixels=5)
    ok = (pl.fitted & true.fitted & (pl.tilt_deg < r.scene.max_tilt_deg)
          & (pl.slope_sigma < sc.MAX_SLOPE_SIGMA))
    if ok.sum() < 3:
        return None
    return sc.slope_gain(pl.slope_x[ok], pl.slope_y[ok], true.slope_x[ok], true.slope_y[ok],
                         r.joint.area_px[ok].astype(np.float64))


def past_limit_fraction(truth: Path) -> float:
    """Fraction of the surface truly tilted past the acceptance, asin(NA)/2: pixels of the
    truth whose tilt exceeds it, among those that are facet (not pit, scratch, dust or
    stain: ``feature.npy`` code 0; all pixels of stacks without it)."""
    meta = json.loads((truth / "params.json").read_text())
    t = np.load(truth / "tilt_deg.npy")
    f = truth / "feature.npy"
    facet = np.load(f) == 0 if f.is_file() else np.ones(t.shape, bool)
    if not facet.any():
        return float("nan")
    return float(np.mean(t[facet] > meta["visibility_limit_deg"]))


def censored_fractions(r) -> dict:
    """The analysis' censored share: the NDF fit's censored weight fraction
    (``MixtureFit.info["censored_fraction"]``) and the fraction of pixels it marked
    censored (``joint.censored``); None where the result has neither."""
    ndf = getattr(r.distributions, "ndf", None)
    info = getattr(ndf, "info", None) or {}
    cens = getattr(getattr(r, "joint", None), "censored", None)
    return {"censored_fraction": info.get("censored_fraction"),
            "censored_pixel_fraction": None if cens is None else float(np.mean(cens))}


def lobe_scores(r, tilt_deg) -> dict:
    """The fitted NDF lobes against the true tilts of the facet pixels below the acceptance:
    their RMS slope (the lobes' tilt density truncated at the limit, E[tan² θ]^½) over the
    truth's, and W1 (°, :func:`pipelines._scoring.ndf_w1_deg`)."""
    from pipelines._scoring import ndf_w1_deg

    ndf = getattr(r.distributions, "ndf", None)
    lim = r.scene.max_tilt_deg
    t = tilt_deg[np.isfinite(tilt_deg) & (tilt_deg < lim)]
    if ndf is None or t.size == 0:
        return {"lobe_ratio": None, "w1_deg": None}
    lobes = [(float(w), float(s)) for w, s in ndf.mixture.components]
    grid = np.linspace(0.0, lim, 2001)
    from microfacet.core.distributions import NDFMixture
    pdf = NDFMixture(lobes).tilt_pdf(grid)
    tan2 = np.tan(np.radians(grid)) ** 2
    lobe_rms = math.sqrt(float(np.trapezoid(pdf * tan2, grid) / np.trapezoid(pdf, grid)))
    true_rms = math.sqrt(float(np.mean(np.tan(np.radians(t)) ** 2)))
    return {"lobe_ratio": lobe_rms / true_rms if true_rms > 0 else None,
            "w1_deg": float(ndf_w1_deg(lobes, t, lim)), "lobes": lobes}


def height_coverage(r, truth: Path) -> float | None:
    """Share of the reported height's errors against the truth within 2 reported σ
    (``height_sigma_um.npy``), over the facet pixels (``feature.npy`` code 0) with a height."""
    from microfacet.analysis.output import height_sigma_um

    sig = height_sigma_um(r)
    if sig is None:
        return None
    ht = np.load(truth / "height_um.npy")
    f = truth / "feature.npy"
    facet = np.load(f) == 0 if f.is_file() else np.ones(ht.shape, bool)
    ok = np.isfinite(r.focus.height_um) & np.isfinite(sig) & facet
    if not ok.any():
        return None
    return float(np.mean(np.abs(r.focus.height_um[ok] - ht[ok]) <= 2.0 * sig[ok]))


def main(folder: str, overrides: dict | None = None) -> None:
    o = overrides or {}
    options = AnalysisOptions(fits=FitOptions(**{"self_check": True, **o.get("fits", {})}),
                              focus=FocusOptions(**o.get("focus", {})),
                              joint=JointOptions(**o.get("joint", {})))
    for d in sorted(p for p in Path(folder).iterdir() if (p / "truth").is_dir()):
        r = analyse_stack(d, options)
        t = np.load(d / "truth" / "tilt_deg.npy")
        feat = d / "truth" / "feature.npy"
        facet = np.load(feat) == 0 if feat.is_file() else np.ones(t.shape, bool)
        t = np.where(facet, t, np.nan)
        vis = np.isfinite(t) & (t < r.scene.max_tilt_deg)
        true_rms = float(np.sqrt(np.mean(np.tan(np.radians(t[vis])) ** 2)))
        meas = sc.measured_rms_slope(r.joint, r.scene.max_tilt_deg)
        c = r.self_check
        params = json.loads((d / "truth" / "params.json").read_text())["params"]
        print(json.dumps({
            "world": world_of(params), "relief_file": params.get("relief_file"),
            "past_limit_fraction": past_limit_fraction(d / "truth"), **censored_fractions(r),
            "actual_gain": _actual_gain(r, np.load(d / "truth" / "height_um.npy")),
            "scene": d.name, "true_rms_slope": true_rms, "measured_rms_slope": meas,
            "actual_ratio": None if meas is None else meas / true_rms,
            "self_check": None if c is None else c.to_json(),
            **lobe_scores(r, t), "height_coverage": height_coverage(r, d / "truth"),
            "identified": r.distributions.ndf_judgement.identified,
            "reason_code": r.distributions.ndf_judgement.to_json()["reason_code"]}), flush=True)


if __name__ == "__main__":
    main(sys.argv[1], json.loads(sys.argv[2]) if len(sys.argv) > 2 else None)
