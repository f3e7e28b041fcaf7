"""The focus curve around its peak: sub-slice peak fit, its variance, the Pertuz reliability,
and the significance test of the peak.

Two curve models are fitted by weighted least squares over the ``2r+1`` slices around the
sharpest one (positions in z steps, any spacing):

* ``"lorentz"``: a parabola in ``y = (F/F_max)^(-1/2)``. The gradient energy of a texture with
  a Gaussian autocorrelation of width ``s`` under Gaussian defocus of spread ``β·|z − μ|`` is
  ``F ∝ (s² + β²(z − μ)²)^-2``, exactly a parabola in ``F^(-1/2)``. Weights ``(F/F_max)³``
  (the inverse variance of ``y`` for a constant noise on ``F``).
* ``"gauss"``: a parabola in ``log F`` (a Gaussian focus curve), weights ``(F/F_max)²``.

The variance of the peak position follows from the normal equations (delta method):
``var(x0) = s²·J M⁻¹ Jᵀ`` with ``J = (∂x0/∂a, ∂x0/∂b)``, ``M`` the weighted normal matrix and
``s²`` the residual variance per unit weight (estimated by :mod:`microfacet.focus.height`,
pooled with its image-wide median at the same peak significance).

References
----------
.. [1] N. Nagata, M. Kamei, K. Takahashi, K. Tobitani, T. Akagi, S. Yamamura, "Simulation
   Technology for Titanium Oxide Layer Interference Color", Technical Report (the seed paper),
   §3.3.2 (the height map from the focus position of each pixel).
.. [2] S. Pertuz, D. Puig, M. A. Garcia, "Analysis of focus measure operators for
   shape-from-focus", Pattern Recognit. 46 (2013), doi:10.1016/j.patcog.2012.11.011 (the
   reliability ratio).
.. [3] S. K. Nayar, Y. Nakagawa, "Shape from focus", IEEE Trans. Pattern Anal. Mach. Intell.
   16(8) (1994) 824-831, doi:10.1109/34.308479 (Gaussian peak interpolation).

Examples
--------
>>> import numpy as np
>>> x = np.arange(-2.0, 3.0)[:, None]
>>> v = 1.0 / (1.0 + (x - 0.3) ** 2) ** 2
>>> fit = fit_peak(v, x, model="lorentz")
>>> round(float(fit.offset[0]), 6), round(float(fit.width[0]), 6)
(0.3, 1.0)
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..core.lazy import load

special = load("scipy.special")

__all__ = ["PeakFit", "detection_threshold", "fit_peak", "pertuz_db"]

MODELS = ("lorentz", "gauss")


@dataclass
class PeakFit:
    """Result of :func:`fit_peak` (arrays of the fit's dtype, shape (...))."""

    #: peak position in the unit of ``x`` (clipped to the valid span; 0 without a peak)
    offset: np.ndarray
    #: ``(a, b, c)`` of ``y ≈ a x² + b x + c`` (``y`` = log F or (F/F_max)^-1/2)
    coef: np.ndarray
    #: True where the fit has a peak
    ok: np.ndarray
    #: ``J M⁻¹ Jᵀ``: the variance of ``offset`` per unit residual variance
    var_unit: np.ndarray
    #: weighted residual sum of squares
    rss: np.ndarray
    #: number of valid points
    n_valid: np.ndarray
    #: width of the fitted curve (half width at 1/4 height for "lorentz", the Gaussian σ)
    width: np.ndarray


def fit_peak(values: np.ndarray, x: np.ndarray, *, model: str = "lorentz",
             weighted: bool = True, dtype=np.float64, vmax: np.ndarray | None = None) -> PeakFit:
    """Weighted least-squares peak fit of focus values around their maximum.

    Parameters
    ----------
    values : ndarray, shape (K, ...)
        Focus values at ``K`` neighbouring slices; NaN marks a missing neighbour.
    x : ndarray, shape (K, ...) or (K,)
        Their positions (e.g. ``z − z_best`` in z steps); NaN where missing. A 1-D ``x`` holds
        the same positions for every pixel (uniform spacing: faster).
    model : {"lorentz", "gauss"}
        Curve model (module docstring).
    weighted : bool
        Weights as in the module docstring (True) or uniform (False; with ``model="gauss"``
        and K = 3 this is the classic 3-point Gaussian interpolation).
    dtype : numpy dtype
        Working precision (``x`` should then be of order 1).
    vmax : ndarray, optional
        The largest valid value per pixel, if known.

    Returns
    -------
    PeakFit
        A flat curve (all valid values equal to 1e-6 relative) has no peak, whatever the sign
        of its rounding-level curvature.
    """
    if model not in MODELS:
        raise ValueError(f"model must be one of {MODELS}, not {model!r}")
    pts = _points(values, x, dtype, vmax)
    sums = _weighted_sums(pts, model, weighted)
    a, b, c, good, cof, inv = _solve_parabola(sums, pts.tiny)
    peak = (a < 0) if model == "gauss" else (a > 0)
    ok = good & peak & ~pts.flat
    a_ok = np.where(ok, a, -1.0 if model == "gauss" else 1.0)
    off = np.clip(np.where(ok, -b / (2.0 * a_ok), 0.0), *_span(sums, pts, weighted))
    # variance of x0 = -b / 2a per unit residual variance: J M^-1 J^T
    c00, c01, c11 = cof
    ja = -off / a_ok
    jb = -0.5 / a_ok
    var_unit = (ja * ja * c00 - 2.0 * ja * jb * c01 + jb * jb * c11) * inv
    var_unit = np.where(ok, np.maximum(var_unit, 0.0), np.inf)
    rss = np.zeros(pts.vmax.shape, dtype)
    for k in range(len(sums.ys)):
        r = sums.ys[k] - (a * sums.xs[k] + b) * sums.xs[k] - c
        rss += sums.ws[k] * r * r
    width = np.where(ok, _width(a_ok, b, c, model, pts.tiny), np.inf)
    return PeakFit(off.astype(dtype, copy=False), np.stack([a, b, c]), ok,
                   var_unit.astype(dtype, copy=False), rss, sums.n_valid, width.astype(dtype))


@dataclass
class _Points:
    """The valid values of a fit, per neighbour (NaN, ≤ 0 and positions missing: invalid)."""

    dtype: type
    tiny: float
    x: np.ndarray           # positions, (K, ...) or (K,)
    per_pixel: bool         # positions per pixel
    valid: list             # K masks
    vk: list                # K values (0 where invalid)
    vmax: np.ndarray        # largest valid value (≥ tiny)
    flat: np.ndarray        # all valid values equal to 1e-6 relative


def _points(values, x, dtype, vmax) -> _Points:
    v = np.asarray(values, dtype=dtype)
    K = v.shape[0]
    x = np.asarray(x, dtype=dtype)
    per_pixel = x.ndim > 1
    tiny = dtype(np.finfo(np.float32).tiny)
    valid = [np.isfinite(v[k]) & (v[k] > 0) for k in range(K)]
    if per_pixel:
        valid = [valid[k] & np.isfinite(x[k]) for k in range(K)]
    vk = [np.where(valid[k], v[k], 0.0).astype(dtype, copy=False) for k in range(K)]
    if vmax is None:
        vmax = vk[0].copy()
        for k in range(1, K):
            np.maximum(vmax, vk[k], out=vmax)
    vmax = np.maximum(np.asarray(vmax, dtype=dtype), tiny)
    vmin = np.where(valid[0], vk[0], np.inf).astype(dtype)
    for k in range(1, K):
        np.minimum(vmin, np.where(valid[k], vk[k], np.inf), out=vmin)
    return _Points(dtype, tiny, x, per_pixel, valid, vk, vmax, vmax - vmin <= 1e-6 * vmax)


@dataclass
class _Sums:
    """Weighted moments of the fit: ``s[i] = Σ w x^i`` (i ≤ 4), ``t[i] = Σ w y x^i`` (i ≤ 2),
    and per neighbour its ``y``, weight and position."""

    s: list
    t: list
    n_valid: np.ndarray
    ys: list
    ws: list
    xs: list


def _weighted_sums(pts: _Points, model: str, weighted: bool) -> _Sums:
    dtype, tiny = pts.dtype, pts.tiny
    shape = pts.vmax.shape
    s = [np.zeros(shape, dtype) for _ in range(5)]
    t = [np.zeros(shape, dtype) for _ in range(3)]
    out = _Sums(s, t, np.zeros(shape, np.int32), [], [], [])
    inv_vmax = 1.0 / pts.vmax
    for k, (valid, vk) in enumerate(zip(pts.valid, pts.vk)):
        u = np.maximum(vk * inv_vmax, tiny)
        if model == "gauss":
            y = np.log(np.maximum(vk, tiny))
            w = u * u if weighted else np.ones(shape, dtype)
        else:
            y = 1.0 / np.sqrt(u)
            w = u * u * u if weighted else np.ones(shape, dtype)
        w = np.where(valid, w, 0.0).astype(dtype, copy=False)
        xk = pts.x[k]
        if pts.per_pixel:
            xk = np.where(valid, xk, 0.0).astype(dtype, copy=False)
        elif np.isfinite(xk):
            xk = dtype(xk)
        else:
            xk = dtype(0.0)
            w = np.zeros(shape, dtype)
        out.n_valid += (w > 0) if weighted else valid
        wx = w * xk
        wx2 = wx * xk
        s[0] += w
        s[1] += wx
        s[2] += wx2
        s[3] += wx2 * xk
        s[4] += wx2 * xk * xk
        wy = w * y
        t[0] += wy
        t[1] += wy * xk
        t[2] += wx2 * y
        out.ys.append(y)
        out.ws.append(w)
        out.xs.append(xk)
    return out


def _solve_parabola(sums: _Sums, tiny):
    """``a, b, c`` of min Σ w (a x² + b x + c − y)² by Cramer's rule (0 where singular), the
    mask of the solvable ones, the cofactors ``(c00, c01, c11)`` and 1/det."""
    s0, s1, s2, s3, s4 = sums.s
    t0, t1, t2 = sums.t
    c00 = s2 * s0 - s1 * s1            # cofactors of M = [[s4 s3 s2] [s3 s2 s1] [s2 s1 s0]]
    c01 = s3 * s0 - s1 * s2
    c11 = s4 * s0 - s2 * s2
    c02 = s3 * s1 - s2 * s2
    det = s4 * c00 - s3 * c01 + s2 * c02
    da = t2 * c00 - s3 * (t1 * s0 - s1 * t0) + s2 * (t1 * s1 - s2 * t0)
    db = s4 * (t1 * s0 - s1 * t0) - t2 * c01 + s2 * (s3 * t0 - t1 * s2)
    dc = s4 * (s2 * t0 - t1 * s1) - s3 * (s3 * t0 - t1 * s2) + t2 * c02
    good = (np.abs(det) > 1e-12 * np.maximum(s4 * s2 * s0, tiny)) & (sums.n_valid >= 3)
    safe = np.where(good, det, 1.0)
    # a determinant that passes the test but underflows float32 (sums of huge or tiny
    # focus values) gives an infinite inverse: such a fit has no usable peak, not a NaN one
    with np.errstate(over="ignore", invalid="ignore"):
        inv = 1.0 / safe
        a, b, c = da * inv, db * inv, dc * inv
    good = good & np.isfinite(inv) & np.isfinite(a) & np.isfinite(b) & np.isfinite(c)
    inv = np.where(good, inv, 0.0)
    a = np.where(good, a, 0.0)
    b = np.where(good, b, 0.0)
    c = np.where(good, c, 0.0)
    return a, b, c, good, (c00, c01, c11), inv


def _span(sums: _Sums, pts: _Points, weighted: bool):
    """The smallest and largest position that took part in the fit (0 where none did)."""
    shape = pts.vmax.shape
    lo = np.full(shape, np.inf, pts.dtype)
    hi = np.full(shape, -np.inf, pts.dtype)
    for k in range(len(sums.xs)):
        has = sums.ws[k] > 0 if weighted else pts.valid[k]
        np.minimum(lo, np.where(has, sums.xs[k], np.inf), out=lo)
        np.maximum(hi, np.where(has, sums.xs[k], -np.inf), out=hi)
    return np.where(np.isfinite(lo), lo, 0.0), np.where(np.isfinite(hi), hi, 0.0)


def _width(a_ok, b, c, model, tiny):
    """Width of the fitted curve: the Gaussian σ, or the Lorentz half width at 1/4 height."""
    if model == "gauss":
        return np.sqrt(-0.5 / a_ok)
    y0 = c - b * b / (4.0 * a_ok)
    return np.sqrt(np.maximum(y0, tiny) / a_ok)


def peak_fit(values: np.ndarray, x: np.ndarray, *, weighted: bool = True, dtype=np.float64,
             model: str = "gauss"):
    """Least-squares peak fit (a Gaussian by default: a parabola in ``log F``).

    The earlier interface of :func:`fit_peak`: returns ``(offset, coef, ok)``; ``coef`` is
    ``(a, b, c)`` of ``log F ≈ a x² + b x + c`` for ``model="gauss"``.
    """
    f = fit_peak(values, x, model=model, weighted=weighted, dtype=dtype)
    return f.offset, f.coef, f.ok


def model_curve(coef, x, model, fmax):
    """The fitted focus curve at ``x`` (same unit as the fit), in focus units."""
    a, b, c = coef
    y = a * x * x + b * x + c
    if model == "gauss":
        return np.exp(np.clip(y, -80.0, 80.0))
    return fmax / np.maximum(y, 1e-6) ** 2


def pertuz_db(vals, xz, fit: PeakFit, model, fmax, fsum, n):
    """Reliability after Pertuz et al. (2013), dB: ``20·log10(N·F_max / Σ_k |F_k − G(z_k)|)``
    with the residual exact inside the fit window and ``F`` itself outside; 0 dB where the
    fit has no peak."""
    finite = np.isfinite(vals)
    vin = np.where(finite, vals, 0.0)
    xv = np.where(np.isfinite(xz), xz, 0.0)
    g = model_curve(fit.coef, xv, model, fmax)
    resid_in = np.where(finite, np.abs(vals - g), 0.0).sum(0)
    outside = np.maximum(fsum - vin.sum(0), 0.0)
    err = resid_in + outside
    tiny = 1e-30
    r = 20.0 * np.log10(np.maximum(n * fmax, tiny) / np.maximum(err, tiny * n))
    return np.clip(np.where(fit.ok & (fmax > 0), r, 0.0), -200, 200)


def detection_threshold(n: int, shape_k: float, alpha: float) -> float:
    """Smallest significant peak excess, in units of the noise spread of the focus measure.

    Under the null hypothesis (pure noise, no focus peak) the ``n`` focus values of a pixel are
    independent Gamma variables of shape ``k`` (:func:`microfacet.focus.measures.noise_shape`)
    and mean μ, spread μ/√k; their maximum exceeds ``μ + t·μ/√k`` with probability ``alpha``
    for the returned ``t``.

    >>> round(detection_threshold(24, 15.8, 1e-5), 2)
    7.0
    """
    q = float(special.gammaincinv(shape_k, (1.0 - alpha) ** (1.0 / max(n, 1)))) / shape_k
    return (q - 1.0) * math.sqrt(shape_k)
