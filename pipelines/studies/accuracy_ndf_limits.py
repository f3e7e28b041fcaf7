"""Where the NDF error of the generalization sweep comes from (docs/accuracy.md).

For every joint-mode scene of a finished sweep (``accuracy-sweep --set work=DIR``; without
``work`` a sweep of ``n`` scenes is run into ``out/work`` first), three NDFs are scored with
the sweep's own W1 (:func:`pipelines._scoring.ndf_w1_deg`) against the true per-pixel tilts,
and the plane fits' slopes are compared with the truth:

* **fitted**: the analysis's lobes (``summary.json``);
* **true lobes**: the scene's own lobe parameters (what a perfect fit of the facet lobes
  would give: the truth's relief beyond the facets — waviness, walls — is not in them);
* **true heights over our facets**: lobes fitted to the true height map's slopes averaged
  over the analysis's facets (``facets.npy``): what the segmentation allows;
* **slope gain**: least-squares slope of the fitted facet slopes (``facets.csv`` tilts
  with the planes' azimuth are not written, so the gain uses tilt magnitudes) against the
  true facet-mean slope magnitudes, on facets with a height plane.

The medians over the scenes go to stderr (docs/accuracy.md quotes them).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from pipelines import Study
from pipelines._shared import fmt, md_table, note

STUDY = Study(
    name="accuracy-ndf-limits",
    question="Where does the NDF error of the generalization sweep come from: the truth, the "
             "segmentation or the height from focus?",
    doc=None,
    run_time="3 min (30 s on a finished sweep)",
    quick_time="11 s",
    options={"work": ("", "the work folder of a finished accuracy-sweep (default: run one)"),
             "n": (30, "scenes of the sweep run without work")},
)


def scene(results: Path, truth: Path) -> dict:
    from microfacet.analysis.ndf_fit import fit_ndf_mixture
    from microfacet.analysis.options import FitOptions
    from pipelines._scoring import ndf_w1_deg

    meta = json.loads((truth / "params.json").read_text())
    limit = meta["visibility_limit_deg"]
    tilt_true = np.load(truth / "tilt_deg.npy")
    s = json.loads((results / "summary.json").read_text())
    fitted = [(c["weight"], c["sd_deg"]) for c in s["ndf"]["mixture"]["components"]]
    lobes = [(c["weight"], c["sd_deg"]) for c in meta["params"]["tilt_lobes"]]
    lab = np.load(results / "facets.npy")
    h = np.load(truth / "height_um.npy").astype(np.float64)
    gy, gx = np.gradient(h, meta["params"]["pixel_size_um"])
    n = int(lab.max()) + 1
    cnt = np.bincount(lab.ravel(), minlength=n)
    sx = np.bincount(lab.ravel(), gx.ravel(), n) / np.maximum(cnt, 1)
    sy = np.bincount(lab.ravel(), gy.ravel(), n) / np.maximum(cnt, 1)
    t_facet = np.degrees(np.arctan(np.hypot(sx, sy)))
    ok = (cnt > 8) & (t_facet < limit)
    seg = fit_ndf_mixture(t_facet[ok], weights=cnt[ok].astype(np.float64),
                          options=FitOptions(max_components=3))
    tab = np.genfromtxt(results / "facets.csv", delimiter=",", names=True)
    fit_ok = (tab["height_plane"] == 1) & np.isfinite(tab["tilt_deg"])
    idx = tab["facet"][fit_ok].astype(int)
    true_t = np.tan(np.radians(t_facet[idx]))
    meas_t = np.tan(np.radians(tab["tilt_deg"][fit_ok]))
    gain = float(np.sum(true_t * meas_t) / np.sum(true_t ** 2)) if idx.size else np.nan
    return {"fitted": ndf_w1_deg(fitted, tilt_true, limit),
            "true_lobes": ndf_w1_deg(lobes, tilt_true, limit),
            "true_heights_our_facets": ndf_w1_deg(list(seg.mixture.components), tilt_true,
                                                  limit),
            "slope_gain": gain}


def run(*, quick: bool, out: Path, work="", n=30) -> str:
    if not work:
        from pipelines.studies.accuracy_sweep import sweep

        work = out / "work"
        size, slices = ((64, 64), 6) if quick else ((256, 256), 16)
        sweep(n=2 if quick else n, seed=0, size=size, slices=slices, modes=["joint"],
              jobs=1 if quick else 0, scheduler="", work=work)
    work = Path(work)
    rows = []
    for res in sorted((work / "results" / "joint").iterdir()):
        if (res / "summary.json").is_file() and (res / "facets.csv").is_file():
            rows.append({"scene": res.name,
                         **scene(res, work / "stacks" / res.name / "truth")})
    keys = ["fitted", "true_lobes", "true_heights_our_facets", "slope_gain"]
    med = {k: float(np.nanmedian([r[k] for r in rows])) for k in keys}
    note(f"medians over {len(rows)} scenes: " + ", ".join(f"{k} {fmt(v)}" for k, v in med.items()))
    return md_table(["scene", "W1 fitted (°)", "W1 true lobes (°)",
                     "W1 true heights, our facets (°)", "slope gain"],
                    [[r["scene"]] + [fmt(r[k]) for k in keys] for r in rows]
                    + [["median"] + [fmt(med[k]) for k in keys]])
