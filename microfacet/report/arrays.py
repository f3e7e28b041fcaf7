"""Arrays prepared for display: finite values, maps reduced to the pixels a page shows,
colour limits and histograms.

A map is drawn at the resolution its panel can show (:func:`display_block`): at least
:data:`~microfacet.report.layout.PDF_DPI` pixels per inch of the panel and at most
:data:`MAX_MAP_PX` a side, by a NaN-aware block mean (:func:`block_mean`) that sums strided
views of the full-resolution map (temporaries of 1/block of its size, no full-size copy).
Percentiles are exact but pick their order statistics among a few values near either end
(:func:`value_stats`), so a map is neither copied nor partitioned whole.

Examples
--------
>>> display_block((992, 992), (2.19, 2.19), dpi=150)  # 331 pixels for 2.19 inches
3
>>> block_mean(np.array([[1.0, np.nan, 3.0], [1.0, 2.0, 5.0]]), 2).tolist()
[[1.3333333730697632, 4.0]]
"""

from __future__ import annotations

import math

import numpy as np

from ..core.densities import histogram_density

__all__ = ["MAX_MAP_PX", "colour_limits", "downsample", "histogram", "value_stats"]

#: Maps are block-averaged so that neither side exceeds this many pixels (map panels are
#: 2.2–3.3 inches wide: 512 pixels is over 150 per inch; larger maps only fatten the PDF).
MAX_MAP_PX = 512


def finite(a, mask=None):
    """The finite values of ``a`` (None: none) outside ``mask`` (True = masked), 1-D float
    (float32 maps stay float32: no float64 copy of a full map)."""
    if a is None:
        return np.empty(0)
    a = np.asarray(a)
    if a.dtype.kind != "f":
        a = a.astype(np.float64)
    ok = np.isfinite(a)
    if mask is not None and mask.shape == a.shape:
        ok &= ~mask
    return a[ok]


def display_block(shape, box_in=None, *, dpi=150.0, max_px=MAX_MAP_PX):
    """The block size at which a map of ``shape`` (H, W, ...) is drawn in a box of
    ``box_in`` (width, height) inches: the largest that keeps at least ``dpi`` pixels per
    inch of the box, and at least the one that brings both sides to ``max_px`` or fewer.

    >>> display_block((1984, 1984), (3.25, 3.25)), display_block((1984, 1984))
    (4, 4)
    >>> display_block((300, 300), (2.0, 2.0)), display_block((4000, 10), (1.0, 1.0))
    (1, 8)
    """
    h, w = shape[:2]
    block = max(1, math.ceil(max(h, w) / max_px))
    if box_in is not None and min(box_in) > 0:
        block = max(block, math.floor(min(w / (box_in[0] * dpi), h / (box_in[1] * dpi))))
    return block


def _block_sums(x, f, axis):
    """Sums of ``f`` consecutive slices of ``x`` along ``axis`` (0 or 1; the last block
    may be shorter), accumulated in place from ``f`` strided views (no reshaped copy)."""
    out = None
    for k in range(min(f, x.shape[axis])):
        part = x[k::f] if axis == 0 else x[:, k::f]
        if out is None:
            out = part.astype(np.float32 if x.dtype.kind == "f" else np.int32)
        elif axis == 0:
            out[:part.shape[0]] += part
        else:
            out[:, :part.shape[1]] += part
    return out


def block_mean(a, f):
    """Mean of each ``f`` × ``f`` block of ``a`` (H×W or H×W×C; NaN ignored, an all-NaN
    block is NaN; the last blocks of a side not a multiple of ``f`` are smaller), float32.

    Rows are summed first, from ``f`` views of every ``f``-th row; temporaries are 1/``f``
    of the map.
    """
    a = np.asarray(a)
    if a.dtype == bool:
        a = a.view(np.uint8)
    h, w = a.shape[:2]
    # NaN propagates through a sum: one pass, no temporary (inf − inf only costs the
    # NaN-aware path)
    with np.errstate(over="ignore", invalid="ignore"):
        nan = a.dtype.kind == "f" and bool(np.isnan(np.add.reduce(a, axis=None)))
    if nan:  # sums of the values and of the valid counts
        rows = cnt = None
        for k in range(min(f, h)):
            part = a[k::f]
            ok = ~np.isnan(part)
            v = np.where(ok, part, np.float32(0)).astype(np.float32, copy=False)
            if rows is None:
                rows, cnt = v.copy(), ok.astype(np.int32)
            else:
                rows[:part.shape[0]] += v
                cnt[:part.shape[0]] += ok
        total, n = _block_sums(rows, f, 1), _block_sums(cnt, f, 1)
    else:  # counts from the block sizes alone
        total = _block_sums(_block_sums(a, f, 0), f, 1)
        nr = np.minimum(f, h - f * np.arange(total.shape[0]))
        nc = np.minimum(f, w - f * np.arange(total.shape[1]))
        n = np.multiply.outer(nr, nc).reshape(nr.size, nc.size, *([1] * (a.ndim - 2)))
    with np.errstate(invalid="ignore", divide="ignore"):
        return (total / n).astype(np.float32, copy=False)


def downsample(a, max_px=MAX_MAP_PX, *, block=None):
    """Block-average ``a`` (H×W or H×W×C; NaN-aware) so neither side exceeds ``max_px``,
    or by ``block`` if given (see :func:`display_block`).

    Returns the reduced array and the block size (1 if unchanged). A boolean array gives a
    boolean array (a block is True if at least half of it is).

    >>> small, block = downsample(np.ones((1030, 20), bool))
    >>> small.shape, small.dtype.name, block
    ((344, 7), 'bool', 3)
    """
    f = display_block(a.shape, max_px=max_px) if block is None else max(1, int(block))
    if f <= 1:
        return a, 1
    x = block_mean(a, f)
    return (x >= 0.5 if a.dtype == bool else x), f


def value_stats(values, q, mask=None):
    """``(percentiles q, min, max)`` of the finite ``values`` (an array, or a sequence of
    arrays taken together) outside ``mask`` (True = masked; arrays of its shape only), or
    None if there are none.

    The percentiles are numpy's (``np.percentile``, linear) of the values as float64. For
    large maps each order statistic is picked among the few values beyond a threshold that
    a strided subsample places just past it (exact: the threshold is checked), so that a
    map is neither copied nor partitioned whole.

    >>> value_stats([np.array([3.0, np.nan, 1.0]), np.array([2.0, 4.0])], [0, 50, 100])
    ((1.0, 2.5, 4.0), 1.0, 4.0)
    """
    arrays = [np.asarray(v) for v in (values if isinstance(values, (list, tuple))
                                      else [values])]
    arrays = [(a if a.dtype.kind == "f" else a.astype(np.float64)).reshape(-1)
              for a in arrays]
    keep = [None if mask is None or mask.size != a.size else ~mask.reshape(-1)
            for a in arrays]
    n = sum(np.count_nonzero(np.isfinite(a) if k is None else np.isfinite(a) & k)
            for a, k in zip(arrays, keep))
    if n == 0:
        return None
    pos = np.asarray(q, dtype=np.float64) / 100.0 * (n - 1)
    below = np.floor(pos).astype(np.int64)
    above = np.minimum(below + 1, n - 1)
    stats = _OrderStats(arrays, keep, n)
    ranks = sorted(set(below.tolist()) | set(above.tolist()) | {0, n - 1})
    v = dict(zip(ranks, stats.values(ranks)))
    a = np.array([v[i] for i in below])
    b = np.array([v[i] for i in above])
    t = pos - below
    diff = b - a  # numpy's linear interpolation, from either end
    p = np.where(t >= 0.5, b - diff * (1.0 - t), a + diff * t)
    return tuple(float(x) for x in p), v[0], v[n - 1]


class _OrderStats:
    """The values of given ranks (0-based, ascending) among the ``n`` finite values of
    flat ``arrays`` (``keep``: which of them count, None: all)."""

    SMALL = 1 << 18      # fewer values: partition them all
    SAMPLE = 1 << 14     # subsample the thresholds are estimated from
    END = 0.1            # ranks within this share of either end are picked among few values

    def __init__(self, arrays, keep, n):
        self.arrays, self.keep, self.n = arrays, keep, n
        self.sample = None
        if n > self.SMALL:
            step = max(1, n // self.SAMPLE)
            sample = np.sort(finite(np.concatenate([a[::step] for a in arrays])))
            self.sample = sample if sample.size >= 100 else None

    def _values(self, select=None):
        """The finite values that count, or those of them where ``select(array)``."""
        parts = []
        for a, k in zip(self.arrays, self.keep):
            ok = np.isfinite(a) if select is None else select(a)
            if k is not None:
                ok &= k
            parts.append(a[ok])
        v = np.concatenate(parts).astype(np.float64)
        return v if select is None else v[np.isfinite(v)]

    def values(self, ranks):
        """The values of ``ranks``, as floats."""
        n, out = self.n, {}
        rest = list(ranks)
        low = [r for r in ranks if r <= self.END * (n - 1)]
        high = [r for r in ranks if r >= (1.0 - self.END) * (n - 1)]
        if self.sample is not None and len(low) + len(high) == len(rest):
            for group, top in ((low, False), (high, True)):
                got = self._near_end(group, top) if group else None
                if got is not None:
                    out.update(got)
                    rest = [r for r in rest if r not in got]
        if rest:
            v = np.partition(self._values(), rest)
            out.update((r, v[r]) for r in rest)
        return [float(out[r]) for r in ranks]

    def _near_end(self, ranks, top):
        """``{rank: value}`` of ``ranks`` near the low (or ``top``) end, picked among the
        values beyond a threshold from the subsample; None if the threshold fell short."""
        n, s = self.n, self.sample
        far = max(ranks) if not top else min(ranks)
        frac = far / (n - 1)
        margin = 0.01 + 4.0 * math.sqrt(max(frac * (1.0 - frac), 1e-4) / s.size)
        if not top:
            t = s[min(s.size - 1, math.ceil((frac + margin) * (s.size - 1)))]
            v = self._values(lambda a: a <= t)   # the v.size smallest values
            idx = list(ranks)
        else:
            t = s[max(0, math.floor((frac - margin) * (s.size - 1)))]
            v = self._values(lambda a: a >= t)   # the v.size largest values
            idx = [r - (n - v.size) for r in ranks]
        if not all(0 <= i < v.size for i in idx):
            return None
        v = np.partition(v, idx)
        return {r: v[i] for r, i in zip(ranks, idx)}


def limits_of(stats, lo=1.0, *, floor=None):
    """Colour limits ``(vmin, vmax, extend)`` from ``stats = ((p_lo, p_hi), min, max)`` of
    :func:`value_stats` (None: no values) — see :func:`colour_limits`."""
    if stats is None:
        return 0.0, 1.0, "neither"
    (vmin, vmax), v_min, v_max = stats
    if floor is not None:
        vmin = max(floor, vmin) if lo > 0 else floor
    if not vmax > vmin:  # a constant map: a range of ±5 % (at least ±1) about it
        d = max(abs(vmin) * 0.05, 1.0)
        vmin, vmax = vmin - d, vmax + d
        if floor is not None and vmin < floor:
            vmin, vmax = floor, max(vmax, floor + d)
    below, above = v_min < vmin, v_max > vmax
    extend = {(True, True): "both", (True, False): "min", (False, True): "max"}.get(
        (bool(below), bool(above)), "neither")
    return float(vmin), float(vmax), extend


def colour_limits(values, lo=1.0, hi=99.0, *, floor=None):
    """Robust colour limits (percentiles of the finite values) and the colour-bar extend.

    >>> colour_limits(np.arange(101.0), 0.0, 99.0)
    (0.0, 99.0, 'max')
    """
    return limits_of(value_stats(values, [lo, hi]), lo, floor=floor)


def histogram(values, lo=None, hi=None, *, bins=80):
    """(centres, density) of the finite ``values`` on ``bins`` equal bins over [lo, hi]
    (default their range), or None if there are fewer than two values or none inside.

    The density is :func:`microfacet.core.densities.histogram_density`'s (normalised over
    the range); this adds only the display defaults.

    >>> histogram(np.array([0.5, 1.5, 1.6, 2.5]), 0.0, 3.0, bins=3)[1].tolist()
    [0.25, 0.5, 0.25]
    """
    values = finite(values)
    if values.size < 2:
        return None
    lo = float(np.min(values)) if lo is None else lo
    hi = float(np.max(values)) if hi is None else hi
    if not hi > lo:
        hi = lo + 1.0
    try:
        return histogram_density(values, bins=bins, range=(lo, hi))
    except ValueError:  # no value inside [lo, hi]
        return None


def quantile_range(x, dens, q=(0.002, 0.998)):
    """The (low, high) quantiles of a density tabulated at bin centres ``x``, or None.

    >>> quantile_range(np.arange(5.0), np.array([0, 1, 1, 1, 0]), q=(0.1, 0.9))
    (1.0, 3.0)
    """
    d = np.nan_to_num(np.asarray(dens, dtype=np.float64)).clip(0)
    if x is None or d.sum() <= 0:
        return None
    c = np.cumsum(d) / d.sum()
    return float(x[min(np.searchsorted(c, q[0]), x.size - 1)]), \
        float(x[min(np.searchsorted(c, q[1]), x.size - 1)])
