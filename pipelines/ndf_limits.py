"""Where the NDF error of the generalization sweep comes from (docs/accuracy.md).

For every joint-mode scene of a finished sweep (``generalization.py --work DIR``), three NDFs
are scored with the sweep's own W1 (``_scoring.ndf_w1_deg``) against the true per-pixel
tilts, and the plane fits' slopes are compared with the truth:

* **fitted**: the analysis's lobes (``summary.json``);
* **true lobes**: the scene's own lobe parameters (what a perfect fit of the facet lobes
  would give: the truth's relief beyond the facets — waviness, walls — is not in them);
* **true heights over our facets**: lobes fitted to the true height map's slopes averaged
  over the analysis's facets (``facets.npy``): what the segmentation allows;
* **slope gain**: least-squares slope of the fitted facet slopes (``facets.csv`` tilts
  with the planes' azimuth are not written, so the gain uses tilt magnitudes) against the
  true facet-mean slope magnitudes, on facets with a height plane.

Run:  python pipelines/ndf_limits.py --work DIR   (DIR of a finished generalization sweep)
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
from _scoring import ndf_w1_deg
from _shared import fmt, md_table, parser

from microfacet.analysis.ndf_fit import fit_ndf_mixture


def scene(results: Path, truth: Path) -> dict:
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
    seg = fit_ndf_mixture(t_facet[ok], weights=cnt[ok].astype(np.float64), max_components=3)
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


def main(argv=None):
    ap = parser(__doc__)
    ap.add_argument("--work", required=True, help="the --work folder of a finished sweep")
    args = ap.parse_args(argv)
    work = Path(args.work)
    rows = []
    for res in sorted((work / "results" / "joint").iterdir()):
        if (res / "summary.json").is_file() and (res / "facets.csv").is_file():
            rows.append({"scene": res.name,
                         **scene(res, work / "stacks" / res.name / "truth")})
    keys = ["fitted", "true_lobes", "true_heights_our_facets", "slope_gain"]
    print(md_table(["scene", "W1 fitted (°)", "W1 true lobes (°)",
                    "W1 true heights, our facets (°)", "slope gain"],
                   [[r["scene"]] + [fmt(r[k]) for k in keys] for r in rows]))
    med = {k: float(np.nanmedian([r[k] for r in rows])) for k in keys}
    print("\nmedians over " + str(len(rows)) + " scenes: "
          + ", ".join(f"{k} {fmt(v)}" for k, v in med.items()))


if __name__ == "__main__":
    main()
