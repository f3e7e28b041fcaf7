"""Conditioning of tilt from colour: ΔE00 per degree of tilt and the tilt uncertainty it gives.

Under the microscope's coaxial light a facet tilted by θ is seen at incidence θ (0 … asin(NA)/2),
so its colour carries its tilt only through the angle dependence of the thin-film colour. For
every oxide thickness d of the analysis range this script computes

* J(d, θ) = |dLab/dθ| in ΔE00 per degree (central difference ±0.25°, direct 1 nm spectral
  evaluation, film/substrate/illuminant defaults) at θ = 5, 10 and 20°;
* K(d, θ) = ΔE00 per nm of thickness (central difference ±0.25 nm) and J/K, the thickness
  change that looks like one degree of tilt;
* σ_tilt = σ_n / J, the linearised 1-σ tilt uncertainty of ``tilt.invert_tilt`` for colour
  noise σ_n (ΔE00 per Lab component, as ``colour_image.estimate_colour_noise`` reports it)
  of 0.5, 1 and 2 ΔE00, capped at the tilt range; and with a thickness uncertainty σ_d:
  σ_tilt = sqrt(σ_n² + (K σ_d)²) / J;
* a Monte-Carlo check: uniform 64 × 64 patches at (θ, d) rendered like ``microfacet.forward.synth``
  (colour table, exposure 1, shot + read noise, 8-bit sRGB), inverted with
  ``tilt.invert_tilt`` at the true thickness (0.5° grid, no prior): the measured spread of
  the recovered tilts against σ_n / J and against the σ ``invert_tilt`` reports;
* J as the analysis computes it (``invert_tilt``'s central differences of the interpolated
  colour table on its 0.5° grid) against the exact J.

Returns the page (docs/conditioning.md below its title) and writes ``out/img/conditioning.png``
(``--docs`` copies it to docs/img/).
"""

from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np

from pipelines import Study
from pipelines._shared import (
    Doc,
    lab_direct,
    md_table,
    noisy_scene,
    pyplot,
    save_figure,
    through_sensor,
)

STUDY = Study(
    name="accuracy-conditioning",
    question="For which films and tilts does colour carry the tilt (ΔE00 per degree and the "
             "tilt uncertainty it gives)?",
    doc=("docs/conditioning.md", "accuracy-conditioning"),
    run_time="10 s",
    quick_time="9 s",
    options={"na": (0.8, "numerical aperture"),
             "d_max": (400.0, "largest thickness, nm (the analysis' default range is 0-400)"),
             "sigma_d": (0.3, "thickness uncertainty for the combined σ, nm (the synthetic "
                              "presets' fine thickness variation)")},
    doc_files={"img/conditioning.png": "docs/img/conditioning.png"},
)

TILTS = (5.0, 10.0, 20.0)
NOISES = (0.5, 1.0, 2.0)
ROW_D = (10, 25, 51, 75, 100, 112, 130, 149, 175, 200, 235, 260, 300, 350, 400)


def sensitivities(d, tilts, h_deg=0.25, h_nm=0.25):
    """J (ΔE00/°) and K (ΔE00/nm), shape (len(tilts), len(d))."""
    from microfacet.colour.difference import delta_e_2000

    th = np.asarray(tilts, float)[:, None]
    dd = np.asarray(d, float)[None, :]
    J = delta_e_2000(lab_direct(th + h_deg, dd), lab_direct(th - h_deg, dd)) / (2 * h_deg)
    K = delta_e_2000(lab_direct(th + 0 * dd, dd + h_nm),
                     lab_direct(th + 0 * dd, np.maximum(dd - h_nm, 0))) / (
        dd + h_nm - np.maximum(dd - h_nm, 0))
    return J, K


def table_sensitivity(model, d, tilts, max_tilt, step=0.5):
    """J as invert_tilt computes it: central differences of the table rows on its θ grid."""
    from microfacet.analysis.tilt import model_lab_rows
    from microfacet.colour.difference import delta_e_2000

    g = np.arange(0.0, max_tilt + 1e-9, step)
    rl = model_lab_rows(model, np.asarray(d, float), g).astype(np.float32)
    sens = np.empty(rl.shape[:2], np.float32)
    sens[:, 1:-1] = delta_e_2000(rl[:, 2:], rl[:, :-2]) / (2 * step)
    sens[:, 0] = delta_e_2000(rl[:, 1], rl[:, 0]) / step
    sens[:, -1] = delta_e_2000(rl[:, -1], rl[:, -2]) / step
    k = [int(round(t / step)) for t in tilts]
    return sens[:, k].T  # (tilts, d)


def patch_lab(table, theta, d, *, full_well, read_noise, rng, size=64):
    """Uniform patch at (θ, d) through the synthetic sensor: (Lab float32, 8-bit sRGB)."""
    from microfacet.forward.synth import SynthParams

    p = SynthParams(full_well_e=full_well, read_noise=read_noise)
    rgb = table.linear_rgb_at(np.full((size, size), theta), np.full((size, size), d))
    return through_sensor(rgb, p, rng)


def monte_carlo(model, max_tilt, thicknesses, tilts, sensors, J_at):
    from microfacet.analysis.colour_image import estimate_colour_noise
    from microfacet.analysis.mask import colour_mask
    from microfacet.analysis.options import MaskOptions, TiltOptions
    from microfacet.analysis.tilt import TiltRows, invert_tilt, model_lab_rows, tilt_grid

    g = tilt_grid(max_tilt, 0.5)
    rows = []
    for sname, fw, rn in sensors:
        rng = np.random.default_rng(7)
        for d in thicknesses:
            rl = model_lab_rows(model, np.array([float(d)]), g)
            for th in tilts:
                lab, enc = patch_lab(model.table, th, d, full_well=fw, read_noise=rn, rng=rng)
                cm = colour_mask(enc, MaskOptions(shadow_ratio=0.0))
                ok = ~cm.mask
                sn = estimate_colour_noise(lab, cm.mask, delta_e_method=model.delta_e_method)
                px = lab[ok]
                inv = invert_tilt(px, np.zeros(px.shape[0], np.intp),
                                  TiltRows(rl, np.array([float(d)]), sn), g, model,
                                  TiltOptions())
                t = inv.tilt_deg.astype(np.float64)
                j = J_at(th, d)
                rows.append(dict(sensor=sname, d=d, theta=th, noise=sn, n=px.shape[0],
                                 masked=float(cm.mask.mean()), sd=float(np.std(t)),
                                 mad=float(np.median(np.abs(t - th))),
                                 bias=float(np.median(t) - th),
                                 pred=min(sn / j, max_tilt) if j > 0 else max_tilt,
                                 reported=float(np.median(inv.tilt_sigma_deg))))
    return rows


def scene_noise(size=256):
    """estimate_colour_noise on the nd and noisy presets' sharp noisy images (texture incl.)."""
    return {name: noisy_scene(name, size=size, seed=11)[-1] for name in ("nd", "noisy")}


def intervals(d, ok):
    """Runs of True in ``ok`` as 'a–b' strings of d."""
    out, start = [], None
    for i, v in enumerate(ok):
        if v and start is None:
            start = i
        if (not v or i == len(ok) - 1) and start is not None:
            end = i if v else i - 1
            out.append(f"{d[start]:g}–{d[end]:g}" if end > start else f"{d[start]:g}")
            start = None
    return ", ".join(out) if out else "none"


def plot(path, d, J, K, tilts, max_tilt, sigma_typ):
    fig, ax = pyplot().subplots(1, 3, figsize=(11.5, 3.3))
    for k, th in enumerate(tilts):
        ax[0].plot(d, J[k], color=f"C{k}", lw=1, label=f"θ = {th:g}°")
        s1 = np.minimum(1.0 / J[k], max_tilt)
        ax[1].plot(d, s1, color=f"C{k}", lw=1, label=f"θ = {th:g}°, σ_n = 1")
        ax[1].fill_between(d, np.minimum(0.5 / J[k], max_tilt), np.minimum(2.0 / J[k], max_tilt),
                           color=f"C{k}", alpha=0.12, lw=0)
        ax[2].plot(d, J[k] / K[k], color=f"C{k}", lw=1, label=f"θ = {th:g}°")
    ax[0].set_yscale("log")
    ax[0].set_ylabel("ΔE00 per degree of tilt", fontsize=7)
    ax[0].set_title("colour sensitivity to tilt J(d, θ)", fontsize=8)
    ax[1].set_yscale("log")
    ax[1].axhline(max_tilt, color="0.3", ls=":", lw=0.8)
    ax[1].annotate(f"whole range ({max_tilt:.1f}°)", (0.02, max_tilt), xycoords=(
        "axes fraction", "data"), fontsize=6, xytext=(0, -8), textcoords="offset points")
    for y, lab in ((2.0, "2°"), (5.0, "5°")):
        ax[1].axhline(y, color="0.5", ls="--", lw=0.7)
        ax[1].annotate(lab, (0.98, y), xycoords=("axes fraction", "data"), fontsize=6,
                       ha="right", xytext=(0, 2), textcoords="offset points")
    ax[1].set_ylabel("σ_tilt (°)", fontsize=7)
    ax[1].set_title(f"σ_tilt = σ_n / J (line σ_n = 1, band 0.5–2; typical {sigma_typ:.2f})",
                    fontsize=8)
    ax[2].set_yscale("log")
    ax[2].set_ylabel("nm of thickness that look like 1° of tilt", fontsize=7)
    ax[2].set_title("tilt–thickness confusion J / K", fontsize=8)
    for a in ax:
        a.set_xlabel("oxide thickness d (nm)", fontsize=7)
        a.tick_params(labelsize=6)
        a.grid(True, lw=0.3, alpha=0.5)
        a.legend(fontsize=6, loc="best")
    fig.tight_layout()
    save_figure(fig, path)


def f2(x):
    return f"{x:.2f}" if x < 10 else f"{x:.1f}"


class _Args:
    def __init__(self, **kw):
        self.__dict__.update(kw)


def run(*, quick: bool, out: Path, na=0.8, d_max=400.0, sigma_d=0.3) -> str:
    from microfacet.colour.model import FilmColourModel
    from microfacet.colour.table import build_colour_table

    args = _Args(quick=quick, na=na, d_max=d_max, sigma_d=sigma_d)
    t0 = time.perf_counter()
    max_tilt = math.degrees(math.asin(args.na)) / 2.0
    step = 2.0 if args.quick else 1.0
    d = np.arange(0.0, args.d_max + 1e-9, step)
    J, K = sensitivities(d, TILTS)
    table = build_colour_table(thickness_range_nm=(0.0, args.d_max),
                               theta_range_deg=(0.0, max_tilt + 0.5))
    model = FilmColourModel(table)
    Jt = table_sensitivity(model, d, TILTS, max_tilt)
    noise = scene_noise(128 if args.quick else 256)
    sigma_typ = noise["nd"]

    def J_at(th, dd):
        return float(sensitivities([dd], [th])[0][0, 0])

    mc_d = (51, 130, 235) if args.quick else (14, 51, 112, 130, 149, 235)
    sensors = [("default (8000 e⁻, read 0.002)", 8000.0, 0.002)]
    if not args.quick:
        sensors.append(("noisy preset (150 e⁻, read 0.02)", 150.0, 0.02))
    mc = monte_carlo(model, max_tilt, mc_d, TILTS, sensors, J_at)

    emit = Doc(echo=False)
    cmd = "python -m pipelines run accuracy-conditioning" + (" --quick" if args.quick else "") + (
        f" --set na={args.na:g}" if args.na != 0.8 else "") + (
        f" --set d_max={args.d_max:g}" if args.d_max != 400 else "") + (
        f" --set sigma_d={args.sigma_d:g}" if args.sigma_d != 0.3 else "")

    emit(f"Reproduce: `{cmd}`\n")
    emit(f"Under the microscope's coaxial light a facet tilted by θ is seen at incidence θ, "
         f"0 … asin(NA)/2 = {max_tilt:.2f}° for NA {args.na:g} (steeper facets are dark), so "
         f"its colour carries the tilt only through the angle dependence of the thin-film "
         f"colour. `tilt.invert_tilt` reports σ_tilt = σ_n / J, with σ_n the image colour "
         f"noise (ΔE00 per Lab component, `colour_image.estimate_colour_noise`) and J the colour "
         f"change per degree. This page shows J over the analysis' thickness range "
         f"(0–{args.d_max:g} nm; default film `TiO2_Jolivet2023_amorphous` on "
         f"`Ti_JohnsonChristy1974`, D65) at θ = 5, 10 and 20°, and the resulting σ_tilt, so "
         f"that users know for which films tilt from colour means anything. Companion page: "
         f"[speed-vs-error.md](speed-vs-error.md) (which search settings are worth their "
         f"time).\n")
    emit("![ΔE00 per degree, σ_tilt and the tilt–thickness confusion against thickness]"
         "(img/conditioning.png)\n")
    emit(f"J is the ΔE00 between the colours at θ ± 0.25° over 0.5° (direct 1 nm spectral "
         f"evaluation); K the same per nm of thickness. Typical colour noise: "
         f"`estimate_colour_noise` gives σ_n = {noise['nd']:.2f} on the `nd` preset "
         f"(8000 e⁻ full well, read noise 0.002, 8-bit; texture included, so an upper bound) "
         f"and {noise['noisy']:.2f} on the `noisy` preset (150 e⁻, read noise 0.02).\n")

    # summary numbers
    emit("## Over the whole range\n")
    emit(md_table(["tilt", "median J (ΔE00/°)", "J range (ΔE00/°)"] + [
        f"σ_n = {sn:g}: share of d with σ_tilt ≤ 2° / ≤ 5°" for sn in NOISES],
        [[f"{th:g}°", f"{np.median(J[k]):.3f}", f"{np.min(J[k]):.3f} – {np.max(J[k]):.3f}"] + [
            f"{100 * np.mean(sn / J[k] <= 2.0):.0f} % / {100 * np.mean(sn / J[k] <= 5.0):.0f} %"
            for sn in NOISES] for k, th in enumerate(TILTS)]))
    emit("")
    sig_n = 0.5
    for k, th in enumerate(TILTS):
        emit(f"* θ = {th:g}°, σ_n = {sig_n:g}: σ_tilt ≤ 2° for d in "
             f"{intervals(d, sig_n / J[k] <= 2.0)} nm; ≤ 5° for "
             f"{intervals(d, sig_n / J[k] <= 5.0)} nm.")
    emit("")

    # table at selected thicknesses
    emit("## At selected thicknesses\n")
    emit(f"σ columns: σ_tilt in degrees (capped at {max_tilt:.1f}° = no information). "
         f"\"+ σ_d\": with σ_n = 0.5 and a thickness uncertainty σ_d = {args.sigma_d:g} nm, "
         f"σ_tilt = sqrt(σ_n² + (K σ_d)²) / J. \"1° ≙\": the thickness change (nm) whose "
         f"colour change equals one degree of tilt at θ = 10°.\n")
    rows = []
    idx = [int(np.argmin(np.abs(d - v))) for v in ROW_D if v <= args.d_max]
    for i in idx:
        def sig(k, sn):
            return f2(min(sn / J[k, i], max_tilt))
        comb = min(math.sqrt(0.25 + (K[1, i] * args.sigma_d) ** 2) / J[1, i], max_tilt)
        comb20 = min(math.sqrt(0.25 + (K[2, i] * args.sigma_d) ** 2) / J[2, i], max_tilt)
        rows.append([f"{d[i]:g}", f"{J[0, i]:.3f}", f"{J[1, i]:.3f}", f"{J[2, i]:.3f}",
                     f"{K[1, i]:.2f}", sig(1, 0.5), sig(1, 1.0), sig(1, 2.0), sig(2, 0.5),
                     sig(2, 1.0), f2(comb), f2(comb20), f"{J[1, i] / K[1, i]:.3f}"])
    emit(md_table(["d (nm)", "J 5° (ΔE00/°)", "J 10°", "J 20°", "K 10° (ΔE00/nm)",
                   "σ 10°, σ_n 0.5", "σ 10°, 1", "σ 10°, 2", "σ 20°, 0.5", "σ 20°, 1",
                   "σ 10°, 0.5 + σ_d", "σ 20°, 0.5 + σ_d", "1° ≙ nm"], rows))

    # Monte Carlo
    emit("\n## Monte-Carlo check\n")
    emit("Uniform 64 × 64 patches at (θ, d), rendered through the colour table and the "
         "synthetic sensor, 8-bit sRGB → Lab, inverted by `invert_tilt` at the true thickness "
         "(0.5° grid, no prior, σ_n from `estimate_colour_noise` on the patch). SD and median "
         "|error| of the recovered tilts, against the linearised σ_n / J (exact J) and the "
         f"median σ `invert_tilt` reports. All capped at {max_tilt:.1f}°; a uniform guess "
         f"over the range has SD {max_tilt / math.sqrt(12):.1f}°.\n")
    emit(md_table(["sensor", "d (nm)", "θ (°)", "σ_n (ΔE00)", "SD of recovered tilt (°)",
                   "median |error| (°)", "median bias (°)", "σ_n / J (°)",
                   "reported σ (median, °)"],
                  [[r["sensor"], r["d"], f"{r['theta']:g}", f"{r['noise']:.2f}", f2(r["sd"]),
                    f2(r["mad"]), f"{r['bias']:+.2f}", f2(r["pred"]), f2(r["reported"])]
                   for r in mc]))

    good = [r for r in mc if r["pred"] < max_tilt / 3]
    if good:
        ratio = [r["mad"] / (0.674 * r["pred"]) for r in good]
        emit(f"\nWhere σ_n / J is below {max_tilt / 3:.1f}° ({len(good)} patches), the measured "
             f"median |error| is {min(ratio):.1f}–{max(ratio):.1f}× (median "
             f"{np.median(ratio):.1f}×) what a Gaussian with σ = σ_n / J gives (0.674 σ): the "
             f"linearised σ is optimistic by about that factor (the sRGB noise is not isotropic "
             f"in ΔE00, and 8-bit quantisation adds to it). Elsewhere the recovered tilts spread "
             f"over the whole range (SD → {max_tilt / math.sqrt(12):.1f}°, the SD of a uniform "
             f"guess) and pile up at 0° for small true tilts; the σ that `invert_tilt` reports "
             f"is then capped at the range, because J is evaluated at the solution's grid node "
             f"and is ~0 near 0°.")

    # table-based J
    ratio = Jt / np.maximum(J, 1e-9)
    emit("\n## J as the analysis computes it\n")
    emit(f"`invert_tilt` takes J from central differences of the model rows on its 0.5° grid, "
         f"interpolated from the colour table (θ step {table.theta_step_deg:.2f}°, d step "
         f"{table.thickness_step_nm:.2g} nm, bilinear in XYZ). Ratio table-J / exact J over "
         f"the thickness range (median, 5th–95th percentile): " + "; ".join(
             f"θ = {th:g}°: {np.median(ratio[k]):.2f} ({np.percentile(ratio[k], 5):.2f}–"
             f"{np.percentile(ratio[k], 95):.2f})" for k, th in enumerate(TILTS)) + ".\n")

    # conclusions with numbers
    k10 = TILTS.index(10.0)
    k20 = TILTS.index(20.0)
    k5 = TILTS.index(5.0)
    emit("## What this means\n")
    emit(f"* **Tilt from colour is weak everywhere in 0–{args.d_max:g} nm**: the median J is "
         f"{np.median(J[k5]):.3f} / {np.median(J[k10]):.3f} / {np.median(J[k20]):.3f} ΔE00 per "
         f"degree at 5 / 10 / 20°, while the colour changes by a median "
         f"{np.median(K[k10]):.2f} ΔE00 per nm of thickness. One degree of tilt at 10° looks "
         f"like {np.median(J[k10] / K[k10]):.3f} nm of thickness (median), so a thickness known "
         f"to {args.sigma_d:g} nm blurs the tilt by "
         f"{np.median(np.minimum(K[k10] * args.sigma_d / J[k10], max_tilt)):.1f}° (median over d) "
         f"even without image noise.")
    emit(f"* **Small tilts are invisible**: colour depends on θ through cos θ₁ ≈ 1 − θ₁²/2, so "
         f"J grows linearly from zero at normal incidence: at 5° σ_tilt with σ_n = 0.5 is "
         f"≤ 2° for only {100 * np.mean(0.5 / J[k5] <= 2):.0f} % of the thicknesses. The mode "
         f"of a zero-mean NDF lobe is exactly where colour says least.")
    thin = d[np.argmax(0.5 / J[k20] <= 5.0)]
    emit(f"* **Thin, pale films carry no tilt information**: below {thin:g} nm σ_tilt > 5° even "
         f"at 20° with σ_n = 0.5 (J at 10 nm is {J[k10][np.argmin(np.abs(d - 10))]:.3f} "
         f"ΔE00/°).")
    emit(f"* **Where it is meaningful** (σ_n = 0.5, the synthetic default sensor): at 20° "
         f"σ_tilt ≤ 2° for {100 * np.mean(0.5 / J[k20] <= 2):.0f} % of the thicknesses "
         f"({intervals(d, 0.5 / J[k20] <= 2.0)} nm), at 10° for "
         f"{100 * np.mean(0.5 / J[k10] <= 2):.0f} %. These are the films whose hue turns "
         f"fast with the optical path (steep parts of the colour curve); near the turning "
         f"points of the colour curve J drops towards zero.")
    fac = np.sqrt(0.25 + (K[k20] * args.sigma_d) ** 2) / 0.5
    emit(f"* **Thickness uncertainty adds to the image noise**: a thickness known to "
         f"{args.sigma_d:g} nm moves the colour by K σ_d = "
         f"{np.median(K[k20] * args.sigma_d):.2f} ΔE00 (median over d), comparable to σ_n; it "
         f"raises σ_tilt by a median factor {np.median(fac):.1f} and up to {np.max(fac):.1f}× "
         f"where the colour turns fastest (the \"+ σ_d\" columns above). "
         f"`invert_tilt` uses σ_n alone, so a thickness that is only known per facet or per "
         f"ROI makes the colour term over-confident; speed-vs-error.md §3c measures the "
         f"consequence in the joint mode.")
    emit("* **Use**: tilt per pixel from colour alone (`--mode seed`) is not a measurement "
         "for most films; the default joint mode takes tilt from the height map's facet "
         "planes and lets colour contribute only through `colour_weight` — which this page "
         "predicts to be small except for steep facets on fast-turning films. Check "
         "`tilt_sigma_deg.npy` and the summary's `tilt_information`; a σ_tilt near "
         f"{max_tilt:.1f}° means the colour said nothing.")
    emit(f"\n---\nMeasured {time.strftime('%Y-%m-%d')} in {time.perf_counter() - t0:.0f} s.")
    plot(out / "img" / "conditioning.png", d, J, K, TILTS, max_tilt, sigma_typ)
    return emit.text()
