"""From the streamed focus curves of one window to a height, its uncertainty and a decision.

For every window (:class:`~microfacet.focus.stream.PeakTracker`) :func:`fit_window` fits the
peak (:mod:`microfacet.focus.peaks`) and tests its significance; :func:`add_relief_terms`
adds what the fit cannot see — the window mixes the heights of its pixels (slope, curvature,
a widened curve); :func:`combine` gives each pixel the window with the smallest uncertainty.

The uncertainty of a height, in z steps (docs/height-from-focus.md for the calibration)::

    σ² = σ_fit² + (κ_s·|∇h|·σ_w)² + (κ_c·|∂²h|·σ_w²)² + (κ_b·√(w² − (ρ·w_med)²)₊)² + σ_0²

* ``σ_fit``: delta method on the weighted least squares, with the residual variance pooled
  with its image-wide median among pixels of similar peak significance (empirical Bayes;
  a residual of 2 degrees of freedom alone is too noisy);
* ``|∇h|`` and ``|∂²h|`` (largest curvature) of the window's own height map, smoothed by the
  window's spread ``σ_w = √(window_px²/12 + 1)`` px: a tilted window sees a range of heights
  (random error ∝ slope·σ_w) and a curved one is biased (≈ curvature·σ_w²/2);
* ``w``: the fitted curve's width; much wider than the image's median ``w_med`` means the
  window holds several heights (a step);
* ``σ_0``: the floor of the curve model.

Significance: the peak excess ``F_max − μ`` over the tails' mean μ, in units of the tails'
noise ``max(√(Σd²/6N), μ/√k)`` (``d`` second differences along z, ``k`` the Gamma shape of
the measure of white noise), against :func:`~microfacet.focus.peaks.detection_threshold`.

References
----------
.. [1] N. Nagata, M. Kamei, K. Takahashi, K. Tobitani, T. Akagi, S. Yamamura, "Simulation
   Technology for Titanium Oxide Layer Interference Color", Technical Report (the seed paper),
   §3.3.2 (the height map, Fig. 16).
.. [2] S. Pertuz, D. Puig, M. A. Garcia, "Analysis of focus measure operators for
   shape-from-focus", Pattern Recognit. 46 (2013), doi:10.1016/j.patcog.2012.11.011.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..core import threads
from ..core.lazy import load
from ..core.pixels import pixel_size_yx
from ..core.threads import chunks, thread_map
from .peaks import detection_threshold, fit_peak, pertuz_db

cv2 = load("cv2")

__all__ = ["RELIEF_COEFFICIENT", "WindowFit", "combine", "disagreement_variance",
           "fit_window", "height_sigma_with_bias", "unresolved_relief_sigma_um"]

#: Nominal false-peak rate per pixel and window of the detection test (the measured rate on
#: pure noise is 1e-4 to 4e-4: the tails' mean and spread are estimated from few slices). A
#: constant of the significance test, not a setting: the reliability cut
#: (:class:`~microfacet.focus.options.FocusOptions` ``min_reliability_db``) is the knob.
DETECTION_ALPHA = 1e-5
#: Terms of the height uncertainty, in z steps (module notes; docs/height-from-focus.md,
#: calibrated with the accuracy-focus-coverage study so that |error| <= 2σ for 96-99 % of the
#: reliable pixels): σ² = σ_fit² + (slope·s·σ_w)² + (curv·c·σ_w²)²
#: + (broad·√(w² − (broad_ratio·w_med)²))² + floor², σ_w the window's spread; ``prior_dof``
#: weighs the image-wide residual variance in σ_fit; ``prefer`` < 1 would favour the main
#: window in :func:`combine`. Calibration constants of the model, not user options.
SIGMA_MODEL = {"slope": 0.4, "curv": 1.4, "broad": 0.5, "broad_ratio": 1.5, "floor": 0.03,
               "prior_dof": 8.0, "prefer": 1.0}
#: Coefficient κ_r of the unresolved-relief term of the analysis' reported height σ
#: (:func:`unresolved_relief_sigma_um`): the median over the 30 scenes of the development
#: sweep (seed 0 of docs/accuracy.md's issue-22 worlds) of the κ_r that makes 2σ cover 95 %
#: of each scene's facet-pixel height errors (``python -m pipelines run accuracy-ndf-worlds``,
#: its last column); checked on the independent seed-1 draw there.
#: A calibration constant of the model, not a user option.
RELIEF_COEFFICIENT = 0.57


@dataclass
class WindowFit:
    """Per-pixel results of one window (on its own grid until :meth:`upsampled`)."""

    window_px: int
    downsample: int
    height_um: np.ndarray       # fitted height (z units)
    sigma_fit: np.ndarray       # σ_fit, z steps
    sigma: np.ndarray           # total σ, z steps (after add_relief_terms)
    width: np.ndarray           # width of the fitted curve, z steps (inf without a peak)
    detected: np.ndarray        # significant peak
    significance: np.ndarray    # peak excess / detection threshold (≥ 1 where detected)
    pertuz_db: np.ndarray | None

    def upsampled(self, shape) -> WindowFit:
        """The maps on the full grid (bilinear; a coarse pixel (i, j) is pixel (2i, 2j))."""
        if self.downsample == 1:
            return self
        H, W = shape
        m = np.array([[1.0 / self.downsample, 0, 0], [0, 1.0 / self.downsample, 0]])

        def up(a, interp=cv2.INTER_LINEAR):
            return cv2.warpAffine(np.ascontiguousarray(a), m, (W, H),
                                  flags=interp | cv2.WARP_INVERSE_MAP,
                                  borderMode=cv2.BORDER_REPLICATE)

        finite = np.isfinite(self.sigma)
        sig = up(np.where(finite, self.sigma, 1e6).astype(np.float32))
        det = up(self.detected.astype(np.uint8), cv2.INTER_NEAREST).astype(bool)
        return WindowFit(self.window_px, 1, up(self.height_um), up(self.sigma_fit),
                         np.where(sig >= 1e5, np.inf, sig).astype(np.float32), up(self.width),
                         det, up(self.significance),
                         None if self.pertuz_db is None else up(self.pertuz_db))


def window_spread_px(window_px: int) -> float:
    """Spread (σ, px) of a window with the 3×3 operator: √(window_px²/12 + 1)."""
    return math.sqrt(window_px * window_px / 12.0 + 1.0)


def fit_window(tracker, zs, step, *, interpolation, shape_k, window_px, downsample=1,
               pertuz=False, alpha=DETECTION_ALPHA,
               prior_dof=SIGMA_MODEL["prior_dof"]) -> WindowFit:
    """Peak fit, significance and σ_fit of every pixel of one window.

    Parameters
    ----------
    tracker : PeakTracker
        After :meth:`~microfacet.focus.stream.PeakTracker.finish`.
    zs : ndarray
        Sorted slice heights; ``step`` their median spacing (the unit of the fit).
    interpolation : {"lorentz", "lsq", "gauss3", "none"}
    shape_k : float
        Gamma shape of the measure of noise.
    window_px, downsample : int
        The window's side (px) and grid (1 full, 2 half), recorded in the result.
    pertuz : bool
        Also compute the Pertuz reliability (dB).
    alpha : float
        The nominal false-peak rate (:data:`DETECTION_ALPHA`).
    prior_dof : float
        Weight (degrees of freedom) of the image-wide residual variance in σ_fit.

    Returns
    -------
    WindowFit
        On the tracker's grid: height in the unit of ``zs``; ``sigma_fit`` (= ``sigma``
        until :func:`add_relief_terms`) and ``width`` in z steps, inf without a peak;
        ``detected`` where the peak is significant.
    """
    n = zs.size
    r = tracker.r
    K = tracker.k
    H, W = tracker.best.shape
    height = np.empty((H, W), np.float32)
    var_unit = np.empty((H, W), np.float32)
    s2res = np.empty((H, W), np.float32)
    dof = np.empty((H, W), np.float32)
    width = np.empty((H, W), np.float32)
    signif = np.empty((H, W), np.float32)
    ok_all = np.empty((H, W), bool)
    pz = np.empty((H, W), np.float32) if pertuz else None
    thr = detection_threshold(n, shape_k, alpha)
    model = "gauss" if interpolation in ("lsq", "gauss3") else "lorentz"
    uniform = n < 3 or bool(np.allclose(np.diff(zs), step, rtol=1e-6, atol=0.0))
    offsets = (np.arange(K) - r).astype(np.float32)
    sub = slice(r - 1, r + 2) if interpolation == "gauss3" else slice(0, K)

    def block(ab):      # a block of rows (bounded temporaries), on the threads
        sl = slice(*ab)
        br = tracker.best_rank[sl].astype(np.int32)     # stored int16: the sums' precision
        vals = tracker.window[:, sl]
        fmax = tracker.best[sl]
        zc = zs[br]
        if uniform:
            xz = offsets          # NaN values mark the neighbours beyond the stack
        else:
            ranks = br[None] + (np.arange(K) - r)[:, None, None]
            inside = (ranks >= 0) & (ranks < n)
            xz = np.where(inside, (zs[np.clip(ranks, 0, n - 1)] - zc) / step,
                          np.nan).astype(np.float32)
        fit = fit_peak(vals[sub], xz[sub], model=model, weighted=(interpolation != "gauss3"),
                       dtype=np.float32, vmax=fmax)
        if interpolation == "none":
            off = np.zeros(br.shape, np.float32)
            var_unit[sl] = np.where(fit.ok, 1.0 / 12.0, np.inf)
            s2res[sl] = 1.0
            dof[sl] = 1e6
        else:
            off = fit.offset
            var_unit[sl] = fit.var_unit
            d = np.maximum(fit.n_valid - 3, 0).astype(np.float32)
            dof[sl] = d
            s2res[sl] = np.where(d > 0, fit.rss / np.maximum(d, 1.0), np.nan)
        height[sl] = zc + off * step
        width[sl] = fit.width
        ok_all[sl] = fit.ok & (fmax > 0)
        signif[sl] = _significance(tracker, sl, n, shape_k) / thr
        if pertuz:
            xp = np.where(np.isfinite(vals[sub]), (xz[sub] if xz.ndim > 1
                                                   else xz[sub][:, None, None]), np.nan)
            pz[sl] = pertuz_db(vals[sub], xp, fit, model, fmax, tracker.fsum[sl], n)

    thread_map(block, chunks(H, max(1, (1 << 16) // max(1, W))))
    detected = ok_all & (signif >= 1.0)
    # empirical-Bayes residual variance: pooled with its median at similar significance
    prior = _binned_prior(s2res, dof, signif, detected | ok_all)
    s2 = np.where(dof > 0, (dof * np.nan_to_num(s2res) + prior_dof * prior)
                  / (dof + prior_dof), prior)
    if interpolation == "none":
        s2 = np.ones_like(s2)
    sigma_fit = np.sqrt(np.maximum(s2 * var_unit, 0.0)).astype(np.float32)
    sigma_fit = np.where(ok_all, sigma_fit, np.inf).astype(np.float32)
    return WindowFit(int(window_px), int(downsample), height, sigma_fit, sigma_fit.copy(),
                     np.where(ok_all, width, np.inf).astype(np.float32), detected,
                     signif, pz)


def _significance(tracker, sl, n, shape_k):
    """Peak excess over the mean of the curve's tails, in units of the tails' noise, of the
    rows ``sl`` (inf for an excess over noiseless tails)."""
    r, K = tracker.r, tracker.k
    br = tracker.best_rank[sl].astype(np.int32)         # int32 counts: float64 means below
    vals = tracker.window[:, sl]
    lo_rank = np.maximum(br - r, 0)
    hi_rank = np.minimum(br + r, n - 1)
    nin = hi_rank - lo_rank + 1
    nt = n - nin
    vsum = np.zeros(br.shape, np.float32)
    for k in range(K):
        vsum += np.nan_to_num(vals[k])
    if (nt >= 2).all():
        mu = (tracker.fsum[sl] - vsum) / nt
    else:
        vmin = np.nanmin(vals, axis=0)
        mu = np.where(nt >= 2, (tracker.fsum[sl] - vsum) / np.maximum(nt, 1), vmin)
    d2in = np.zeros(br.shape, np.float32)
    nd2in = np.zeros(br.shape, np.int32)
    for j in range(1, K - 1):          # second differences inside the window
        has = (br - r + j - 1 >= 0) & (br - r + j + 1 <= n - 1)
        d2 = vals[j - 1] - 2.0 * vals[j] + vals[j + 1]
        d2in += np.where(has, d2 * d2, 0.0)
        nd2in += has
    nd2 = (n - 2) - nd2in
    tail_var = np.maximum(tracker.d2sum[sl] - d2in, 0.0) / (6.0 * np.maximum(nd2, 1))
    tail_var = np.where(nd2 >= 1, tail_var, 0.0)
    noise = np.sqrt(np.maximum(tail_var, mu * mu / shape_k))
    excess = tracker.best[sl] - mu
    return np.where(noise > 0, excess / np.maximum(noise, 1e-30),
                    np.where(excess > 0, np.inf, 0.0))


def _binned_prior(s2res, dof, signif, use, bins=16):
    """Median residual variance (÷ ln 2, the median of χ²₂/2) per significance bin."""
    ls = np.log(np.maximum(np.where(np.isfinite(signif), signif, 1e6), 1e-6)).astype(np.float32)
    sel = use & (dof > 0) & np.isfinite(s2res)
    flat_s, flat_v = ls[sel], s2res[sel]
    stride = max(1, flat_s.size // 200_000)
    flat_s, flat_v = flat_s[::stride], flat_v[::stride]
    if flat_s.size < bins:
        med = float(np.median(flat_v)) / math.log(2.0) if flat_v.size else 1.0
        return np.full(s2res.shape, med, np.float32)
    edges = np.quantile(flat_s, np.linspace(0.0, 1.0, bins + 1))
    idx = np.clip(np.searchsorted(edges, flat_s, side="right") - 1, 0, bins - 1)
    med = np.full(bins, np.nan)
    for i in range(bins):
        v = flat_v[idx == i]
        if v.size:
            med[i] = np.median(v) / math.log(2.0)
    med = np.where(np.isfinite(med), med, np.nanmax(med))
    full = np.clip(np.searchsorted(edges, ls, side="right") - 1, 0, bins - 1)
    return med[full].astype(np.float32)


def _normalised(a, w, sigma):
    num = cv2.GaussianBlur(a * w, (0, 0), sigma, borderType=cv2.BORDER_REFLECT)
    den = cv2.GaussianBlur(w, (0, 0), sigma, borderType=cv2.BORDER_REFLECT)
    return num / np.maximum(den, 1e-6)


def add_relief_terms(fit: WindowFit, step, model: dict) -> None:
    """Add the slope, curvature and width terms and the floor to ``fit.sigma`` (in place).

    Parameters
    ----------
    fit : WindowFit
        From :func:`fit_window`; its ``height_um`` is differentiated (units of ``step``).
    step : float
        The z step in the unit of ``fit.height_um`` (µm): the terms are in z steps.
    model : dict
        Coefficients ``slope``, ``curv``, ``broad``, ``broad_ratio`` and ``floor`` (z steps),
        see :data:`SIGMA_MODEL` and the module docstring.
    """
    ds = fit.downsample
    spread = window_spread_px(fit.window_px)
    s = spread / ds                                   # on the window's grid
    w = fit.detected.astype(np.float32)
    if not w.any():
        w = np.isfinite(fit.sigma_fit).astype(np.float32)
    h = np.where(np.isfinite(fit.height_um), fit.height_um / step, 0.0).astype(np.float32)
    sm = _normalised(h, w, s)
    h = w = None
    wd = fit.width[fit.detected & np.isfinite(fit.width)]
    w_med = float(np.median(wd)) if wd.size else np.inf
    wd = None
    sigma = np.empty(sm.shape, np.float32)
    # a block of rows at a time (with the one-row margin the 3×3 derivatives read): the
    # derivative and float64 temporaries are a block's, not the map's; the same numbers
    for a, b in threads.row_chunks(sm.shape):
        lo, hi = max(a - 1, 0), min(b + 1, sm.shape[0])
        part, keep = sm[lo:hi], slice(a - lo, b - lo)

        def d(dx, dy, part=part, keep=keep):
            return cv2.Sobel(part, cv2.CV_32F, dx, dy, ksize=3,
                             borderType=cv2.BORDER_REFLECT)[keep]
        gx, gy = d(1, 0) / 8.0, d(0, 1) / 8.0
        slope = np.sqrt(gx * gx + gy * gy) / ds                # z steps per full-grid pixel
        hxx, hyy, hxy = d(2, 0) / 4.0, d(0, 2) / 4.0, d(1, 1) / 4.0
        curv = (np.abs(0.5 * (hxx + hyy)) + np.sqrt(0.25 * (hxx - hyy) ** 2 + hxy * hxy)) \
            / ds ** 2
        width = fit.width[a:b]
        broad = np.sqrt(np.maximum(np.where(np.isfinite(width), width, 0.0) ** 2
                                   - (model["broad_ratio"] * w_med) ** 2, 0.0))
        var = (fit.sigma_fit[a:b].astype(np.float64) ** 2
               + (model["slope"] * slope * spread) ** 2
               + (model["curv"] * curv * spread ** 2) ** 2 + (model["broad"] * broad) ** 2
               + model["floor"] ** 2)
        sigma[a:b] = np.sqrt(var)
    fit.sigma = sigma


def combine(fits: list[WindowFit], primary: int, step, *, prefer: float = 1.0):
    """Per pixel the window with the smallest σ among those with a significant peak.

    ``fits`` are on one grid and sorted by window size. A larger window's σ first gets the
    part of its disagreement with the next smaller window that their σ_fit does not explain
    (a larger window is biased more by relief). ``prefer`` < 1 favours ``fits[primary]``: another
    window is taken only where its σ is below ``prefer`` times the primary's.

    Returns
    -------
    index : ndarray of int8
        Chosen window per pixel (among all windows by σ where no peak is significant).
    sigma : ndarray of float32
        Its σ, z steps.
    detected : ndarray of bool
        True where at least one window has a significant peak.
    """
    shape = np.shape(fits[0].sigma)
    # a block of rows at a time: the float64 temporaries are a block's, not the image's
    blocks = [slice(a, b) for a, b in threads.row_chunks(shape)]
    for lo, hi in zip(fits[:-1], fits[1:]):
        widened = np.empty(shape, np.float32)
        for r in blocks:
            both = lo.detected[r] & hi.detected[r]
            d2 = (((hi.height_um[r] - lo.height_um[r]) / step) ** 2 - hi.sigma_fit[r] ** 2
                  - lo.sigma_fit[r] ** 2)
            extra = np.where(both & np.isfinite(d2), np.maximum(d2, 0.0), 0.0)
            widened[r] = np.sqrt(hi.sigma[r].astype(np.float64) ** 2 + extra)
        hi.sigma = widened
    idx = np.empty(shape, np.int8)
    sigma = np.empty(shape, np.float32)
    detected = np.empty(shape, bool)
    others = [i for i in range(len(fits)) if i != primary]
    for r in blocks:
        raw = np.stack([f.sigma[r] for f in fits])
        det = np.stack([f.detected[r] for f in fits])
        score = np.minimum(np.where(np.isfinite(raw), raw, 1e5), 1e5).astype(np.float64)
        score[others] /= prefer
        score = np.where(det, score, score + 1e7)
        idx[r] = np.argmin(score, axis=0)
        sigma[r] = np.take_along_axis(raw, idx[r][None].astype(np.intp), 0)[0]
        detected[r] = det.any(0)
    return idx, sigma, detected


#: σ (px) of the neighbourhood over which :func:`disagreement_variance` pools.
DISAGREEMENT_POOL_PX = 7.0


def disagreement_variance(height, sigma, evidence_height, evidence_sigma, *,
                          pool_px=DISAGREEMENT_POOL_PX):
    """The variance of a height's bias that its σ does not hold: where the combined height
    and the evidence window's (each from the focus evidence at the pixel itself) both exist,
    their squared difference less what their σ explain, pooled over a Gaussian
    neighbourhood of ``pool_px`` (then clipped at 0: pooling first keeps it unbiased where
    the σ are right) so that a pixel without evidence of its own (whose height is borrowed
    from its neighbours) takes its neighbourhood's, and the image's mean where no neighbour
    has both.

    Parameters
    ----------
    height, sigma, evidence_height, evidence_sigma : ndarray (H, W)
        The combined height and its σ, the evidence window's and its σ (same units; NaN
        where absent).
    pool_px : float

    Returns
    -------
    ndarray of float32 (H, W)
        Variance to add to ``sigma``² (≥ 0).

    Examples
    --------
    >>> h = np.zeros((20, 20)); s = np.full((20, 20), 0.1)
    >>> he = h + 0.5; he[:, 10:] = np.nan                  # biased by 0.5 where measured
    >>> v = disagreement_variance(h, s, he, s)
    >>> round(float(v[5, 2]), 2), round(float(v[5, 18]), 2)
    (0.23, 0.23)
    """
    maps = np.broadcast_arrays(*(np.asarray(a) for a in (height, sigma, evidence_height,
                                                         evidence_sigma)))   # views
    shape = maps[0].shape
    excess, both, measured = np.zeros(shape, np.float32), np.zeros(shape, bool), []
    # in float64 as before, a block of rows at a time (a few MB of float64 in flight, and
    # the measured excesses, not 100 MB at 1 MP); the same numbers
    for a, z in threads.row_chunks(shape):
        h, s, he, se = (np.asarray(m[a:z], np.float64) for m in maps)
        b = np.isfinite(h) & np.isfinite(s) & np.isfinite(he) & np.isfinite(se)
        with np.errstate(invalid="ignore"):
            e = np.where(b, (h - he) ** 2 - s ** 2 - se ** 2, 0.0)   # unbiased, ± noise
        excess[a:z], both[a:z] = e, b
        measured.append(e[b])
    if not both.any():
        return np.zeros(shape, np.float32)
    num = cv2.GaussianBlur(excess, (0, 0), pool_px, borderType=cv2.BORDER_REFLECT)
    den = cv2.GaussianBlur(both.astype(np.float32), (0, 0), pool_px,
                           borderType=cv2.BORDER_REFLECT)
    fallback = np.float32(max(float(np.mean(np.concatenate(measured))), 0.0))
    pooled = np.where(den > 1e-3, num / np.maximum(den, np.float32(1e-3)), fallback)
    return np.maximum(pooled, 0.0).astype(np.float32)              # clipped once pooled


def unresolved_relief_sigma_um(rms_gradient, window_px_map, pixel_size_um, *,
                               coefficient=RELIEF_COEFFICIENT):
    """σ (µm) of the relief a pixel's focus window averages away: ``κ_r · Sdq · σ_w · p``.

    A window of spread ``σ_w`` px (:func:`window_spread_px` of the window each pixel took)
    returns the texture-weighted mean height of what it sees; a surface whose facets are
    smaller than the window differs from that mean at the pixel by about its slope times
    ``σ_w``. The slope is not the window's own smoothed gradient (the relief term of
    :data:`SIGMA_MODEL`, which cannot see facets smaller than the window) but the height
    map's RMS gradient ``Sdq`` over the whole map (ISO 25178-2, about its plane), with the
    calibrated coefficient :data:`RELIEF_COEFFICIENT`. Its errors are correlated between the
    windows, so the evidence window's disagreement (:func:`disagreement_variance`) cannot
    measure it.

    Parameters
    ----------
    rms_gradient : float
        The height map's RMS gradient Sdq (µm/µm); NaN or None gives 0.
    window_px_map : ndarray of int (H, W)
        The focus window (px) whose height each pixel took
        (:attr:`~microfacet.focus.height.FocusResult.window_px_map`).
    pixel_size_um : float or (float, float)
        Pixel size, one number or ``(y, x)`` (their geometric mean is used).
    coefficient : float
        κ_r.

    Returns
    -------
    ndarray of float32 (H, W)
        The σ in µm (0 where the window is 0 px, i.e. unknown).

    Examples
    --------
    >>> w = np.full((2, 2), 7, np.uint8)
    >>> s = unresolved_relief_sigma_um(0.2, w, 0.25, coefficient=1.0)
    >>> round(float(s[0, 0]), 4), round(0.2 * window_spread_px(7) * 0.25, 4)
    (0.1127, 0.1127)
    """
    g = 0.0 if rms_gradient is None or not np.isfinite(rms_gradient) else float(rms_gradient)
    py, px = pixel_size_yx(pixel_size_um)
    w = np.asarray(window_px_map)
    sizes = np.unique(w)
    spread = np.zeros(int(sizes.max()) + 1 if sizes.size else 1, np.float64)
    for k in sizes:
        spread[int(k)] = window_spread_px(int(k)) if k > 0 else 0.0
    # the σ of each window size, then looked up per pixel (no float64 map)
    sigma = (coefficient * g * math.sqrt(py * px) * spread).astype(np.float32)
    return sigma[w if w.dtype.kind in "ui" else w.astype(np.intp)]


def height_sigma_with_bias(focus):
    """σ of a :class:`~microfacet.focus.height.FocusResult`'s combined height with the
    variance of its unexplained disagreement with the evidence window added
    (:func:`disagreement_variance`); its own σ without an evidence window."""
    s = np.asarray(focus.height_sigma_um, np.float32)
    if focus.evidence_height_um is None:
        return s
    v = disagreement_variance(focus.height_fit_um, s, focus.evidence_height_um,
                              focus.evidence_sigma_um)
    out = np.multiply(s, s, dtype=np.float32)     # √(s² + v) in float32, in one array
    out += v
    return np.sqrt(out, out=out)
