"""What holds issues 22 and 23's counts where they are, tallied over accuracy-sweep runs
(docs/accuracy.md, "What limits the two issues' counts").

    python -m pipelines.sweep_limits OUT:WORK [OUT:WORK ...]

Each ``OUT:WORK`` is one ``accuracy-sweep --set mode=joint --set work=WORK --out OUT`` run
(``OUT/generalization.csv``, ``WORK/results/joint/NAME/summary.json``,
``WORK/stacks/NAME/truth/``); all are pooled. Prints, one line each:

* the NDF: the textured scenes by world and by the reason their NDF is not identified; those
  that pass the self-check's three conditions (both transfers in range, the gain's spread
  within its limit) by reason, and of those refused only as ``curved_facets`` how many are
  off by more than 25 %; the correlation of the self-check's width transfer with the
  scene's true width ratio, and, on the textured scenes without rounded facets whose spread
  is within the limit, the median ratio and the quartiles of the ratio over the transfer;
  the dome transfer; every textured scene's NDF as reported and the dome share read
  (:func:`reported_line`); the segments' purity against the true facets, its correlation
  with the scenes' lobe RMS ratio (:func:`purity_line`) and its range on the identified NDFs
  by their error (:func:`purity_identified_line`);
* the thickness: the scenes with too few and too many components, and the kinds (two true
  populations under one wide component; a population split into close components; a
  component far above every true population: another interference order), with the model
  choice's independent count over the Kish count of the true regions' areas on each kind;
  the components set aside as misread facets, by why, that lie within :data:`MATCH_NM` of a
  true population (≥ 2 % of the area) no kept component lies on — a population lost — and
  the others; the true count by the share of the thickness map read an order off
  (:func:`order_off_line`) and by the slices' JPEG quality (:func:`jpeg_line`); the true
  count were every facet read at its true region's thickness (:func:`ceiling_line`: what
  the model choice itself gets right);
* the region MAE: the scenes above 0.5 nm by kind (a true region read an order off, all
  regions off alike, scattered; :func:`region_mae_kind`), with and without a white-balance
  error, and the median signed region error by world on the scenes with no region an order
  off (:func:`region_mae_lines`);
* the white balance: the estimate's median error per gain, its median error in units of its
  own σ, the median error by the number of film colours, and the range of the medians with
  and without each of the sweep's variations; and what applying the gains the estimate
  names off 1 (more than 3σ and 3 %) with a σ below 3 % would do (:func:`apply_rule_line`:
  docs/accuracy.md, "What keeps the region MAE above 0.5 nm").
"""

from __future__ import annotations

import csv
import json
import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np

from microfacet.analysis.identification import (
    GAIN_OFF_MIN,
    GAIN_OFF_SIGMAS,
    gains_off_one,
    self_check_passes,
)
from microfacet.analysis.options import FitOptions
from microfacet.analysis.white_balance import WhiteBalance
from microfacet.core.distributions import NDFMixture
from pipelines._scoring import (
    facet_tilts,
    lobe_rms_ratio,
    present_means_nm,
    region_thickness_errors,
)

#: A component this wide (nm) spanning two true means within :data:`SPAN_SD` of its SD is two
#: populations fitted as one; two components this close (nm) nearest one true population are
#: a split; a component this far (nm) above every true population is another order.
WIDE_SD_NM, SPAN_SD, SPLIT_NM, FAR_NM = 4.5, 2.5, 8.0, 60.0
#: A component within this (nm) of a true population's mean lies on it.
MATCH_NM = 5.0
#: The region MAE target (nm); a true region whose median is this far (nm) from its mean is
#: read an order off; regions "off alike" when the signed mean error is at least this share
#: of the MAE (the regions without one an order off).
MAE_TARGET_NM, ORDER_OFF_NM, COMMON_SHARE = 0.5, 50.0, 0.6
#: The rule :func:`apply_rule_line` tallies: a gain the estimate names off 1
#: (``identification.gains_off_one``), inside its search (``WhiteBalance.at_search_edge``),
#: with σ below this.
APPLY_SIGMA = 0.03


def scenes(specs):
    """``(row, summary, truth/params.json, truth folder)`` of every joint-mode scene."""
    for spec in specs:
        out, _, work = spec.partition(":")
        with open(Path(out) / "generalization.csv", newline="") as f:
            for r in csv.DictReader(f):
                res = Path(work) / "results" / "joint" / r["name"] / "summary.json"
                if r["mode"] != "joint" or r["status"] != "done" or not res.is_file():
                    continue
                truth = Path(work) / "stacks" / r["name"] / "truth"
                yield (r, json.loads(res.read_text()),
                       json.loads((truth / "params.json").read_text()), truth)


def _f(x) -> float:
    return float(x) if x not in ("", None) else float("nan")


def ndf_lines(rows, fits: FitOptions) -> list:
    tex = [(r, s) for r, s, _, _ in rows if r["textured"] == "True"]
    out = [f"textured scenes: {len(tex)}; by world "
           + _counts(r["world"] for r, _ in tex),
           "refused, by reason (faceted world): "
           + _counts(s["ndf"].get("reason_code") or "identified" for r, s in tex
                     if r["world"] == "faceted")]
    sc = [(r, s["ndf"].get("reason_code"), s["ndf"].get("self_check") or {}) for r, s in tex]

    def passes(c):          # the analysis' own rule (standard errors 0 where not recorded)
        keys = ("transfer", "width_transfer", "spread", "transfer_se", "width_transfer_se")
        return self_check_passes(SimpleNamespace(**{k: _f(c.get(k, 0.0)) for k in keys}),
                                 fits)
    ok = [(r, why) for r, why, c in sc if passes(c)]
    curved = [_f(r["lobe_rms_ratio"]) for r, why in ok if why == "curved_facets"]
    out.append(f"pass the self-check: {len(ok)}, by reason "
               + _counts(why or "identified" for _, why in ok)
               + f"; of the curved_facets ones {sum(abs(v - 1) > 0.25 for v in curved)} off by "
               f"more than 25 % ({_range([v for v in curved if abs(v - 1) > 0.25])})")
    wt = np.array([_f(c.get("width_transfer")) for _, _, c in sc])
    ratio = np.array([_f(r["lobe_rms_ratio"]) for r, _, _ in sc])
    use = np.isfinite(wt) & np.isfinite(ratio) & (wt > 0.3)
    out.append(f"width transfer against the true width ratio: correlation "
               f"{np.corrcoef(wt[use], ratio[use])[0, 1]:.2f} ({int(use.sum())} scenes)")
    steady = np.array([r["v_rounded"] == "0" and _f(c.get("spread")) <= fits.self_check_max_spread
                       for r, _, c in sc]) & use
    q = np.percentile(ratio[steady] / wt[steady], [25, 50, 75])
    out.append(f"no rounded facets, spread within the limit ({int(steady.sum())} scenes): ratio "
               f"median {np.median(ratio[steady]):.2f}; ratio / width transfer median "
               f"{q[1]:.2f}, quartiles {q[0]:.2f}-{q[2]:.2f}")
    out.append(_dome_line(sc))
    out.append(reported_line(tex))
    out.append(reported_line([(r, s) for r, s, _, _ in rows if r["textured"] != "True"],
                             "scenes without focus texture"))
    out.append(correction_line(rows))
    out.append(purity_line(rows))
    out.append(purity_identified_line(rows))
    return out


def reported_line(tex, label="textured scenes") -> str:
    """Every scene's NDF of ``tex`` as reported (identified or for inspection): its lobe RMS
    ratio's median and the shares within 15 % and off by more than 25 %, its W1's median;
    and the dome share the planar-facet check read (``ndf.mixture.dome_share_measured``) on
    the faceted scenes without rounded facets (median, quartiles)."""
    r = np.array([_f(row["lobe_rms_ratio"]) for row, _ in tex])
    r = r[np.isfinite(r)]
    w1 = np.array([_f(row.get("ndf_w1_deg")) for row, _ in tex])
    w1 = w1[np.isfinite(w1)]
    d = np.array([_f((s["ndf"].get("mixture") or {}).get("dome_share_measured"))
                  for row, s in tex if row["world"] == "faceted" and row["v_rounded"] == "0"])
    d = d[np.isfinite(d)]
    if r.size == 0:
        return f"reported NDFs ({label}): none scored"
    q = np.percentile(d, [25, 50, 75]) if d.size else [np.nan] * 3
    return (f"reported NDFs ({r.size} {label}): ratio median {np.median(r):.2f}, "
            f"within 15 % on {np.mean(np.abs(r - 1) <= 0.15):.0%}, off by more than 25 % on "
            f"{np.mean(np.abs(r - 1) > 0.25):.0%}, W1 median "
            f"{np.median(w1) if w1.size else np.nan:.2f}°; dome share read, faceted without "
            f"rounding ({d.size}): median {q[1]:.2f}, quartiles {q[0]:.2f}-{q[2]:.2f}")


def _share_line(r) -> str:
    r = np.asarray(r, np.float64)
    r = r[np.isfinite(r)]
    return (f"median {np.median(r):.2f}, within 15 % {np.mean(np.abs(r - 1) <= 0.15):.0%}, "
            f"off > 25 % {np.mean(np.abs(r - 1) > 0.25):.0%}" if r.size else "none")


def correction_line(rows, constants=(1.15, 1.2, 1.25)) -> str:
    """The textured scenes whose NDF the self-check's width correction scaled
    (``ndf.mixture.width_correction``): the planes' second moment over the truth's RMS slope
    below the acceptance, the lobes as fitted (``uncorrected``) and as corrected, and the
    lobes as fitted scaled by each one of ``constants`` instead (does the scene's own
    correction do better than one factor for all?)."""
    got = []
    for r, s, _, truth in rows:
        ndf = s.get("ndf") or {}
        corr = (ndf.get("mixture") or {}).get("width_correction") or {}
        if r["textured"] != "True" or "uncorrected" not in corr:
            continue
        lim = ndf["max_tilt_deg"]
        tilt = facet_tilts(truth)
        seen = tilt[np.isfinite(tilt) & (tilt < lim)]
        true = float(np.sqrt(np.mean(np.tan(np.radians(seen)) ** 2))) if seen.size else np.nan
        fitted = NDFMixture([(c["weight"], c["sd_deg"]) for c in corr["uncorrected"]])
        got.append([corr["planes_rms_slope"] / true, lobe_rms_ratio(fitted.components, tilt, lim),
                    _f(r["lobe_rms_ratio"])]
                   + [lobe_rms_ratio(fitted.scaled(k).components, tilt, lim) for k in constants])
    if not got:
        return "width correction: no textured scene corrected"
    g = np.array(got, np.float64)
    each = "; ".join(f"×{k:g}: {_share_line(g[:, 3 + i])}" for i, k in enumerate(constants))
    return (f"width correction ({len(g)} textured scenes): planes' second moment "
            f"{_share_line(g[:, 0])}; lobes as fitted {_share_line(g[:, 1])}; corrected "
            f"{_share_line(g[:, 2])}; as fitted × one constant {each}")


def segment_purity(facets, true_facets) -> float:
    """The share of the segments' area that lies in each segment's majority true facet
    (``facets``, ``true_facets``: label maps of one shape); 1 where every segment is within
    one true facet.

    >>> seg = np.array([[0, 0, 1, 1]]); true = np.array([[0, 0, 0, 1]])
    >>> segment_purity(seg, true)
    0.75
    """
    seg = np.asarray(facets, np.int64).ravel()
    true = np.unique(np.asarray(true_facets).ravel(), return_inverse=True)[1]
    n_true = int(true.max()) + 1
    key, count = np.unique(seg * n_true + true, return_counts=True)
    best = np.zeros(int(seg.max()) + 1, np.int64)
    np.maximum.at(best, key // n_true, count)
    return float(best.sum() / seg.size)


def _purities(rows):
    """Per textured faceted scene with its segments: the segments' purity
    (:func:`segment_purity`), the lobe RMS ratio and whether the NDF was identified."""
    out = []
    for r, summary, _, truth in rows:
        seg = truth.parents[2] / "results" / "joint" / r["name"] / "facets.npy"
        if (r["textured"] != "True" or r["world"] != "faceted" or not seg.is_file()
                or not (truth / "facet_id.npy").is_file()):
            continue
        out.append((segment_purity(np.load(seg), np.load(truth / "facet_id.npy")),
                    _f(r["lobe_rms_ratio"]), bool((summary.get("ndf") or {}).get("identified"))))
    return np.array(out, dtype=np.float64).reshape(-1, 3)


def purity_line(rows) -> str:
    """Issue 22's item 2 measured: the segments' purity (:func:`segment_purity`, the joint
    results' ``facets.npy`` against ``truth/facet_id.npy``) on the textured faceted scenes,
    and how the scenes' lobe RMS ratio follows it."""
    p = _purities(rows)
    if not len(p):
        return "segment purity: no textured faceted scene with its segments"
    pur, ratio = p[:, 0], p[:, 1]
    q = np.percentile(pur, [25, 50, 75])
    ok = np.isfinite(ratio)
    return (f"segment purity (textured faceted, {pur.size} scenes): median {q[1]:.2f}, "
            f"quartiles {q[0]:.2f}-{q[2]:.2f}; correlation with the lobe RMS ratio "
            f"{np.corrcoef(pur[ok], ratio[ok])[0, 1]:.2f}")


def purity_identified_line(rows) -> str:
    """The segments' purity of the scenes whose NDF was identified, within 15 % of its true
    RMS slope and more than 25 % off."""
    p = _purities(rows)
    ident, err = p[:, 2] > 0, np.abs(p[:, 1] - 1)
    near, far = list(p[ident & (err <= 0.15), 0]), list(p[ident & (err > 0.25), 0])
    return (f"segment purity of the identified NDFs: within 15 % {_range(near)}, more than "
            f"25 % off {_range(far)}")


def _dome_line(sc) -> str:
    """The self-check's dome transfer over the textured scenes that measured it: percentiles,
    its standard error's median and its correlation with the slope transfer."""
    d = np.array([[_f(c.get(k)) for k in ("dome_transfer", "dome_transfer_se", "transfer")]
                  for _, _, c in sc]).reshape(-1, 3)
    d = d[np.isfinite(d).all(axis=1)]
    if len(d) < 3:
        return "dome transfer: measured on fewer than 3 textured scenes"
    q = np.percentile(d[:, 0], [10, 50, 90])
    return (f"dome transfer ({len(d)} textured scenes): 10th / 50th / 90th percentile "
            f"{q[0]:.2f} / {q[1]:.2f} / {q[2]:.2f}, standard error median "
            f"{np.median(d[:, 1]):.2f}; correlation with the slope transfer "
            f"{np.corrcoef(d[:, 0], d[:, 2])[0, 1]:.2f}")


def _counts(items) -> str:
    keys, n = np.unique(list(items), return_counts=True)
    return ", ".join(f"{k} {c}" for k, c in zip(keys, n))


def _range(v) -> str:
    return f"{min(v):.2f}-{max(v):.2f}" if v else "none"


def true_kish(truth: Path) -> float:
    """Kish count of the true regions' areas."""
    rid = np.load(truth / "region_id.npy")
    a = np.bincount(rid[rid >= 0].ravel()).astype(np.float64)
    a = a[a > 0]
    return float(a.sum() ** 2 / np.sum(a * a))


def kind(row, mixture, params) -> str | None:
    """The kind of a wrong count (None: the count is right, or another kind)."""
    found, true = int(row["pops_found"]), int(row["pops_true"])
    tm = np.array([t["mean_nm"] for t in params["thickness"]])
    comps = mixture["components"]
    if found < true:
        wide = any(c["sd_nm"] >= WIDE_SD_NM
                   and np.sum(np.abs(tm - c["mean_nm"]) <= SPAN_SD * c["sd_nm"]) >= 2
                   for c in comps)
        return "merged" if wide else "too few, other"
    if found > true:
        mu = np.sort([c["mean_nm"] for c in comps])
        near = np.argmin(np.abs(tm[None, :] - mu[:, None]), axis=1)
        if np.any((near[1:] == near[:-1]) & (np.diff(mu) <= SPLIT_NM)):
            return "split"
        return "another order" if np.any(mu > tm.max() + FAR_NM) else "too many, other"
    return None


def set_aside_line(rows) -> str:
    """The misread components set aside, by why: how many lie on a true population that no
    kept component lies on."""
    lost, other = [], []
    for r, s, meta, truth in rows:
        mix = s["thickness"]["mixture"]
        tm = np.array(present_means_nm(meta["populations"]))
        kept = np.array([c["mean_nm"] for c in mix["components"]])
        for m in mix.get("misread_components") or []:
            on = tm[np.abs(tm - m["mean_nm"]) <= MATCH_NM] if tm.size else tm
            alone = on.size and not (kept.size and np.any(
                np.abs(kept[:, None] - on[None, :]) <= MATCH_NM))
            (lost if alone else other).append(m["why"])
    return (f"set aside as misread: {len(lost) + len(other)}; on a true population no kept "
            f"component lies on: {len(lost)} ({_counts(lost) or 'none'}); others: "
            f"{_counts(other) or 'none'}")


#: Upper edges of the bins of :func:`order_off_line` (share of the map read an order off).
ORDER_OFF_BINS = (0.01, 0.05, 0.15, 0.30, 1.0)


def order_off_line(rows) -> str:
    """The true count by the share of the thickness map read an order off
    (``order_off_fraction``; runs recorded without it are left out), with the scenes read
    in a wrong order in each bin."""
    got = [(_f(r.get("order_off_fraction")), r["pops_found"] == r["pops_true"],
            r["order_wrong"] == "True") for r, *_ in rows]
    got = [g for g in got if np.isfinite(g[0])]
    if not got:
        return "map read an order off: not recorded"
    share, right, wrong = (np.array(v) for v in zip(*got))
    parts, lo = [], -np.inf
    for hi in ORDER_OFF_BINS:
        b = (share > lo) & (share <= hi)
        parts.append(f"<= {100 * hi:.0f} %: {int(right[b].sum())} of {int(b.sum())}"
                     f" ({int(wrong[b].sum())} wrong order)")
        lo = hi
    return "true count by the share of the map read an order off: " + "; ".join(parts)


#: Upper edges of the bins of :func:`jpeg_line` (the slices' JPEG quality; the sweep draws
#: 70-95).
JPEG_BINS = (75, 80, 85, 90, 100)


def jpeg_line(rows) -> str:
    """The true count by the slices' JPEG quality (``params.json`` ``params.jpeg_quality``;
    lossless slices first)."""
    q = np.array([_f((p.get("params") or {}).get("jpeg_quality")) for _, _, p, _ in rows])
    right = np.array([r["pops_found"] == r["pops_true"] for r, *_ in rows])
    parts, lo = [f"lossless {int(right[~np.isfinite(q)].sum())} of "
                 f"{int((~np.isfinite(q)).sum())}"], 0
    for hi in JPEG_BINS:
        b = (q > lo) & (q <= hi)
        parts.append(f"{lo + 1}-{hi}: {int(right[b].sum())} of {int(b.sum())}")
        lo = hi
    return "true count by the slices' JPEG quality: " + "; ".join(parts)


def facets_at_truth(results: Path, truth: Path, *, seed=0):
    """Each facet of a scene's results (its ``facets`` map and table,
    :class:`~microfacet.io.results.Results`) at the mean thickness of the true region holding
    most of its pixels (``truth/region_id.npy``, ``params.json`` ``regions``), plus a normal
    error of its own reported σ (``thickness_sigma_nm``); only the facets the analysis gave a
    thickness. Returns ``(labels, value, sigma, area)``, the per-facet arrays NaN where a
    facet carries no sample."""
    from microfacet.io.results import Results

    res = Results(results)
    labels, table = res.map("facets"), res.table("facets")
    rid = np.load(truth / "region_id.npy")
    means = np.array([q["mean_thickness_nm"]
                      for q in json.loads((truth / "params.json").read_text())["regions"]])
    S, R = int(labels.max()) + 1, means.size
    inside = rid >= 0
    votes = np.bincount(labels[inside].astype(np.int64) * R + rid[inside],
                        minlength=S * R).reshape(S, R)
    region = np.where(votes.any(axis=1), votes.argmax(axis=1), -1)
    k = table["facet"].astype(np.int64)
    value, sigma, area = np.full(S, np.nan), np.full(S, np.nan), np.zeros(S)
    value[k] = np.where(np.isfinite(table["thickness_nm"]) & (region[k] >= 0),
                        means[np.maximum(region[k], 0)], np.nan)
    sigma[k], area[k] = table["thickness_sigma_nm"], table["n_pixels"]
    ok = np.isfinite(value) & np.isfinite(sigma) & (area > 0)
    noise = np.random.default_rng(seed).standard_normal(S)
    value = np.where(ok, value + noise * np.where(ok, sigma, 0.0), np.nan)
    return labels, value, np.where(ok, sigma, np.nan), area


def count_at_truth(results: Path, truth: Path, sd_ceiling_nm=None, *, seed=0) -> int:
    """The number of components the analysis's thickness mixture (its samples, thickness
    regions and model choice, :func:`~microfacet.analysis.mixtures.fit_thickness_mixture`
    with a background, the SD ceiling the scene's fit used) finds in
    :func:`facets_at_truth`: the count the model choice gets were every facet read
    right. The pipeline's later steps (misread components set aside, order moves) are not
    run: the facets carry no misreads."""
    from microfacet.analysis.mixtures import fit_thickness_mixture
    from microfacet.analysis.sampling import thickness_regions

    labels, value, sigma, area = facets_at_truth(results, truth, seed=seed)
    ok = np.isfinite(value)
    regions = thickness_regions(labels, value, sigma)
    fit = fit_thickness_mixture(value[ok], sigma_nm=sigma[ok], weights=area[ok],
                                n_effective=regions, background=True, seed=seed,
                                options=FitOptions(thickness_max_sd_nm=sd_ceiling_nm))
    return fit.n_components


def ceiling_line(rows) -> str:
    """The true count were every facet read at its true region's thickness
    (:func:`count_at_truth`) against the analysis's own, over the scenes whose results hold
    the facets."""
    at_truth = own = n = 0
    for r, s, _, truth in rows:
        results = truth.parents[2] / "results" / "joint" / r["name"]
        if not (results / "facets.npy").is_file():
            continue
        k = count_at_truth(results, truth, s["thickness"]["mixture"].get("sd_ceiling_nm"),
                           seed=int(r["seed"]))
        n += 1
        at_truth += k == int(r["pops_true"])
        own += int(r["pops_found"]) == int(r["pops_true"])
    return (f"true count were every facet read at its true region's thickness (the model "
            f"choice's own ceiling): {at_truth} of {n}; as read: {own} of {n}")


def thickness_lines(rows) -> list:
    kinds, ratios = [], {}
    for r, s, p, truth in rows:
        k = kind(r, s["thickness"]["mixture"], p["params"])
        if k is None:
            continue
        kinds.append(k)
        if k in ("merged", "split"):
            ratios.setdefault(k, []).append(
                s["thickness"]["mixture"]["n_effective"] / true_kish(truth))
    out = [f"wrong counts: {len(kinds)}; " + _counts(kinds), set_aside_line(rows),
           order_off_line(rows), jpeg_line(rows), ceiling_line(rows)]
    for k, v in ratios.items():
        v = np.array(v)
        out.append(f"{k}: n_effective / the true regions' Kish count median {np.median(v):.2f}, "
                   f"range {v.min():.2f}-{v.max():.2f}, below 1 on {int((v < 1).sum())} of "
                   f"{v.size}")
    return out


def region_errors(row_summary_params_truth) -> np.ndarray:
    """A scene's signed region errors (nm, ``region_thickness_errors`` on its thickness map,
    ``WORK/results/joint/NAME/thickness_nm.npy`` beside the truth's ``stacks/NAME``)."""
    r, _, p, truth = row_summary_params_truth
    res = truth.parent.parent.parent / "results" / "joint" / r["name"] / "thickness_nm.npy"
    est = np.load(res)
    reg = region_thickness_errors(est, np.load(truth / "region_id.npy"),
                                  [x["mean_thickness_nm"] for x in p["regions"]])
    return np.asarray(reg["errors_nm"], dtype=np.float64)


def region_mae_kind(errors_nm) -> str:
    """Why a scene's region MAE is above :data:`MAE_TARGET_NM`: ``"order off"`` (a region read
    an order off), ``"alike"`` (the others' signed mean at least :data:`COMMON_SHARE` of their
    MAE), ``"scattered"``; ``"met"`` at or below the target, ``"none"`` without a region.

    >>> region_mae_kind([0.2, -0.3]), region_mae_kind([0.9, 1.1, 110.0])
    ('met', 'order off')
    >>> region_mae_kind([0.9, 1.1, 0.7]), region_mae_kind([0.9, -1.1, 0.7])
    ('alike', 'scattered')
    """
    e = np.asarray(errors_nm, dtype=np.float64)
    if e.size == 0:
        return "none"
    if np.mean(np.abs(e)) <= MAE_TARGET_NM:
        return "met"
    off = np.abs(e) > ORDER_OFF_NM
    if off.any():
        return "order off"
    return "alike" if abs(np.mean(e)) >= COMMON_SHARE * np.mean(np.abs(e)) else "scattered"


def region_mae_lines(rows) -> list:
    kinds = {True: [], False: []}
    signed = {}
    for row in rows:
        e = region_errors(row)
        wb = row[0].get("v_white_balance") == "1"
        kinds[wb].append(region_mae_kind(e))
        if e.size and not wb and not (np.abs(e) > ORDER_OFF_NM).any():
            signed.setdefault(row[0]["world"], []).append(float(np.mean(e)))
    every = [v for vs in signed.values() for v in vs]
    by_world = ", ".join(f"{w} {np.median(v):+.3f} ({len(v)})" for w, v in sorted(signed.items()))
    return [f"region MAE by kind, white-balance scenes: {_counts(kinds[True])}; the others: "
            f"{_counts(kinds[False])}",
            f"signed region error, median over the scenes without a white-balance error or a "
            f"region an order off: {np.median(every):+.3f} nm ({len(every)}); by world "
            f"{by_world}" if every else "signed region error: no scene"]


def apply_rule_line(rows) -> str:
    """What applying each gain the estimate names off 1 with a σ below :data:`APPLY_SIGMA`
    would do: the gains applied on scenes with a white-balance error (and how many within 2 %
    of the truth) and on balanced ones (and how many put more than 3 % off)."""
    wb_n, wb_ok, bal_n, bal_off = 0, 0, 0, 0
    for r, s, _, _ in rows:
        w = s.get("white_balance") or {}
        est, sig = w.get("estimate_rgb"), w.get("estimate_sigma_rb")
        if not est or not sig:
            continue
        wb = WhiteBalance(estimate_rgb=tuple(est), estimate_sigma=tuple(
            float("inf") if v is None else float(v) for v in sig))
        edge = dict(zip("RB", wb.at_search_edge()))
        truth = {"R": r["wb_true_r"], "B": r["wb_true_b"]}
        for name, g, sd in gains_off_one(wb):
            if sd >= APPLY_SIGMA or edge[name]:
                continue
            err = abs(g / float(truth[name]) - 1.0)
            if r.get("v_white_balance") == "1":
                wb_n, wb_ok = wb_n + 1, wb_ok + (err <= 0.02)
            else:
                bal_n, bal_off = bal_n + 1, bal_off + (err > 0.03)
    return (f"gains off 1 (> {GAIN_OFF_SIGMAS:g}σ, > {100 * GAIN_OFF_MIN:g} %) with σ < "
            f"{100 * APPLY_SIGMA:g} %: {wb_n} on white-balance scenes ({wb_ok} within 2 %), "
            f"{bal_n} on balanced ones ({bal_off} more than 3 % off)")


def white_balance_lines(rows) -> list:
    err, z, sd, colours, flags = [], [], [], [], []
    for r, s, _, _ in rows:
        wb = s.get("white_balance") or {}
        est, sig = wb.get("estimate_rgb"), wb.get("estimate_sigma_rb")
        if not est or not sig:
            continue
        e = (np.log(est[0] / float(r["wb_true_r"])), np.log(est[2] / float(r["wb_true_b"])))
        err.append(e)
        sd.append(tuple(_f(g) if g else float("nan") for g in sig))
        z.append(tuple(abs(v) / g for v, g in zip(e, sd[-1])))
        colours.append(wb.get("film_colours"))
        flags.append({k: v == "1" for k, v in r.items() if k.startswith("v_")})
    err, z, sd = np.abs(np.array(err)), np.array(z), np.array(sd)
    by = ", ".join(f"{c}: {np.median(err[np.array(colours) == c], axis=0)[0]:.3f} / "
                   f"{np.median(err[np.array(colours) == c], axis=0)[1]:.3f}"
                   for c in sorted(set(colours) - {None}))
    meds = [np.median(err[np.array([f[k] == on for f in flags])], axis=0)
            for k in flags[0] for on in (True, False)
            if any(f[k] == on for f in flags)]
    fin = np.isfinite(z)
    within = [f"{int((z[fin[:, i], i] <= 2.0).sum())} of {int(fin[:, i].sum())}"
              for i in (0, 1)]
    return [f"white-balance estimate, |log error| median R {np.median(err[:, 0]):.3f}, "
            f"B {np.median(err[:, 1]):.3f} ({len(err)} scenes); in its own σ "
            f"{np.nanmedian(z[:, 0]):.2f} / {np.nanmedian(z[:, 1]):.2f}; within 2σ (R / B, "
            f"of the scenes with a finite σ) {within[0]} / {within[1]}; σ median "
            f"{np.nanmedian(sd[:, 0]):.3f} / {np.nanmedian(sd[:, 1]):.3f}",
            f"by film colours (R / B): {by}",
            f"with and without each variation of the sweep: medians "
            f"{np.min(meds):.3f}-{np.max(meds):.3f}"]


def main(argv) -> None:
    if not argv:
        raise SystemExit(__doc__.splitlines()[2].strip())
    rows = list(scenes(argv))
    for line in (ndf_lines(rows, FitOptions()) + thickness_lines(rows)
                 + region_mae_lines(rows) + white_balance_lines(rows)
                 + [apply_rule_line(rows)]):
        print(line)


if __name__ == "__main__":
    main(sys.argv[1:])
