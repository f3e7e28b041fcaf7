"""Accuracy of the analysis on synthetic truth, per preset: one stack each in both modes, or
many stacks with drawn noise and roughness.

Default (``sweep=0``): for each preset, generates a stack (seed 11, not the fixture's; 512 px,
24 slices) and analyses it in the seed mode and the joint mode, then scores against the truth
(:func:`pipelines._scoring.preset_scores`): ROI thickness MAE (joint: the ROI mean of the
per-pixel thickness), mixture components found/true and the worst true-mean error, per-pixel
tilt median |error|, NDF Wasserstein-1, ΔE00 mean and median, masked fraction, exposure
(true in brackets) and the analysis time. ``stack=PATH`` scores an existing synthetic stack
(with ``truth/``; e.g. fixtures/stacks/nd-fixture) instead; its results go under ``out``.

``sweep=N``: N stacks (256 px, 16 slices) cycling over the presets, each with its own seed,
a sensor noise drawn log-uniformly (full well 150 … 20,000 e⁻, i.e. relative noise 1.5 % …
15 % at a linear signal of 0.3) and its tilt lobes scaled by a factor drawn uniformly in
0.5 … 2 (each lobe capped at 20°), analysed in ``mode`` with
:func:`microfacet.workflow.run_batch` (local processes, or a Dask ``scheduler``): a table of
medians per preset, the Spearman rank correlation of each error with noise and with
roughness (stderr), ``out/synthetic-sweep.csv`` (one row per stack) and
``out/synthetic-sweep.png`` (errors against noise and roughness). docs/accuracy.md records
one such sweep (42 stacks) below the development table.
"""

from __future__ import annotations

import json
import math
import time
from pathlib import Path

import numpy as np

from pipelines import Study
from pipelines._shared import md_table, note, pyplot, save_figure, write_csv

STUDY = Study(
    name="accuracy-presets",
    question="How accurate are the seed and joint modes on each development preset (and "
             "across noise and roughness)?",
    doc=("docs/accuracy.md", "accuracy-presets"),
    run_time="8 min",
    quick_time="14 s",
    options={"presets": ("", "presets, comma-separated (default: all; sweep: all but noisy "
                             "and overexposed)"),
             "size": (0, "image side, px (default 512; sweep 256)"),
             "slices": (0, "slices per stack (default 24; sweep 16)"),
             "seed": (11, "seed of the stacks (sweep: seeds from 1000)"),
             "stack": ("", "score this existing synthetic stack (with truth/) instead"),
             "sweep": (0, "N > 0: N stacks with drawn noise and roughness"),
             "mode": ("joint", "sweep: analysis mode"),
             "jobs": (0, "local worker processes (0: the batch's default)"),
             "scheduler": ("", "sweep: Dask scheduler address"),
             "work": ("", "folder for stacks and results (default out/work); reused: a sweep "
                          "resumes")},
)

SWEEP_PRESETS = ("sd", "nd", "thick", "steep", "thin", "grainy", "16bit")
SIGNAL = 0.3  # linear signal at which the relative noise is quoted


def _generate(folder: Path, p) -> None:
    """Generate ``p`` into ``folder`` unless the same parameters are there already."""
    from microfacet.forward.synth import generate_stack

    meta = folder / "truth" / "params.json"
    if meta.is_file() and json.loads(meta.read_text()).get("params") == json.loads(
            json.dumps(p.to_json())):
        return
    generate_stack(folder, p, overwrite=True)


def _analyse(stacks, results: Path, mode, jobs, scheduler=None) -> list:
    from microfacet.analysis.options import AnalysisOptions
    from microfacet.workflow.batch import run_batch

    res = run_batch(stacks, results, options=AnalysisOptions(mode=mode), report=False,
                    jobs=jobs or None, scheduler=scheduler or None)
    return res.rows


# ------------------------------------------------------------------- one stack per preset
def _presets_table(jobs_, work: Path, jobs) -> str:
    from pipelines._scoring import preset_scores

    rows = []
    results = {}
    for mode in ("seed", "joint"):
        brows = _analyse([f for _, f, _ in jobs_], work / "results" / mode, mode, jobs)
        results[mode] = brows
    for k, (name, folder, p) in enumerate(jobs_):
        for mode in ("seed", "joint"):
            b = results[mode][k]
            if b["status"] not in ("done", "skipped"):
                rows.append([name, mode, f"failed: {b.get('reason', '')[:60]}"] + [""] * 8)
                continue
            s = preset_scores(b["results"], folder / "truth", p)
            rows.append([name, mode, f"{s['roi_mae_nm']:.2f}",
                         f"{s['components_found']}/{s['components_true']}",
                         f"{s['worst_mean_err_nm']:.1f}", f"{s['tilt_median_err_deg']:.2f}",
                         f"{s['ndf_w1_deg']:.2f}",
                         f"{s['delta_e_mean']:.2f} / {s['delta_e_median']:.2f}",
                         f"{s['masked_fraction']:.3f}", f"{s['exposure']:.3f} ({p.exposure:g})",
                         f"{b.get('time_s') or math.nan:.1f}"])
            note(" | ".join(rows[-1]))
    return md_table(["preset", "mode", "ROI thickness MAE (nm)", "components found/true",
                     "worst mean error (nm)", "tilt median abs err (deg)", "NDF W1 (deg)",
                     "dE00 mean / median", "masked", "exposure (true)", "time (s)"], rows)


# --------------------------------------------------------------- many stacks (the sweep)
def design(n, presets, *, size, slices, seed0=1000):
    """The N parameter sets: preset cycled, seed, noise and roughness drawn per stack."""
    from microfacet.forward.synth import TiltLobe, preset

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
    from microfacet.core.distributions import NDFMixture

    return NDFMixture(lobes).rms_sd_deg


COLUMNS = ("name", "preset", "seed", "full_well_e", "noise_pct", "roughness_scale",
           "rms_slope_true_deg", "status", "reason", "time_s", "thickness_mae_nm",
           "roi_mae_nm", "tilt_median_err_deg", "ndf_w1_deg", "ndf_rms_err_deg",
           "components_found", "components_true", "worst_mean_err_nm", "delta_e_mean",
           "masked_fraction", "colour_noise_de")


def sweep_plot(rows, path: Path) -> None:
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


def sweep_table(rows) -> str:
    """Markdown table of medians per preset."""
    body = []
    for name in sorted({r["preset"] for r in rows}):
        rs = [r for r in rows if r["preset"] == name]
        ok = [r for r in rs if r["status"] in ("done", "skipped")]

        def med(k):
            v = [r[k] for r in ok if r.get(k) is not None and not math.isnan(r[k])]
            return f"{np.median(v):.2f}" if v else "–"

        hit = sum(r["components_found"] == r["components_true"] for r in ok)
        body.append([name, f"{len(rs)} ({len(rs) - len(ok)})", med("thickness_mae_nm"),
                     med("roi_mae_nm"), med("tilt_median_err_deg"), med("ndf_w1_deg"),
                     med("ndf_rms_err_deg"), f"{hit}/{len(ok)}", med("worst_mean_err_nm"),
                     med("delta_e_mean")])
    return md_table(["preset", "stacks (failed)", "thickness MAE (nm)", "ROI thickness MAE (nm)",
                     "tilt median err (°)", "NDF W1 (°)", "NDF rms error (°)",
                     "components found = true", "worst mean err (nm)", "ΔE00 mean"], body)


def correlations(rows) -> list:
    """Spearman rank correlation of each error with noise and with roughness."""
    from scipy.stats import spearmanr

    ok = [r for r in rows if r["status"] in ("done", "skipped")]
    out = []
    for key in ("thickness_mae_nm", "tilt_median_err_deg", "ndf_w1_deg"):
        parts = []
        for xkey, label in (("noise_pct", "noise"), ("rms_slope_true_deg", "roughness")):
            pairs = [(r[xkey], r[key]) for r in ok if not math.isnan(r[key])]
            if len(pairs) >= 4:
                parts.append(f"{label} ρ = {spearmanr(*zip(*pairs)).statistic:+.2f}")
        out.append(f"{key}: " + (", ".join(parts) or "too few stacks"))
    return out


def _sweep(n, presets, *, size, slices, mode, jobs, scheduler, work: Path, out: Path) -> str:
    from pipelines._scoring import preset_scores

    plan = design(n, presets, size=size, slices=slices)
    t0 = time.perf_counter()
    stacks = []
    for name, p, _ in plan:
        _generate(work / "stacks" / name, p)
        stacks.append(work / "stacks" / name)
    t_gen = time.perf_counter() - t0
    t1 = time.perf_counter()
    brows = _analyse(stacks, work / "results" / mode, mode, jobs, scheduler)
    t_an = time.perf_counter() - t1
    rows = []
    for (name, p, rough), folder, b in zip(plan, stacks, brows):
        row = {"name": name, "preset": p.preset, "seed": p.seed, "full_well_e": p.full_well_e,
               "noise_pct": noise_pct(p), "roughness_scale": rough,
               "rms_slope_true_deg": rms_slope_deg([(lb.weight, lb.sd_deg)
                                                    for lb in p.tilt_lobes]),
               "status": b["status"], "reason": b.get("reason", ""), "time_s": b.get("time_s")}
        if b["status"] in ("done", "skipped"):
            row.update(preset_scores(b["results"], folder / "truth", p))
        rows.append(row)
    write_csv(out / "synthetic-sweep.csv", rows, COLUMNS)
    sweep_plot(rows, out / "synthetic-sweep.png")
    where = "scheduler" if scheduler else f"jobs={jobs or 'auto'}"
    note(f"{n} stacks of {size}×{size} px × {slices} slices, mode {mode}; generation "
         f"{t_gen:.0f} s, analysis (batch, {where}) {t_an:.0f} s; one row per stack in "
         f"{out / 'synthetic-sweep.csv'}, plot {out / 'synthetic-sweep.png'}")
    return (sweep_table(rows) + "\n\nSpearman rank correlation of each error with the noise "
            "and with the true roughness, over all stacks:\n\n"
            + "\n".join(f"* {line}" for line in correlations(rows)))


def run(*, quick: bool, out: Path, presets="", size=0, slices=0, seed=11, stack="", sweep=0,
        mode="joint", jobs=0, scheduler="", work="") -> str:
    from microfacet.forward.synth import PRESETS, SynthParams, preset

    work = Path(work) if work else out / "work"
    names = [p for p in presets.split(",") if p]
    if sweep:
        if quick:
            sweep, size, slices, jobs = min(sweep, 2), 64, 6, jobs or 1
        return _sweep(sweep, names or list(SWEEP_PRESETS), size=size or 256,
                      slices=slices or 16, mode=mode, jobs=jobs, scheduler=scheduler,
                      work=work, out=out)
    if stack:
        meta = json.loads((Path(stack) / "truth" / "params.json").read_text())["params"]
        p = SynthParams.from_json(meta)
        note(f"{stack}: {p.height_px}x{p.width_px} px, {p.n_slices} slices, seed {p.seed}")
        return _presets_table([(meta.get("preset", "stack"), Path(stack), p)], work,
                              jobs or (1 if quick else 0))
    size, slices = size or 512, slices or 24
    if quick:
        names, size, slices, jobs = names or ["nd", "sd"], 96, 8, jobs or 1
    jobs_ = []
    for name in names or list(PRESETS):
        p = preset(name, seed=seed, height_px=size, width_px=size, n_slices=slices)
        _generate(work / "stacks" / name, p)
        jobs_.append((name, work / "stacks" / name, p))
    note(f"{size}x{size} px, {slices} slices, seed {seed}")
    return _presets_table(jobs_, work, jobs)
