"""Focus measures: how sharp each pixel's neighbourhood is in one slice.

``operator``: ``"tenengrad"`` (squared Sobel gradient, default), ``"sml"``
(sum-modified-Laplacian, Nayar & Nakagawa 1994) or ``"glv"`` (grey-level local variance),
accumulated over a window of ``window_px`` pixels. ``window="gaussian"`` (default) uses a
Gaussian window with the same standard deviation as a box of side ``window_px``
(σ = window_px/√12); ``window="box"`` uses the box itself. ``colour="luma"`` (default) measures
the Rec. 601 luma; ``colour="rgb"`` sums the measure of the three channels (it sees
isoluminant colour texture, at three times the noise floor of one channel).

:func:`focus_measures` computes several windows from one slice, sharing the per-pixel energy;
a window can be evaluated on a grid downsampled by 2 (``downsample=2``: the energy is reduced
with :func:`cv2.pyrDown`, then windowed with the remaining spread), which is exact enough for
windows of 11 px and more and costs a quarter. The defaults were chosen from measurements
(docs/height-from-focus.md).

References
----------
.. [1] N. Nagata, M. Kamei, K. Takahashi, K. Tobitani, T. Akagi, S. Yamamura, "Simulation
   Technology for Titanium Oxide Layer Interference Color", Technical Report (the seed paper),
   §3.3.2 (the height map from the focus position of each pixel).
.. [2] S. Pertuz, D. Puig, M. A. Garcia, "Analysis of focus measure operators for
   shape-from-focus", Pattern Recognit. 46 (2013), doi:10.1016/j.patcog.2012.11.011.
.. [3] S. K. Nayar, Y. Nakagawa, "Shape from focus", IEEE Trans. Pattern Anal. Mach. Intell.
   16(8) (1994) 824-831, doi:10.1109/34.308479 (sum-modified-Laplacian).
.. [4] E. Krotkov, "Focusing", Int. J. Comput. Vision 1 (1988) 223-237, doi:10.1007/BF00127822
   (Tenengrad).

Examples
--------
>>> import numpy as np
>>> img = np.zeros((16, 16), np.float32); img[:, 8:] = 1
>>> f = focus_measure(img)
>>> bool(f[8, 8] > f[8, 2])
True
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from ..core.lazy import load
from .options import COLOURS, OPERATORS, WINDOWS, FocusOptions, odd_window_reason

cv2 = load("cv2")

__all__ = ["focus_measure", "focus_measures", "measure_spread_px"]

#: The defaults of the keyword arguments: those of :class:`~microfacet.focus.options.
#: FocusOptions` (declared there only).
_DEFAULTS = FocusOptions()


_ML_KX = np.array([[-1.0, 2.0, -1.0]], dtype=np.float32)
#: spread (σ, px) that cv2.pyrDown's 5-tap binomial kernel applies before decimation
_PYR_SIGMA = 1.0


def to_grey(image: np.ndarray) -> np.ndarray:
    """Luma of an image for focus measurement.

    Parameters
    ----------
    image : ndarray, shape (H, W) or (H, W, 3)
        Grey or RGB; any real dtype.

    Returns
    -------
    ndarray of float32, shape (H, W)
        The image itself for grey input, Rec. 601 luma (0.299 R + 0.587 G + 0.114 B) for RGB.
    """
    img = np.asarray(image)
    if img.ndim == 2:
        return img.astype(np.float32, copy=False)
    if img.ndim == 3 and img.shape[2] == 3:
        return cv2.cvtColor(img.astype(np.float32, copy=False), cv2.COLOR_RGB2GRAY)
    raise ValueError(f"image must have shape (H, W) or (H, W, 3), got {img.shape}")


def _check_window(window_px, window):
    """Raise ValueError unless ``window_px`` is an odd integer >= 1 and ``window`` known."""
    reason = odd_window_reason(window_px)
    if reason is not None:
        raise ValueError(f"window_px {reason}")
    if window not in WINDOWS:
        raise ValueError(f"window must be 'gaussian' or 'box', not {window!r}")


def _window_sum(img: np.ndarray, window_px: int, window: str, downsample: int = 1, *,
                dst=None) -> np.ndarray:
    """Window mean of ``img`` (already reduced by ``downsample`` when that is 2), written
    into ``dst`` when given."""
    if downsample == 2:
        sig = math.sqrt(max(window_px * window_px / 12.0 - _PYR_SIGMA ** 2, 0.0)) / 2.0
        side = max(1, int(round(window_px / 2.0)) | 1)
        if window == "box" and side > 1:
            return _into(cv2.boxFilter(img, -1, (side, side), dst=dst, normalize=True,
                                       borderType=cv2.BORDER_REFLECT), dst)
        if window != "box" and sig > 0.05:
            return _into(cv2.GaussianBlur(img, (0, 0), sig, dst=dst,
                                          borderType=cv2.BORDER_REFLECT), dst)
        return _into(img, dst)
    if window_px == 1:
        return _into(img, dst)
    if window == "box":
        return _into(cv2.boxFilter(img, -1, (window_px, window_px), dst=dst, normalize=True,
                                   borderType=cv2.BORDER_REFLECT), dst)
    sigma = window_px / math.sqrt(12.0)
    return _into(cv2.GaussianBlur(img, (0, 0), sigma, dst=dst, borderType=cv2.BORDER_REFLECT),
                 dst)


def _into(a, dst):
    """``a``, in ``dst`` when one is given (copied there unless OpenCV already wrote it)."""
    if dst is None or a is dst:
        return a
    np.copyto(dst, a)
    return dst


def _channels(image, colour):
    img = np.asarray(image)
    if colour == "rgb" and img.ndim == 3:
        return img.astype(np.float32, copy=False)
    if colour not in COLOURS:
        raise ValueError(f"colour must be one of {COLOURS}, not {colour!r}")
    return to_grey(img)


def _sum_channels(e):
    if e.ndim == 2:
        return e
    return cv2.transform(e, np.ones((1, 3), np.float32))


def _energy(g, operator):
    """Per-pixel (unwindowed) energy of ``g`` (grey or 3-channel) for tenengrad and sml."""
    border = cv2.BORDER_REFLECT
    if operator == "tenengrad":
        gx = cv2.Sobel(g, cv2.CV_32F, 1, 0, ksize=3, borderType=border)
        gy = cv2.Sobel(g, cv2.CV_32F, 0, 1, ksize=3, borderType=border)
        cv2.multiply(gx, gx, dst=gx)
        cv2.multiply(gy, gy, dst=gy)
        return _sum_channels(cv2.add(gx, gy, dst=gx))
    mx = cv2.filter2D(g, cv2.CV_32F, _ML_KX, borderType=border)
    my = cv2.filter2D(g, cv2.CV_32F, _ML_KX.T, borderType=border)
    return _sum_channels(cv2.add(cv2.absdiff(mx, 0.0), cv2.absdiff(my, 0.0)))


def focus_measures(image: np.ndarray, windows: Sequence[tuple[int, str, int]], *,
                   operator: str = _DEFAULTS.operator,
                   colour: str = _DEFAULTS.colour, out=None) -> list[np.ndarray]:
    """The focus measure of one slice for several windows.

    Parameters
    ----------
    image : ndarray, shape (H, W) or (H, W, 3)
        One slice (float, typically in [0, 1]).
    windows : sequence of (window_px, window, downsample)
        Odd window side, ``"gaussian"`` or ``"box"``, and 1 (full grid) or 2 (the result on
        the grid ``[::2, ::2]``, shape ``((H+1)//2, (W+1)//2)``).
    operator, colour
        See :func:`focus_measure`.
    out : sequence of ndarray or None, optional
        Where to write each window's map (float32, C-contiguous, of its grid), e.g. the ring
        buffers of the streaming peak trackers (:meth:`~microfacet.focus.stream.PeakTracker.
        next_slot`); the maps returned are these arrays, with the same values as without.

    Returns
    -------
    list of ndarray of float32
        One map per window, non-negative, larger is sharper.
    """
    if operator not in OPERATORS:
        raise ValueError(f"operator must be one of {OPERATORS}, not {operator!r}")
    for px, win, ds in windows:
        _check_window(px, win)
        if ds not in (1, 2):
            raise ValueError(f"downsample must be 1 or 2, got {ds!r}")
    dsts = [None] * len(windows) if out is None else list(out)
    if len(dsts) != len(windows):
        raise ValueError(f"out: one array per window ({len(windows)}), got {len(dsts)}")
    g = _channels(image, colour)
    maps = []
    if operator == "glv":
        g2 = cv2.multiply(g, g)
        half = None
        for (px, win, ds), dst in zip(windows, dsts):
            a, b = g, g2
            if ds == 2:
                half = half or (cv2.pyrDown(g), cv2.pyrDown(g2))
                a, b = half
            m = _window_sum(a, px, win, ds)
            v = cv2.subtract(_window_sum(b, px, win, ds), cv2.multiply(m, m))
            maps.append(_into(cv2.max(_sum_channels(v), 0.0, dst=dst), dst))
        return maps
    e = _energy(g, operator)
    e_half = None
    for (px, win, ds), dst in zip(windows, dsts):
        if ds == 2:
            e_half = cv2.pyrDown(e) if e_half is None else e_half
            maps.append(_window_sum(e_half, px, win, 2, dst=dst))
        else:
            maps.append(_window_sum(e, px, win, dst=dst))
    return maps


def focus_measure(image: np.ndarray, *, operator: str = _DEFAULTS.operator,
                  window_px: int = _DEFAULTS.window_px, window: str = _DEFAULTS.window,
                  colour: str = _DEFAULTS.colour) -> np.ndarray:
    """Focus measure of one slice.

    Parameters
    ----------
    image : ndarray, shape (H, W) or (H, W, 3)
        One slice (float, typically in [0, 1]).
    operator : {"tenengrad", "sml", "glv"}
        ``"tenengrad"``: window mean of ``Gx² + Gy²`` (3×3 Sobel). ``"sml"``: window mean of the
        modified Laplacian ``|2I − I(x−1) − I(x+1)| + |2I − I(y−1) − I(y+1)|`` (Nayar & Nakagawa
        1994). ``"glv"``: local grey-level variance over the window.
    window_px : int
        Odd window side in pixels.
    window : {"gaussian", "box"}
        Window shape; the Gaussian has σ = window_px/√12 (the box's standard deviation).
    colour : {"luma", "rgb"}
        Measure the luma of an RGB slice, or sum the measures of its three channels.

    Returns
    -------
    ndarray of float32, shape (H, W)
        Non-negative; larger is sharper.
    """
    _check_window(window_px, window)
    return focus_measures(image, [(window_px, window, 1)], operator=operator,
                          colour=colour)[0]


def _operator_kernels(operator):
    """The 2D kernels whose responses an operator's energy sums (:func:`_energy`), and the
    power of those responses: OpenCV's own 3×3 Sobel pair for tenengrad (squared), the
    modified Laplacian's pair for sml (absolute); none for glv (its window is its support)."""
    if operator == "tenengrad":
        kx, ky = cv2.getDerivKernels(1, 0, 3)
        return (np.outer(ky, kx), np.outer(kx, ky)), 2
    if operator == "sml":
        return (_ML_KX, _ML_KX.T), 1
    return (), 2


def measure_spread_px(*, operator: str, window_px: int, window: str) -> float:
    """σ (px, per axis) of the support of a focus measure at one pixel: how far from a pixel
    the texture lies whose focus its measure (and so its height) reports.

    A height from focus is the texture-weighted mean height over this support, not the
    height at the pixel: at a crease between two facets each side's heights mix (the
    facet planes undo that, :func:`~microfacet.analysis.planes.fit_unmixed_planes`). The
    variance is the window's (``window_px²/12``, a box's ``(window_px² − 1)/12``) plus the
    operator's: the mean over both axes and both kernels of ``Σ q² |k(q)|^p / Σ |k(q)|^p``
    (p = 2 for tenengrad's squared responses, 1 for sml's absolute ones), the spread of a
    point's share of the energy (tenengrad 2/3 px², sml 1/4 px², glv 0).

    >>> round(measure_spread_px(operator="tenengrad", window_px=3, window="gaussian"), 4)
    1.1902
    >>> measure_spread_px(operator="glv", window_px=1, window="box")
    0.0
    """
    if operator not in OPERATORS:
        raise ValueError(f"operator must be one of {OPERATORS}, not {operator!r}")
    _check_window(window_px, window)
    var_w = window_px * window_px / 12.0 if window == "gaussian" else (window_px ** 2 - 1) / 12.0
    var_k = []
    kernels, power = _operator_kernels(operator)
    for k in kernels:
        w = np.abs(np.asarray(k, dtype=np.float64)) ** power
        qy = np.arange(k.shape[0]) - (k.shape[0] - 1) / 2.0
        qx = np.arange(k.shape[1]) - (k.shape[1] - 1) / 2.0
        var_k.append(0.5 * (float(np.sum(w * qy[:, None] ** 2)) + float(np.sum(w * qx ** 2)))
                     / float(np.sum(w)))
    var_op = float(np.mean(var_k)) if var_k else 0.0
    return math.sqrt(var_w + var_op)


_NOISE_SHAPE: dict = {}


def noise_shape(*, operator: str, window_px: int, window: str, downsample: int,
                colour: str, channels: int) -> float:
    """Shape ``k = mean²/variance`` of the focus measure of white noise (measured once per
    setting on a 256×256 noise image and cached).

    For a quadratic measure (Tenengrad, GLV) of Gaussian noise the windowed value is close to
    a Gamma variable with this shape: ``k`` is the number of independent noise samples the
    window averages, which sets the false-peak threshold of the height step
    (:func:`microfacet.focus.peaks.detection_threshold`).
    """
    key = (operator, int(window_px), window, int(downsample), colour, int(channels))
    if key not in _NOISE_SHAPE:
        rng = np.random.default_rng(12345)
        shape = (256, 256, 3) if channels == 3 else (256, 256)
        img = rng.standard_normal(shape).astype(np.float32)
        f = focus_measures(img, [(window_px, window, downsample)], operator=operator,
                           colour=colour)[0]
        b = 16 // downsample
        f = f[b:-b, b:-b].astype(np.float64)
        _NOISE_SHAPE[key] = float(f.mean() ** 2 / max(f.var(), 1e-300))
    return _NOISE_SHAPE[key]
