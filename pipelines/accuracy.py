"""Accuracy of the analysis on synthetic truth, per preset, for both modes.

For each preset, generates a stack (seed 11, not the fixture's) and analyses it in the seed
mode and the joint mode, then scores against the truth:

* thickness per ROI: |ROI estimate − ROI mean of the true thickness| (unmasked pixels),
  mean over ROIs; for the joint mode the ROI estimate is the mean per-pixel thickness;
* mixture: number of components found vs true, and the largest distance from a true
  component mean to the nearest fitted mean;
* per-pixel tilt median absolute error (visible, unmasked pixels);
* NDF: Wasserstein-1 distance between estimated per-pixel tilts and the true tilts of the
  visible pixels;
* summary ΔE00 mean (and median), masked fraction, exposure (true 1.0 unless the preset
  says otherwise), time.

Run:  python pipelines/accuracy.py [--size 512] [--slices 24] [--presets nd sd ...]
      python pipelines/accuracy.py --stack fixtures/stacks/nd-fixture   (an existing synthetic
      stack, scored against its own truth/)
Prints a markdown table (docs/accuracy.md).
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np
from _shared import best_of, md_header, md_row, parser, tilt_scores, worst_mean_error

from microfacet.analysis import AnalysisOptions, analyze_stack
from microfacet.analysis.roi import nearest_roi_index, roi_grid
from microfacet.forward.synth import PRESETS, generate_stack, preset


def score(r, truth, p):
    d_true, t_true = truth["thickness_nm"], truth["tilt_deg"]
    vis = truth["visible"]
    rows, cols, size = roi_grid(d_true.shape, size_px=r.options.roi_size_px)
    ri, ci = nearest_roi_index(d_true.shape, rows, cols, size)
    idx = ri[:, None] * len(cols) + ci[None, :]
    used = ~r.mask.mask
    errs = []
    for k in range(len(rows) * len(cols)):
        m = (idx == k) & used & np.isfinite(r.thickness_nm)
        if m.sum() < 20:
            continue
        est = (r.roi.thickness_nm[k] if r.options.mode == "seed"
               else float(np.mean(r.thickness_nm[m])))
        errs.append(abs(est - float(np.mean(d_true[m]))))
    fit_means = r.thickness_fit.mixture.means_nm if r.thickness_fit is not None else []
    tilt_med, w1 = tilt_scores(r.tilt_deg, t_true, vis)
    de = r.delta_e_stats
    return {
        "roi_mae_nm": float(np.mean(errs)) if errs else float("nan"),
        "k": f"{len(fit_means)}/{len(p.thickness)}",
        "mean_err_nm": worst_mean_error([c.mean_nm for c in p.thickness], fit_means),
        "tilt_med_deg": tilt_med,
        "w1_deg": w1,
        "de_mean": de["mean"] if de["mean"] is not None else float("nan"),
        "de_median": de["median"] if de["median"] is not None else float("nan"),
        "masked": r.mask.fraction,
        "exposure": r.exposure,
    }


def main(argv=None):
    ap = parser(__doc__)
    ap.add_argument("--size", type=int, default=512)
    ap.add_argument("--slices", type=int, default=24)
    ap.add_argument("--seed", type=int, default=11)
    ap.add_argument("--presets", nargs="+", default=list(PRESETS))
    ap.add_argument("--stack", default=None,
                    help="score this existing synthetic stack (with truth/) instead")
    args = ap.parse_args(argv)
    if args.stack:
        import json

        meta = json.loads((Path(args.stack) / "truth" / "params.json").read_text())["params"]
        p = preset(meta["preset"], seed=meta["seed"], height_px=meta["height_px"],
                   width_px=meta["width_px"], n_slices=meta["n_slices"])
        jobs = [(meta["preset"], Path(args.stack), p)]
        print(f"{args.stack}: {p.height_px}x{p.width_px} px, {p.n_slices} slices, seed {p.seed}\n")
    else:
        jobs = None
        print(f"{args.size}x{args.size} px, {args.slices} slices, seed {args.seed}\n")
    print(md_header(["preset", "mode", "ROI thickness MAE (nm)", "components found/true",
                     "worst mean error (nm)", "tilt median abs err (deg)", "NDF W1 (deg)",
                     "dE00 mean / median", "masked", "exposure (true)", "time (s)"]))
    with tempfile.TemporaryDirectory() as tmp:
        if jobs is None:
            jobs = []
            for name in args.presets:
                p = preset(name, seed=args.seed, height_px=args.size, width_px=args.size,
                           n_slices=args.slices)
                generate_stack(Path(tmp) / name, p)
                jobs.append((name, Path(tmp) / name, p))
        for name, folder, p in jobs:
            t = folder / "truth"
            truth = {k: np.load(t / f"{k}.npy") for k in
                     ("thickness_nm", "tilt_deg", "visible")}
            for mode in ("seed", "joint"):
                dt, r = best_of(lambda: analyze_stack(folder, AnalysisOptions(mode=mode)), 1)
                s = score(r, truth, p)
                print(md_row([name, mode, f"{s['roi_mae_nm']:.2f}", s["k"],
                              f"{s['mean_err_nm']:.1f}", f"{s['tilt_med_deg']:.2f}",
                              f"{s['w1_deg']:.2f}", f"{s['de_mean']:.2f} / {s['de_median']:.2f}",
                              f"{s['masked']:.3f}", f"{s['exposure']:.3f} ({p.exposure:g})",
                              f"{dt:.1f}"]), flush=True)


if __name__ == "__main__":
    main()
