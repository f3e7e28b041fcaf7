"""Coverage of height from focus against texture contrast, behaviour at sharp relief, and
the calibration of the reported uncertainty.

Renders focus stacks of analytic height maps (in z steps) with a controlled texture contrast
and Gaussian sensor noise, and runs each method of ``METHODS`` on them:

* scenes: ``smooth`` (waves and a tilt: the reference), ``steps`` (terraces with steps of
  0.5-4.5 z steps), ``craters`` (bowls with a sharp-crested rim), ``ridges`` (roof-shaped
  ridges with sharp crests and V valleys, 20° and 36° at 0.216 µm px and 0.5 µm steps);
* texture: band-limited noise around grey 0.5 with a luma SD (the *contrast*, 0.003-0.1)
  and an isoluminant chroma part (same SD unless said otherwise); sensor noise SD 0.01 per
  channel, 8-bit quantisation;
* optics: each pixel blurred by its own Gaussian defocus σ = √(0.67² + (β·Δz)²) px with
  β = 1.55 px per z step (microfacet's synthetic stacks: NA 0.8, 0.216 µm pixels, 0.5 µm
  steps), by interpolation between precomputed blur levels (the approach of the
  ``render_stack`` test fixture).

For each method and stack: **coverage** (fraction of pixels declared reliable, 8-px border
excluded), **RMSE** and **p95** (95th percentile of |error|) of the reliable heights in z
steps, **wrong** (fraction of the reliable pixels off by more than one z step: confident
wrong heights), and **in 2σ** (fraction of the reliable pixels with |error| ≤ 2σ of the
reported ``height_sigma_um``); the same on the *relief zone* (pixels within 4 px of a step,
crest, valley or rim). Then the calibration of σ (actual RMS error per bin of reported σ), the
colour measures on chroma-rich texture, and the Cou & Guennebaud (2023) stacks. The plot of
coverage against contrast is ``out/coverage.png``.

docs/height-from-focus.md quotes the tables (its text between them was edited by hand, so
no block is regenerated).
"""

from __future__ import annotations

import contextlib
import io
import math
from pathlib import Path

import cv2
import numpy as np

from microfacet.focus.height import height_from_focus
from microfacet.focus.options import EARLIER_DEFAULT, FocusOptions
from pipelines import Study
from pipelines._shared import cou_stack, md_header, md_row

STUDY = Study(
    name="accuracy-focus-coverage",
    question="How much of a surface does height from focus cover against texture contrast and "
             "at sharp relief, and is its reported σ calibrated?",
    doc=None,
    run_time="2 min",
    quick_time="11 s",
    options={"size": (128, "image side, px"),
             "seeds": (2, "texture and noise draws per case"),
             "blur": (1.55, "defocus px per z step"),
             "cou": (True, "also the Cou & Guennebaud stacks")},
)

N_SLICES = 24
NOISE = 0.01
CONTRASTS = (0.003, 0.006, 0.012, 0.025, 0.05, 0.1)
SCENES = ("smooth", "steps", "craters", "ridges")
#: name -> options of height_from_focus (the default last but one; colour last)
METHODS = {
    "earlier default (Gauss fit, 7 px, Pertuz 12 dB)": EARLIER_DEFAULT,
    "Lorentz fit, 7 px, Pertuz 12 dB": FocusOptions(coarse_window_px=0, reliability="pertuz"),
    "Lorentz fit, 7 px, σ cut": FocusOptions(coarse_window_px=0),
    "+ fine 3 px": FocusOptions(coarse_window_px=0, fine_window_px=3),
    "+ coarse 15 px (new default)": FocusOptions(),
    "3 + 7 + 15 px": FocusOptions(fine_window_px=3),
}


# ----------------------------------------------------------------------------- rendering
#: Rec. 601 luma weights; the chroma texture lies in the plane of zero luma
LUMA = np.array([0.299, 0.587, 0.114], np.float32)
CHROMA_AXES = np.array([[1.0, -0.509, 0.0], [-0.19, 0.0, 0.5]], np.float32)
CHROMA_AXES /= np.linalg.norm(CHROMA_AXES, axis=1, keepdims=True)


def texture(shape, *, luma_sd, chroma_sd, seed, corr_px=0.8):
    """RGB texture around grey 0.5: a luma part of SD ``luma_sd`` and an isoluminant chroma
    part of SD ``chroma_sd`` (independent band-limited noise, correlation ``corr_px``)."""
    rng = np.random.default_rng(seed)

    def field():
        f = cv2.GaussianBlur(rng.standard_normal(shape).astype(np.float32), (0, 0), corr_px)
        return (f - f.mean()) / f.std()

    tex = np.full(shape + (3,), 0.5, np.float32)
    tex += luma_sd * field()[..., None]
    for ax in CHROMA_AXES:
        tex += (chroma_sd / math.sqrt(2.0)) * field()[..., None] * ax
    return tex


def defocus_sigma_px(dz, *, blur_per_slice, sigma0=0.67):
    """Gaussian defocus SD (px) at ``dz`` slices from focus: diffraction ⊕ geometric disc
    (the model of microfacet's synthetic stacks; 1.55 px/slice is NA 0.8, 0.216 µm pixels,
    0.5 µm steps)."""
    return np.sqrt(sigma0 * sigma0 + (blur_per_slice * np.asarray(dz)) ** 2)


def render(height, z, tex, *, blur_per_slice=1.55, noise=0.01, seed=0, bits=8):
    """Slices (float32 in [0, 1]) of texture ``tex`` on surface ``height`` (in slices) at
    stage heights ``z``: each pixel blurred by its own defocus σ (space-variant blur by
    interpolation between precomputed blur levels, as tests/conftest.py ``render_stack``),
    Gaussian noise of SD ``noise`` per channel, ``bits``-bit quantisation."""
    rng = np.random.default_rng(seed + 1000)
    hgt = np.asarray(height, np.float32)
    step = 0.25
    smax = float(defocus_sigma_px(np.ptp(z) + np.ptp(hgt) + 1, blur_per_slice=blur_per_slice))
    levels = np.arange(0.0, smax + 2 * step, step)
    ladder = [tex] + [cv2.GaussianBlur(tex, (0, 0), s) for s in levels[1:]]
    out = []
    for zk in z:
        pos = defocus_sigma_px(zk - hgt, blur_per_slice=blur_per_slice) / step
        lo = np.floor(pos).astype(int)
        t = (pos - lo).astype(np.float32)[..., None]
        img = np.zeros_like(tex)
        for li in np.unique(lo):
            m = lo == li
            img[m] = (1 - t[m]) * ladder[li][m] + t[m] * ladder[li + 1][m]
        if noise:
            img += rng.normal(0.0, noise, img.shape).astype(np.float32)
        img = np.clip(img, 0.0, 1.0)
        if bits:
            q = float(2 ** bits - 1)
            img = np.round(img * q) / q
        out.append(img.astype(np.float32))
    return out


# ------------------------------------------------------------------------------ scenes
def scene(name, size, n_slices):
    """Analytic height map (slices) and its relief zone (pixels within 4 px of a step,
    crest or rim), for scenes ``smooth``, ``steps``, ``craters``, ``ridges``."""
    H = W = size
    yy, xx = np.mgrid[0:H, 0:W].astype(np.float32)
    mid = (n_slices - 1) / 2.0
    if name == "smooth":
        h = mid + 2.5 * np.sin(xx / 17.0) * np.cos(yy / 23.0) + 0.02 * (xx - W / 2)
        edge = np.zeros((H, W), bool)
    elif name == "steps":
        # terraces 20 px wide, steps of 0.5 .. 4 slices up and down
        seq = np.array([0.0, 1.0, 3.0, 2.5, 4.5, 2.0, 0.0, 0.5, 4.0, 1.5, -1.0, 3.0])
        k = np.minimum((xx // 20).astype(int), len(seq) - 1)
        h = mid - 1.5 + seq[k] + 0.01 * yy
        edge = np.zeros((H, W), bool)
        edge[:, 20:W:20] = True
        edge[:, 19:W:20] = True
    elif name == "craters":
        h = np.full((H, W), mid + 1.0, np.float32)
        edge = np.zeros((H, W), bool)
        R, depth, rim = 14.0, 4.0, 1.5
        for cy in range(22, H, 44):
            for cx in range(22, W, 44):
                r = np.hypot(yy - cy, xx - cx)
                inside = np.where(r < R, rim - depth * (1 - (r / R) ** 2), 0.0)
                outside = np.where(r >= R, rim * np.exp(-(r - R) / 4.0), 0.0)
                h += inside + outside
                edge |= np.abs(r - R) < 1.0
    elif name == "ridges":
        # roof-shaped ridges: sharp crests and V valleys, slopes 0.16 and 0.31 slices/px
        # (20° and 36° at 0.216 µm pixels and 0.5 µm steps)
        period = 32.0
        u = (xx + 0.3 * yy) % period
        tri = np.abs(u - period / 2) / (period / 2)          # 1 at valleys, 0 at crest
        amp = np.where(((xx + 0.3 * yy) // period) % 2 == 0, 2.5, 5.0)
        h = mid + amp * (0.5 - tri)
        edge = (np.abs(u - period / 2) < 1.0) | (u < 1.0) | (u > period - 1.0)
    else:
        raise ValueError(name)
    relief = cv2.dilate(edge.astype(np.uint8), np.ones((9, 9), np.uint8)) > 0
    return h.astype(np.float32), relief


# -------------------------------------------------------------------------- measurement
class Pool:
    """Errors (z steps), reported σ and reliability of the evaluated pixels, pooled."""

    def __init__(self):
        self.n = 0
        self.err, self.sig, self.rel_db, self.fit_err, self.conf = [], [], [], [], []

    def add(self, res, truth, zone, step=1.0):
        self.n += int(zone.sum())
        conf = res.reliability_db.astype(np.float64)
        if res.detected is not None and res.params.get("reliability") == "sigma":
            conf = np.where(res.detected, conf, -np.inf)
        self.fit_err.append((res.height_fit_um[zone] - truth[zone]) / step)
        self.conf.append(conf[zone])
        ok = res.reliable & zone & np.isfinite(res.height_um)
        self.err.append((res.height_um[ok] - truth[ok]) / step)
        sig = res.height_sigma_um if res.height_sigma_um is not None else np.full(ok.shape, np.nan)
        self.sig.append(sig[ok] / step)
        self.rel_db.append(res.reliability_db[ok])

    def stats(self):
        e = np.concatenate(self.err) if self.err else np.zeros(0)
        s = np.concatenate(self.sig) if self.sig else np.zeros(0)
        a = np.abs(e)
        out = {"cov": e.size / max(self.n, 1), "n": e.size}
        if e.size:
            out.update(rmse=float(np.sqrt(np.mean(e * e))), p95=float(np.percentile(a, 95)),
                       med=float(np.median(a)),
                       wrong=float(np.mean(a > 1.0)),
                       in2=float(np.mean(a <= 2 * s)) if np.isfinite(s).any() else math.nan)
        else:
            out.update(rmse=math.nan, p95=math.nan, med=math.nan, wrong=math.nan, in2=math.nan)
        return out

    def coverage_at(self, targets):
        """Largest fraction of the pixels, taken in decreasing reliability, whose heights
        have an RMSE ≤ each target (the method's own ranking; its cut is one point)."""
        e = np.concatenate(self.fit_err)
        c = np.concatenate(self.conf)
        e2 = np.where(np.isfinite(e), e * e, 1e6)[np.argsort(-c, kind="stable")]
        run = np.cumsum(e2) / np.arange(1, e2.size + 1)
        return [float(np.max(np.nonzero(run <= t * t)[0], initial=-1) + 1) / max(e2.size, 1)
                for t in targets]


def f3(x):
    return "–" if x is None or not np.isfinite(x) else f"{x:.3f}"


def pct(x):
    return "–" if x is None or not np.isfinite(x) else f"{100 * x:.1f}"


def run_synthetic(size, seeds, blur):
    """Pools per (method, scene, contrast) for the whole pixel set and the relief zone."""
    z = np.arange(N_SLICES, dtype=float)
    pools = {}
    inner = np.zeros((size, size), bool)
    inner[8:-8, 8:-8] = True
    for name in SCENES:
        h, relief = scene(name, size, N_SLICES)
        for c in CONTRASTS:
            for seed in range(seeds):
                tex = texture((size, size), luma_sd=c, chroma_sd=c, seed=100 * seed + 1)
                imgs = render(h, z, tex, blur_per_slice=blur, noise=NOISE, seed=seed)
                for m, opts in METHODS.items():
                    res = height_from_focus(imgs, opts, z_um=z)
                    for zone, mask in (("all", inner), ("relief", inner & relief)):
                        if mask.any():
                            pools.setdefault((m, name, c, zone), Pool()).add(res, h, mask)
    return pools


def merged(pools, method, scenes, contrasts, zone):
    p = Pool()
    for s in scenes:
        for c in contrasts:
            q = pools.get((method, s, c, zone))
            if q is not None:
                p.n += q.n
                p.err += q.err
                p.sig += q.sig
                p.rel_db += q.rel_db
                p.fit_err += q.fit_err
                p.conf += q.conf
    return p


def tables(pools, methods):
    short = {m: f"M{i + 1}" for i, m in enumerate(methods)}
    print("Methods: " + "; ".join(f"**{short[m]}** {m}" for m in methods) + "\n")
    for title, scenes, zone in (
            ("All pixels of the four scenes: coverage % / median |error| / RMSE (z steps) / "
             "wrong %", SCENES, "all"),
            ("Relief zone (steps, craters, ridges): coverage % / median |error| / RMSE / "
             "wrong % / in 2σ %", SCENES[1:], "relief")):
        print(f"\n{title}\n")
        print(md_header(["luma contrast"] + [short[m] for m in methods]))
        for c in CONTRASTS:
            cells = []
            for m in methods:
                s = merged(pools, m, scenes, [c], zone).stats()
                cells.append(f"{pct(s['cov'])} / {f3(s['med'])} / {f3(s['rmse'])} / "
                             f"{pct(s['wrong'])}" + ("" if zone == "all" else
                                                     f" / {pct(s['in2'])}"))
            print(md_row([c] + cells))
    print("\nCoverage % at a given accuracy: the largest share of all pixels (four scenes), "
          "taken in decreasing reliability of each method, whose RMSE is ≤ 0.1 / 0.2 / 0.3 "
          "z steps\n")
    print(md_header(["luma contrast"] + [short[m] for m in methods]))
    for c in CONTRASTS:
        print(md_row([c] + [" / ".join(pct(v) for v in merged(
            pools, m, SCENES, [c], "all").coverage_at((0.1, 0.2, 0.3))) for m in methods]))
    print("\nPer scene, contrasts 0.012-0.1 pooled: coverage %, RMSE, p95, wrong %, in 2σ % "
          "(all pixels | relief zone)\n")
    print(md_header(["scene", "method", "cov", "RMSE", "p95", "wrong", "in 2σ", "relief cov",
                     "relief RMSE", "relief wrong", "relief in 2σ"]))
    for sc in SCENES:
        for m in methods:
            a = merged(pools, m, [sc], CONTRASTS[2:], "all").stats()
            r = merged(pools, m, [sc], CONTRASTS[2:], "relief").stats()
            print(md_row([sc, short[m], pct(a["cov"]), f3(a["rmse"]), f3(a["p95"]),
                          pct(a["wrong"]), pct(a["in2"]), pct(r["cov"]) if r["n"] or sc != "smooth"
                          else "–", f3(r["rmse"]), pct(r["wrong"]), pct(r["in2"])]))
    return short


def calibration(pools, default, earlier):
    print("\nCalibration of the reported σ (new default, every scene and contrast): actual "
          "RMS error per bin of σ, z steps\n")
    p = merged(pools, default, SCENES, CONTRASTS, "all")
    e, s = np.concatenate(p.err), np.concatenate(p.sig)
    print(md_header(["reported σ", "pixels %", "RMS error", "|error| ≤ σ %", "|error| ≤ 2σ %",
                     "wrong %"]))
    edges = [0, 0.05, 0.1, 0.2, 0.3, 0.5, 0.71, 1.0]
    for lo, hi in zip(edges[:-1], edges[1:]):
        m = (s >= lo) & (s < hi)
        if m.any():
            a = np.abs(e[m])
            print(md_row([f"{lo}-{hi}", pct(m.mean()), f3(np.sqrt(np.mean(a * a))),
                          pct(np.mean(a <= s[m])), pct(np.mean(a <= 2 * s[m])),
                          pct(np.mean(a > 1))]))
    print("\nThe earlier reliability (Pertuz dB, earlier default) against the error\n")
    p = merged(pools, earlier, SCENES, CONTRASTS, "all")
    e, r = np.concatenate(p.err), np.concatenate(p.rel_db)
    print(md_header(["Pertuz reliability", "pixels %", "RMS error", "wrong %"]))
    for lo, hi in ((12, 15), (15, 20), (20, 25), (25, 200)):
        m = (r >= lo) & (r < hi)
        if m.any():
            a = np.abs(e[m])
            print(md_row([f"{lo}-{hi} dB", pct(m.mean()), f3(np.sqrt(np.mean(a * a))),
                          pct(np.mean(a > 1))]))


def cut_stats(pool, cut):
    """Coverage, median |error|, RMSE and wrong fraction of the pixels with confidence ≥ cut
    (dB) among those of ``pool`` (from its unmasked heights: any cut, one run)."""
    e = np.concatenate(pool.fit_err)
    c = np.concatenate(pool.conf)
    keep = c >= cut
    a = np.abs(e[keep])
    if not a.size:
        return 0.0, math.nan, math.nan, math.nan
    return (a.size / max(e.size, 1), float(np.median(a)), float(np.sqrt(np.mean(a * a))),
            float(np.mean(a > 1.0)))


def cut_table(pools, default, earlier, cuts=(0.0, 2.0, 3.0, 4.0, 5.0, 6.0, 8.0, 10.0, 14.0)):
    """How the reliability cut of the new default was chosen: coverage and error against the
    cut, next to the earlier default at its own cut."""
    print("\nChoice of the cut (new default's σ reliability, −20·log10(σ / step) dB; earlier "
          "default: Pertuz 12 dB), contrasts 0.012-0.1 pooled: coverage % / median |error| / "
          "RMSE (z steps) / wrong %\n")
    print(md_header(["cut", "all pixels, four scenes", "relief zone", "smooth scene",
                     "contrasts 0.003-0.006, all pixels"]))
    groups = ((SCENES, "all", CONTRASTS[2:]), (SCENES[1:], "relief", CONTRASTS[2:]),
              (SCENES[:1], "all", CONTRASTS[2:]), (SCENES, "all", CONTRASTS[:2]))
    pertuz_cut = EARLIER_DEFAULT.reliability_cut_db
    rows = [(f"earlier default, Pertuz ≥ {pertuz_cut:g} dB", earlier, pertuz_cut)]
    rows += [(f"σ ≤ {10 ** (-c / 20):.2f} step ({c:g} dB)", default, c) for c in cuts]
    for label, m, cut in rows:
        cells = []
        for scenes, zone, contrasts in groups:
            cov, med, rmse, wrong = cut_stats(merged(pools, m, scenes, contrasts, zone), cut)
            cells.append(f"{pct(cov)} / {f3(med)} / {f3(rmse)} / {pct(wrong)}")
        print(md_row([label] + cells))


def colour_table(size, blur):
    print("\nColour: luma vs the sum of the RGB channels' Tenengrad (smooth scene, new "
          "default otherwise): coverage % / RMSE\n")
    z = np.arange(N_SLICES, dtype=float)
    h, _ = scene("smooth", size, N_SLICES)
    inner = np.zeros(h.shape, bool)
    inner[8:-8, 8:-8] = True
    print(md_header(["chroma SD / luma SD", "luma contrast", "luma", "rgb"]))
    for ratio in (0.0, 1.0, 2.0, 4.0):
        for c in (0.006, 0.012):
            tex = texture(h.shape, luma_sd=c, chroma_sd=ratio * c, seed=7)
            imgs = render(h, z, tex, blur_per_slice=blur, noise=NOISE, seed=3)
            cells = []
            for col in ("luma", "rgb"):
                p = Pool()
                p.add(height_from_focus(imgs, FocusOptions(colour=col), z_um=z), h, inner)
                s = p.stats()
                cells.append(f"{pct(s['cov'])} / {f3(s['rmse'])}")
            print(md_row([ratio, c] + cells))


def cou_table(methods, short):
    print("\nCou & Guennebaud (2023) stacks 1-3: coverage %, RMSE of the reliable pixels, "
          "RMSE of all pixels (height_fit_um), |error| ≤ 2σ %\n")
    print(md_header(["method", "stack 1", "stack 2", "stack 3"]))
    stacks = [cou_stack(s) for s in (1, 2, 3)]
    o = 20
    for m in methods:
        cells = []
        for st, ref in stacks:
            res = height_from_focus(st, METHODS[m])
            truth = np.full(res.height_um.shape, np.nan)
            truth[o:o + ref.shape[0], o:o + ref.shape[1]] = ref
            p = Pool()
            p.add(res, truth, np.isfinite(truth))
            s = p.stats()
            e_all = res.height_fit_um[o:o + ref.shape[0], o:o + ref.shape[1]] - ref
            cells.append(f"{pct(s['cov'])} / {f3(s['rmse'])} / "
                         f"{f3(float(np.sqrt(np.mean(e_all ** 2))))} / {pct(s['in2'])}")
        print(md_row([short[m]] + cells), flush=True)


def plot(pools, methods, short, path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(10, 4), sharey=True)
    for ax, (scenes, zone, title) in zip(axes, ((SCENES, "all", "all pixels"),
                                                (SCENES[1:], "relief", "relief zone"))):
        for m in methods:
            cov = [merged(pools, m, scenes, [c], zone).stats()["cov"] for c in CONTRASTS]
            ax.semilogx(CONTRASTS, [100 * v for v in cov], "o-", label=short[m])
        ax.set_xlabel("texture contrast (luma SD; noise SD 0.01)")
        ax.set_title(title)
    axes[0].set_ylabel("coverage (%)")
    axes[1].legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def run(*, quick: bool, out: Path, size=128, seeds=2, blur=1.55, cou=True) -> str:
    if quick:
        size, seeds, cou = min(size, 40), 1, False
    methods = list(METHODS)
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        print(f"{size}x{size} px, {N_SLICES} slices, defocus {blur} px per step, "
              f"noise SD {NOISE}, {seeds} draws per case\n")
        pools = run_synthetic(size, seeds, blur)
        short = tables(pools, methods)
        cut_table(pools, methods[4], methods[0])
        calibration(pools, methods[4], methods[0])
        colour_table(size, blur)
        if cou:
            cou_table(methods, short)
        plot(pools, methods, short, out / "coverage.png")
    return buf.getvalue()
