"""Self-check against truth on a folder of synthetic stacks (issue 22 work in progress; not yet
a registered study): per scene, the measured/true RMS facet slope and the self-check's
transfer (``analysis.self_check``), the scene's world (faceted, sparse, measured: see
``pipelines.studies.accuracy_sweep``), and the censored fraction against the truly-past-limit
area.

    python -m pipelines.self_check_sweep STACKS_DIR ['{"focus": {...}, "truth_facets": true}']

STACKS_DIR holds stacks with ``truth/tilt_deg.npy`` (e.g. the stacks folder of
``python -m pipelines run accuracy-sweep``). Prints one JSON line per scene.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

from microfacet.analysis import AnalysisOptions, analyse_stack
from microfacet.analysis import self_check as sc
from microfacet.analysis.options import FitOptions, JointOptions
from microfacet.analysis.output import height_sigma_terms, height_sigma_um
from microfacet.analysis.planes import MAX_SLOPE_SIGMA, fit_facet_planes
from microfacet.focus.options import FocusOptions
from pipelines._scoring import (
    facet_tilts,
    height_coverage,
    lobe_rms_ratio,
    ndf_w1_deg,
    past_limit_fraction,
    relief_coefficient_95,
)
from pipelines.studies.accuracy_sweep import world_of

#: Segment areas (px) the planes' gain is reported for: [0, 30), [30, 60), [60, 120), ≥ 120.
AREA_BINS_PX = (0, 30, 60, 120)


def plane_gains(r, true_height_um, true_rms_slope) -> dict:
    """The analysis' facet-plane slopes against the planes fitted to the true heights over
    the same segments (facets below the acceptance with a usable plane): their gain
    (``actual_gain``, area-weighted; ``None`` with fewer than 3), that gain per segment area
    (``gain_by_area``: ``AREA_BINS_PX``, None with fewer than 5 planes in a bin), and the
    true planes' area-weighted RMS slope over the true per-pixel one
    (``segment_rms_ratio``: what the segments alone leave of the width, heights aside)."""
    pl = r.joint.slope_planes
    true = fit_facet_planes(r.joint.facets, true_height_um, height_sigma_um=1.0,
                            reliable=np.isfinite(true_height_um),
                            pixel_size_um=r.scene.pixel_size_um, min_pixels=5)
    ok = (pl.fitted & true.fitted & (pl.tilt_deg < r.scene.max_tilt_deg)
          & (pl.slope_sigma < MAX_SLOPE_SIGMA))
    area = r.joint.area_px.astype(np.float64)
    if ok.sum() < 3:
        return {"actual_gain": None, "gain_by_area": None, "segment_rms_ratio": None}

    def gain(m):
        return sc.slope_gain(pl.slope_x[m], pl.slope_y[m], true.slope_x[m], true.slope_y[m],
                             area[m])

    edges = (*AREA_BINS_PX, np.inf)
    bins = [ok & (area >= lo) & (area < hi) for lo, hi in zip(edges[:-1], edges[1:])]
    rms = np.sqrt(np.sum(area[ok] * (true.slope_x[ok] ** 2 + true.slope_y[ok] ** 2))
                  / np.sum(area[ok]))
    return {"actual_gain": gain(ok),
            "gain_by_area": [gain(m) if m.sum() >= 5 else None for m in bins],
            "segment_rms_ratio": float(rms / true_rms_slope)}


def _relief_coefficient(r, truth, facet) -> float | None:
    """The unresolved-relief coefficient κ_r that would make the reported height σ cover
    95 % of this scene's ``facet``-pixel errors (:func:`pipelines._scoring.relief_coefficient_95`
    on :func:`~microfacet.analysis.output.height_sigma_terms`; ``RELIEF_COEFFICIENT`` is the
    median of it over the development sweep's scenes); at most 50 (none up to 50 does)."""
    terms = height_sigma_terms(r, coefficient=1.0)
    if terms is None:
        return None
    err = np.where(facet, r.focus.height_um - np.load(truth / "height_um.npy"), np.nan)
    k = relief_coefficient_95(err, *terms)
    return None if np.isnan(k) else float(min(k, 50.0))


def facet_purity(labels, true_facets) -> float:
    """Share of the pixels whose segment's majority true facet is their own: 1 when every
    segment lies inside one true facet."""
    _, lab = np.unique(labels, return_inverse=True)
    _, tru = np.unique(true_facets, return_inverse=True)
    m = int(tru.max()) + 1
    counts = np.bincount(lab.ravel().astype(np.int64) * m + tru.ravel(),
                         minlength=(int(lab.max()) + 1) * m).reshape(-1, m)
    return float(counts.max(axis=1).sum() / counts.sum())


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
    """The fitted NDF lobes against the true facet tilts: RMS slope ratio and W1 (°)."""
    ndf = getattr(r.distributions, "ndf", None)
    if ndf is None:
        return {"lobe_ratio": None, "w1_deg": None}
    lobes = [(float(w), float(s)) for w, s in ndf.mixture.components]
    lim = r.scene.max_tilt_deg
    return {"lobe_ratio": lobe_rms_ratio(lobes, tilt_deg, lim),
            "w1_deg": ndf_w1_deg(lobes, tilt_deg[np.isfinite(tilt_deg)], lim), "lobes": lobes}


def _use_truth_facets(stack_dir: Path) -> None:
    """Diagnostic: the analysis' segmentation replaced by the truth's facets
    (``truth/facet_id.npy``) for the next analysis; its heights and self-check unchanged."""
    import microfacet.analysis.pipeline as pipeline
    from microfacet.analysis.joint import Segmented, facet_labels

    fid = np.load(stack_dir / "truth" / "facet_id.npy").astype(np.int32)

    def labels(colour, surface, scene, options):
        seg = facet_labels(colour, surface, scene, options)
        return Segmented(fid, seg.heights, seg.evidence)

    pipeline.facet_labels = labels


def analysis_options(overrides: dict | None = None) -> AnalysisOptions:
    """The options of the sweep: the self-check on, and ``{"focus": {...}, "joint": {...},
    "fits": {...}}`` option values."""
    o = overrides or {}
    return AnalysisOptions(fits=FitOptions(**{"self_check": True, **o.get("fits", {})}),
                           focus=FocusOptions(**o.get("focus", {})),
                           joint=JointOptions(**o.get("joint", {})))


def scene_record(d: Path, options: AnalysisOptions) -> dict:
    """One stack analysed and scored against its truth: its world, the NDF's identification
    and reason, the lobes' RMS ratio and W1, the self-check, censored against truly past
    the limit, the height's 2σ coverage and the relief coefficient that would make it 95 %,
    the planes' actual slope gain (all, and by segment area) and the true planes' RMS slope
    over the per-pixel one (:func:`plane_gains`)."""
    r = analyse_stack(d, options)
    t = facet_tilts(d / "truth")
    vis = np.isfinite(t) & (t < r.scene.max_tilt_deg)
    true_rms = float(np.sqrt(np.mean(np.tan(np.radians(t[vis])) ** 2)))
    meas = sc.measured_rms_slope(r.joint, r.scene.max_tilt_deg)
    c = r.self_check
    params = json.loads((d / "truth" / "params.json").read_text())["params"]
    return {
        "world": world_of(params), "relief_file": params.get("relief_file"),
        "past_limit_fraction": past_limit_fraction(d / "truth", r.scene.max_tilt_deg),
        **censored_fractions(r),
        **plane_gains(r, np.load(d / "truth" / "height_um.npy"), true_rms),
        "facet_purity": facet_purity(r.joint.facets, np.load(d / "truth" / "facet_id.npy"))
        if (d / "truth" / "facet_id.npy").exists() else None,
        "scene": d.name, "true_rms_slope": true_rms, "measured_rms_slope": meas,
        "actual_ratio": None if meas is None else meas / true_rms,
        "self_check": None if c is None else c.to_json(),
        **lobe_scores(r, t),
        "height_coverage": height_coverage(r.focus.height_um, height_sigma_um(r), d / "truth")
        if r.scene.from_focus else None,
        "relief_coefficient_95": _relief_coefficient(r, d / "truth", np.isfinite(t)),
        "identified": r.distributions.ndf_judgement.identified,
        "reason_code": r.distributions.ndf_judgement.to_json()["reason_code"]}


def _num(v, digits=2):
    return "–" if v is None or not np.isfinite(v) else f"{v:.{digits}f}"


def world_table(rows, label="") -> str:
    """Markdown: per world (and all) the scenes, the NDFs identified, those off by more than
    25 % in RMS slope, the identified ones' lobe RMS ratio and W1, the median |censored −
    truly past the limit|, the height's median (min) 2σ coverage and the median
    unresolved-relief coefficient that would give 95 % (``RELIEF_COEFFICIENT`` is that of
    seed 0, all worlds)."""
    from pipelines._shared import md_table

    body = []
    for w in ("faceted", "sparse", "measured", "all"):
        sub = rows if w == "all" else [r for r in rows if r["world"] == w]
        if not sub:
            continue
        ident = [r for r in sub if r["identified"]]
        wrong = [r for r in ident if r.get("lobe_ratio") is None
                 or not abs(r["lobe_ratio"] - 1.0) <= 0.25]
        cens = [abs((r["censored_fraction"] or 0.0) - r["past_limit_fraction"]) for r in sub
                if r["past_limit_fraction"] is not None]
        hc = [r["height_coverage"] for r in sub if r.get("height_coverage") is not None]
        kr = [r["relief_coefficient_95"] for r in sub
              if r.get("relief_coefficient_95") is not None]
        body.append([label, w, str(len(sub)), str(len(ident)), str(len(wrong)),
                     ", ".join(f"{_num(r['lobe_ratio'])}, {_num(r['w1_deg'])}°" for r in ident)
                     or "–",
                     _num(float(np.median(cens)) if cens else None, 3),
                     f"{_num(float(np.median(hc)) if hc else None)} "
                     f"({_num(min(hc) if hc else None)})",
                     _num(float(np.median(kr)) if kr else None)])
    return md_table(["sweep", "world", "scenes", "NDF identified",
                     "identified, RMS slope off > 25 %", "identified: lobe RMS ratio, W1",
                     "median abs(censored − past limit)", "height 2σ coverage, median (min)",
                     "κ_r for 95 % coverage, median"],
                    body)


def main(folder: str, overrides: dict | None = None) -> None:
    """``overrides``: option values (:func:`analysis_options`), and ``"truth_facets": true``
    to analyse on the true facets (a diagnostic)."""
    o = dict(overrides or {})
    truth_facets = bool(o.pop("truth_facets", False))
    options = analysis_options(o)
    for d in sorted(p for p in Path(folder).iterdir() if (p / "truth").is_dir()):
        if truth_facets:
            _use_truth_facets(d)
        print(json.dumps(scene_record(d, options)), flush=True)


if __name__ == "__main__":
    main(sys.argv[1], json.loads(sys.argv[2]) if len(sys.argv) > 2 else None)
