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

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np

from microfacet.analysis.pipeline import AnalysisOptions, analyze_stack
from microfacet.core.densities import wasserstein1
from microfacet.forward.synth import PRESETS, generate_stack, preset
from microfacet.analysis.roi import nearest_roi_index, roi_grid


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
    okt = np.isfinite(r.tilt_deg) & vis
    true_means = np.array([c.mean_nm for c in p.thickness])
    if r.thickness_fit is not None:
        fit_means = r.thickness_fit.mixture.means_nm
        mean_err = float(np.max(np.min(np.abs(true_means[:, None] - fit_means[None, :]), 1)))
        k_fit = len(fit_means)
    else:
        mean_err, k_fit = float("nan"), 0
    de = r.delta_e_stats
    return {
        "roi_mae_nm": float(np.mean(errs)) if errs else float("nan"),
        "k": f"{k_fit}/{len(p.thickness)}",
        "mean_err_nm": mean_err,
        "tilt_med_deg": float(np.median(np.abs(r.tilt_deg[okt] - t_true[okt]))) if okt.any()
        else float("nan"),
        "w1_deg": wasserstein1(r.tilt_deg[okt], t_true[vis]) if okt.any() else float("nan"),
        "de_mean": de["mean"] if de["mean"] is not None else float("nan"),
        "de_median": de["median"] if de["median"] is not None else float("nan"),
        "masked": r.mask.fraction,
        "exposure": r.exposure,
    }


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
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
    print("| preset | mode | ROI thickness MAE (nm) | components found/true | worst mean error (nm) "
          "| tilt median abs err (deg) | NDF W1 (deg) | dE00 mean / median | masked | exposure "
          "(true) | time (s) |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
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
                t0 = time.perf_counter()
                r = analyze_stack(folder, AnalysisOptions(mode=mode))
                dt = time.perf_counter() - t0
                s = score(r, truth, p)
                print(f"| {name} | {mode} | {s['roi_mae_nm']:.2f} | {s['k']} | "
                      f"{s['mean_err_nm']:.1f} | {s['tilt_med_deg']:.2f} | {s['w1_deg']:.2f} | "
                      f"{s['de_mean']:.2f} / {s['de_median']:.2f} | {s['masked']:.3f} | "
                      f"{s['exposure']:.3f} ({p.exposure:g}) | {dt:.1f} |", flush=True)


if __name__ == "__main__":
    main()
