"""Accuracy across many synthetic stacks: error against image noise and surface roughness.

Generates N synthetic stacks (``microfacet.forward.synth``) cycling over the presets, each with its
own seed, a sensor noise drawn log-uniformly (full well 150 … 20,000 e⁻, i.e. relative noise
1.5 % … 15 % at a linear signal of 0.3) and its tilt lobes scaled by a factor drawn
uniformly in 0.5 … 2 (each lobe capped at 20°). Analyses them all with
:func:`microfacet.workflow.run_batch` (local processes, or ``--scheduler`` a Dask cluster) and
scores every results folder against its truth:

* ``thickness_mae_nm``: mean |estimated − true| per-pixel thickness (unmasked, finite);
* ``roi_thickness_mae_nm``: the same for ROI means (the ROI grid of the analysis);
* ``tilt_median_err_deg``: median |estimated − true| per-pixel tilt (visible, finite);
* ``ndf_w1_deg``: Wasserstein-1 distance between estimated and true tilt distributions;
* ``ndf_rms_err_deg``: fitted NDF rms slope angle − true (signed);
* ``components_found`` / ``components_true`` and ``worst_mean_err_nm`` (largest distance
  from a true thickness-component mean to the nearest fitted mean): mixture recovery.

Writes ``--csv`` (one row per stack), ``--plot`` (errors against noise and roughness,
coloured by preset) and prints a markdown table of medians per preset; ``--docs`` replaces
the sweep section of docs/accuracy.md with it. The CSV and the plot go to docs/data/ and
docs/img/ with ``--docs``, else to out/synthetic-sweep/.

Run:  python pipelines/synthetic_sweep.py --n 42 --jobs 2 --docs
      python pipelines/synthetic_sweep.py --n 6 --size 128 --slices 12   (a quick look)
"""

from __future__ import annotations

import json
import math
import tempfile
import time
from pathlib import Path

import numpy as np
from _shared import (
    DOCS,
    ROOT,
    md_header,
    md_row,
    parser,
    pyplot,
    replace_block,
    save_figure,
    tilt_scores,
    worst_mean_error,
    write_csv,
)

from microfacet.analysis.options import AnalysisOptions
from microfacet.analysis.roi import nearest_roi_index, roi_grid
from microfacet.workflow.batch import run_batch
from microfacet.core.distributions import NDFMixture
from microfacet.forward.synth import TiltLobe, generate_stack, preset

DEFAULT_PRESETS = ("sd", "nd", "thick", "steep", "thin", "grainy", "16bit")
SIGNAL = 0.3  # linear signal at which the relative noise is quoted
MARK_START = "<!-- synthetic-sweep:start -->"
MARK_END = "<!-- synthetic-sweep:end -->"


def design(n, presets, *, size, slices, seed0=1000):
    """The N parameter sets: preset cycled, seed, noise and roughness drawn per stack."""
    out = []
    for i in range(n):
        name = presets[i % len(presets)]
        rng = np.random.default_rng(seed0 + i)
        full_well = float(10 ** rng.uniform(math.log10(150.0), math.log10(20000.0)))
        rough = float(rng.uniform(0.5, 2.0))
        base = preset(name)
        lobes = tuple(TiltLobe(lb.weight, min(20.0, lb.sd_deg * rough)) for lb in base.tilt_lobes)
        p = preset(name, seed=seed0 + i, height_px=size, width_px=size, n_slices=slices,
                   full_well_e=full_well, tilt_lobes=lobes)
        out.append((f"{i:03d}_{name}", p, rough))
    return out


def noise_pct(p) -> float:
    """Relative sensor noise (%) at a linear signal of 0.3."""
    var = (SIGNAL / p.full_well_e if p.full_well_e else 0.0) + p.read_noise ** 2
    return 100.0 * math.sqrt(var) / SIGNAL


def rms_slope_deg(lobes) -> float:
    """rms slope angle of a mixture of zero-mean Gaussian-slope lobes (weights normalised)."""
    return NDFMixture(lobes).rms_sd_deg


def score(results: Path, truth_dir: Path, p) -> dict:
    """Scores of one results folder against its synthetic truth."""
    s = json.loads((results / "summary.json").read_text())
    d_true = np.load(truth_dir / "thickness_nm.npy")
    t_true = np.load(truth_dir / "tilt_deg.npy")
    vis = np.load(truth_dir / "visible.npy")
    d_est = np.load(results / "thickness_nm.npy")
    t_est = np.load(results / "tilt_deg.npy")
    used = ~np.load(results / "mask.npy") & np.isfinite(d_est)
    out = {"thickness_mae_nm": float(np.mean(np.abs(d_est[used] - d_true[used])))
           if used.any() else math.nan}
    rows, cols, size = roi_grid(d_true.shape, size_px=s["parameters"]["roi_size_px"])
    ri, ci = nearest_roi_index(d_true.shape, rows, cols, size)
    idx = (ri[:, None] * len(cols) + ci[None, :])[used]
    n = np.bincount(idx, minlength=len(rows) * len(cols))
    ok = n >= 20
    est = np.bincount(idx, d_est[used], minlength=n.size)[ok] / n[ok]
    tru = np.bincount(idx, d_true[used], minlength=n.size)[ok] / n[ok]
    out["roi_thickness_mae_nm"] = float(np.mean(np.abs(est - tru))) if ok.any() else math.nan
    out["tilt_median_err_deg"], out["ndf_w1_deg"] = tilt_scores(t_est, t_true, vis)
    lobes = s["ndf"]["mixture"]["components"]
    out["ndf_rms_err_deg"] = (rms_slope_deg([(c["weight"], c["sd_deg"]) for c in lobes])
                              - rms_slope_deg([(lb.weight, lb.sd_deg) for lb in p.tilt_lobes])
                              if lobes else math.nan)
    comps = s["thickness"]["mixture"]["components"]
    true_means = np.array([c.mean_nm for c in p.thickness])
    out["components_true"] = len(true_means)
    out["components_found"] = len(comps)
    out["worst_mean_err_nm"] = worst_mean_error(true_means, [c["mean_nm"] for c in comps])
    out["delta_e_mean"] = s["delta_e"]["mean"]
    out["masked_fraction"] = s["masked_fraction"]
    out["colour_noise_de"] = s.get("colour_noise_de")
    return out


COLUMNS = ("name", "preset", "seed", "full_well_e", "noise_pct", "roughness_scale",
           "rms_slope_true_deg", "status", "reason", "time_s", "thickness_mae_nm",
           "roi_thickness_mae_nm", "tilt_median_err_deg", "ndf_w1_deg", "ndf_rms_err_deg",
           "components_found", "components_true", "worst_mean_err_nm", "delta_e_mean",
           "masked_fraction", "colour_noise_de")


def plot(rows, path: Path) -> None:
    plt = pyplot()
    from matplotlib.ticker import FormatStrFormatter, LogLocator, NullFormatter

    metrics = (("thickness_mae_nm", "thickness MAE (nm)"),
               ("tilt_median_err_deg", "tilt median |error| (°)"),
               ("ndf_w1_deg", "NDF W1 distance (°)"))
    axes_x = (("noise_pct", "relative noise at signal 0.3 (%)", True),
              ("rms_slope_true_deg", "true rms slope angle (°)", False))
    presets = sorted({r["preset"] for r in rows})
    colours = dict(zip(presets, plt.get_cmap("tab10").colors))
    fig, axes = plt.subplots(len(metrics), 2, figsize=(9, 8.5), sharex="col")
    done = [r for r in rows if r["status"] in ("done", "skipped")]
    for i, (key, label) in enumerate(metrics):
        for j, (xkey, xlabel, logx) in enumerate(axes_x):
            ax = axes[i, j]
            for name in presets:
                pts = [(r[xkey], r[key]) for r in done if r["preset"] == name
                       and r.get(key) is not None and not math.isnan(r[key])]
                if pts:
                    x, y = zip(*pts)
                    ax.scatter(x, y, s=22, color=colours[name], label=name, alpha=0.85)
            if logx:
                ax.set_xscale("log")
                ax.xaxis.set_major_locator(LogLocator(subs=(1.0, 2.0, 5.0)))
                ax.xaxis.set_major_formatter(FormatStrFormatter("%g"))
                ax.xaxis.set_minor_formatter(NullFormatter())
            ax.set_yscale("log")
            ax.yaxis.set_major_locator(LogLocator(subs=(1.0, 2.0, 5.0)))
            ax.yaxis.set_major_formatter(FormatStrFormatter("%g"))
            ax.yaxis.set_minor_formatter(NullFormatter())
            ax.grid(True, which="both", alpha=0.3)
            if j == 0:
                ax.set_ylabel(label)
            if i == len(metrics) - 1:
                ax.set_xlabel(xlabel)
    axes[0, 1].legend(title="preset", fontsize=8, title_fontsize=8, loc="upper left",
                      bbox_to_anchor=(1.02, 1.0))
    fig.suptitle(f"Synthetic sweep: {len(done)} stacks, error against noise and roughness")
    fig.tight_layout()
    save_figure(fig, path)


def table(rows) -> str:
    """Markdown table of medians per preset."""
    lines = [md_header(["preset", "stacks (failed)", "thickness MAE (nm)",
                        "ROI thickness MAE (nm)", "tilt median err (°)", "NDF W1 (°)",
                        "NDF rms error (°)", "components found = true", "worst mean err (nm)",
                        "ΔE00 mean"])]
    for name in sorted({r["preset"] for r in rows}):
        rs = [r for r in rows if r["preset"] == name]
        ok = [r for r in rs if r["status"] in ("done", "skipped")]

        def med(k):
            v = [r[k] for r in ok if r.get(k) is not None and not math.isnan(r[k])]
            return f"{np.median(v):.2f}" if v else "–"

        hit = sum(r["components_found"] == r["components_true"] for r in ok)
        lines.append(md_row([name, f"{len(rs)} ({len(rs) - len(ok)})", med("thickness_mae_nm"),
                             med("roi_thickness_mae_nm"), med("tilt_median_err_deg"),
                             med("ndf_w1_deg"), med("ndf_rms_err_deg"), f"{hit}/{len(ok)}",
                             med("worst_mean_err_nm"), med("delta_e_mean")]))
    return "\n".join(lines)


def correlations(rows) -> str:
    """Spearman rank correlation of each error with noise and with roughness."""
    from scipy.stats import spearmanr

    ok = [r for r in rows if r["status"] in ("done", "skipped")]
    out = []
    for key in ("thickness_mae_nm", "tilt_median_err_deg", "ndf_w1_deg"):
        parts = []
        for xkey, label in (("noise_pct", "noise"), ("rms_slope_true_deg", "roughness")):
            pairs = [(r[xkey], r[key]) for r in ok if not math.isnan(r[key])]
            if len(pairs) >= 4:
                rho = spearmanr(*zip(*pairs)).statistic
                parts.append(f"{label} ρ = {rho:+.2f}")
        out.append(f"{key}: " + ", ".join(parts))
    return "\n".join(out)


def main(argv=None):
    ap = parser(__doc__)
    ap.add_argument("--n", type=int, default=42, help="number of stacks (default 42)")
    ap.add_argument("--presets", nargs="+", default=list(DEFAULT_PRESETS))
    ap.add_argument("--size", type=int, default=256, help="image side in px (default 256)")
    ap.add_argument("--slices", type=int, default=16, help="slices per stack (default 16)")
    ap.add_argument("--mode", choices=("joint", "seed"), default="joint")
    ap.add_argument("--jobs", type=int, default=None, help="local worker processes")
    ap.add_argument("--scheduler", default=None, help="Dask scheduler address")
    ap.add_argument("--work", default=None,
                    help="folder for the stacks and results (default: a temporary one); "
                         "reusing it resumes a sweep")
    ap.add_argument("--csv", default=None,
                    help="per-stack CSV (default docs/data/synthetic-sweep.csv with --docs, "
                         "else out/synthetic-sweep/synthetic-sweep.csv)")
    ap.add_argument("--plot", default=None,
                    help="plot (default docs/img/synthetic-sweep.png with --docs, else "
                         "out/synthetic-sweep/synthetic-sweep.png)")
    ap.add_argument("--docs", action="store_true",
                    help="replace the sweep section of docs/accuracy.md (and write the CSV and "
                         "the plot under docs/)")
    args = ap.parse_args(argv)
    dest = {"csv": DOCS / "data", "plot": DOCS / "img"} if args.docs else \
        {"csv": ROOT / "out" / "synthetic-sweep", "plot": ROOT / "out" / "synthetic-sweep"}
    csv_path = Path(args.csv) if args.csv else dest["csv"] / "synthetic-sweep.csv"
    plot_path = Path(args.plot) if args.plot else dest["plot"] / "synthetic-sweep.png"

    tmp = None
    if args.work is None:
        tmp = tempfile.TemporaryDirectory()
        work = Path(tmp.name)
    else:
        work = Path(args.work)
    plan = design(args.n, args.presets, size=args.size, slices=args.slices)
    t0 = time.perf_counter()
    stacks = []
    for name, p, _ in plan:
        folder = work / "stacks" / name
        if not (folder / "stack.json").exists():
            generate_stack(folder, p, overwrite=True)
        stacks.append(folder)
    t_gen = time.perf_counter() - t0
    res = run_batch(stacks, work / "results", jobs=args.jobs, scheduler=args.scheduler,
                    options=AnalysisOptions(mode=args.mode), report=False)
    rows = []
    for (name, p, rough), folder, brow in zip(plan, stacks, res.rows):
        row = {"name": name, "preset": p.preset, "seed": p.seed, "full_well_e": p.full_well_e,
               "noise_pct": noise_pct(p), "roughness_scale": rough,
               "rms_slope_true_deg": rms_slope_deg([(lb.weight, lb.sd_deg) for lb in p.tilt_lobes]),
               "status": brow["status"], "reason": brow.get("reason", ""),
               "time_s": brow.get("time_s")}
        if brow["status"] in ("done", "skipped"):
            row.update(score(Path(brow["results"]), folder / "truth", p))
        rows.append(row)
    write_csv(csv_path, rows, COLUMNS)
    plot(rows, plot_path)
    summary = table(rows)
    corr = correlations(rows)
    where = "scheduler" if args.scheduler else f"jobs={args.jobs or 'auto'}"
    header = (f"{args.n} stacks of {args.size}×{args.size} px × {args.slices} slices, mode "
              f"{args.mode}; generation {t_gen:.0f} s, analysis (batch, "
              f"{where}) "
              f"{res.elapsed_s:.0f} s.")
    print(header + "\n\n" + summary + "\n\nSpearman rank correlations:\n" + corr)
    if args.docs:
        rel_csv = csv_path.resolve().relative_to(ROOT) if csv_path.resolve().is_relative_to(ROOT) \
            else csv_path
        rel_png = plot_path.resolve().relative_to(DOCS) \
            if plot_path.resolve().is_relative_to(DOCS) else plot_path
        text = (f"Reproduce: `python pipelines/synthetic_sweep.py --n {args.n} --size {args.size} "
                f"--slices {args.slices} --docs`. {header} Medians per preset (one row per "
                f"stack in `{rel_csv}`):\n\n{summary}\n\nSpearman rank correlation of each "
                f"error with the noise and with the true roughness, over all stacks:\n\n"
                + "\n".join(f"* {line}" for line in corr.splitlines())
                + f"\n\n![errors against noise and roughness]({rel_png})")
        replace_block(DOCS / "accuracy.md", MARK_START, MARK_END, text)
    if tmp is not None:
        tmp.cleanup()


if __name__ == "__main__":
    main()
