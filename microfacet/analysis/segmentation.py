"""Facets from colour and height edges: over-segment, then merge what the data cannot tell apart.

The seed observed (§3.3.2, Fig. 17) that one colour in the microscope image is one flat
facet. A facet is found in two steps, both driven by the measured noise rather than by a
tuned scale:

1. **Over-segmentation.** Felzenszwalb's graph segmentation of the Lab image (in units of
   its noise), in the regime where its threshold is far below the noise, so that it only
   grows regions along the weakest edges until each reaches ``min_size`` (a quarter of a
   facet's area): the blobs stop at real colour edges but are smaller than facets. Where
   the heights are precise enough to show a facet edge pixel by pixel (slope noise below
   :data:`MAX_SLOPE_NOISE`: exports, not focus) their slopes are added as channels.
2. **Statistical merging.** Neighbouring blobs are merged, mutual best pairs first, while
   (a) their mean colours differ by less than the colour noise allows (χ² with 3 degrees of
   freedom on the Lab means, ``p > alpha``) and (b) one plane fits the heights of both
   as well as two planes do (the extra residual, in units of the per-pixel height variance,
   is χ² with 3 degrees of freedom), and (c) the union is no larger than ``max_area_factor``
   facet areas. Where the heights are unknown (NaN) test (b) has no power and colour alone
   decides; where neither colour nor height shows an edge the segments stop at the area cap,
   an arbitrary but facet-sized partition.

The sufficient statistics of a weighted plane fit are sums (:func:`plane_moments`), so the
test of a merge costs one 3×3 solve per neighbour pair, vectorised over all pairs.

References
----------
.. [1] N. Nagata, M. Kamei, K. Takahashi, K. Tobitani, T. Akagi, S. Yamamura, "Simulation
   Technology for Titanium Oxide Layer Interference Color", Technical Report (the seed paper),
   §3.3.2 and Fig. 17 (one colour, one flat facet).
.. [2] P. F. Felzenszwalb, D. P. Huttenlocher, "Efficient graph-based image segmentation", Int.
   J. Comput. Vision 59(2) (2004) 167-181, doi:10.1023/B:VISI.0000022288.19776.77.
"""

from __future__ import annotations

import math
import warnings

import numpy as np

from ..core.lazy import load
from ..core.pixels import pixel_size_yx
from ..core.threads import BLOCK_VALUES, chunks, row_chunks, thread_map
from .options import JointOptions

measure = load("skimage.measure")
segmentation = load("skimage.segmentation")
# scipy.special, not scipy.stats (0.19 s more to import) for a χ² quantile
special = load("scipy.special")

__all__ = ["merge_adjacent", "segment_facets"]

#: Grey used for the segmentation where the Lab image is NaN.
_NAN_LAB = (50.0, 0.0, 0.0)


def plane_moments(labels, height_um, weight, *, pixel_size_um, n_labels=None) -> np.ndarray:
    """Weighted sums per label for a least-squares plane ``z = a x + b y + c``.

    Parameters
    ----------
    labels : ndarray of int, shape (H, W)
        Labels 0..S-1.
    height_um : ndarray, shape (H, W)
        Height (µm; NaN = no height, weight 0).
    weight : ndarray, shape (H, W)
        Non-negative weights (1/σ² for a χ²-scaled residual).
    pixel_size_um : float or (float, float)
        x = columns, y = rows, both in µm, centred on the image; ``(y, x)`` for non-square
        pixels.
    n_labels : int, optional
        S (default ``labels.max() + 1``).

    Returns
    -------
    ndarray, shape (S, 10)
        ``Σw, Σwx, Σwy, Σwz, Σwxx, Σwxy, Σwyy, Σwxz, Σwyz, Σwzz``; sums of several labels
        are the moments of their union.
    """
    h, w = labels.shape
    S = int(labels.max()) + 1 if n_labels is None else int(n_labels)
    py, px = pixel_size_yx(pixel_size_um)
    flat = labels.ravel()
    z_all, wt_all = (np.broadcast_to(np.asarray(v), labels.shape).ravel()
                     for v in (height_um, weight))
    out = np.zeros((S, 10))

    def group(g):
        lo, hi, a, b = g
        sel = np.arange(a, b)[(flat[a:b] >= lo) & (flat[a:b] < hi)]
        lab = flat[sel] - lo
        z = z_all[sel].astype(np.float64)
        finite = np.isfinite(z)
        wt = np.where(finite, wt_all[sel].astype(np.float64), 0.0)
        z = np.where(finite, z, 0.0)
        rows, cols = np.divmod(sel, w)
        x = (cols - (w - 1) / 2.0) * px
        y = (rows - (h - 1) / 2.0) * py
        wz = wt * z
        terms = ((wt, None), (wt, x), (wt, y), (wz, None), (wt, x * x), (wt, x * y),
                 (wt, y * y), (wz, x), (wz, y), (wz, z))
        for c, (u, v) in enumerate(terms):
            out[lo:hi, c] = np.bincount(lab, weights=u if v is None else u * v,
                                        minlength=hi - lo)

    # a group of whole labels at a time on the threads: each label's sums over its pixels
    # in image order, as over the whole image
    thread_map(group, label_groups(labels, None, S, BLOCK_VALUES))
    return out


def label_groups(labels, idx, S, size):
    """Groups of whole labels, each a task of about ``size`` pixels: ``(lo, hi, a, b)``,
    labels ``lo..hi-1``, whose pixels among ``idx`` (flat indices, ascending; None: all
    pixels) all lie in ``idx[a:b]`` (in flat indices ``a..b-1`` for all pixels): the rows
    whose label range meets the group's. Labels numbered in raster order, as the
    segmentation's are, make that a band of the image, so that finding a group's pixels
    does not read the whole image."""
    h, w = labels.shape
    n = np.bincount(labels.ravel() if idx is None else labels.ravel()[idx], minlength=S)
    row_lo, row_hi = labels.min(axis=1), labels.max(axis=1)
    end = np.cumsum(n)
    cuts = [0]
    while cuts[-1] < S:
        base = end[cuts[-1] - 1] if cuts[-1] else 0
        nxt = int(np.searchsorted(end, base + size, side="right"))
        cuts.append(min(S, max(nxt, cuts[-1] + 1)))
    groups = []
    for lo, hi in zip(cuts[:-1], cuts[1:]):
        rows = np.flatnonzero((row_lo < hi) & (row_hi >= lo))
        if rows.size == 0:
            continue
        a, b = int(rows[0]) * w, (int(rows[-1]) + 1) * w
        if idx is not None:
            a, b = int(np.searchsorted(idx, a)), int(np.searchsorted(idx, b))
        groups.append((lo, hi, a, b))
    return groups


def plane_from_moments(m):
    """The weighted least-squares plane of :func:`plane_moments` rows.

    Returns
    -------
    a, b : ndarray
        dz/dx and dz/dy (NaN where the points do not determine a plane).
    rss : ndarray
        Weighted residual sum of squares (0 where undetermined).
    cov_ab : ndarray, shape (..., 2, 2)
        ``inv(C)``: the covariance of (a, b) per unit residual variance (with weights 1/σ²
        it is the covariance itself).
    """
    m = np.asarray(m, dtype=np.float64)
    sw, sx, sy, sz, sxx, sxy, syy, sxz, syz, szz = np.moveaxis(m, -1, 0)
    with np.errstate(invalid="ignore", divide="ignore"):
        mx, my, mz = sx / sw, sy / sw, sz / sw
        cxx = sxx - sw * mx * mx
        cxy = sxy - sw * mx * my
        cyy = syy - sw * my * my
        cxz = sxz - sw * mx * mz
        cyz = syz - sw * my * mz
        czz = szz - sw * mz * mz
        det = cxx * cyy - cxy * cxy
        ok = (sw > 0) & (det > 1e-9 * np.maximum(cxx * cyy, 1e-300)) & (det > 0)
        a = np.where(ok, (cyy * cxz - cxy * cyz) / det, np.nan)
        b = np.where(ok, (cxx * cyz - cxy * cxz) / det, np.nan)
        rss = np.where(ok, np.maximum(czz - a * cxz - b * cyz, 0.0),
                       np.where(sw > 0, np.maximum(czz, 0.0), 0.0))
        cov = np.stack([np.stack([cyy, -cxy], -1), np.stack([-cxy, cxx], -1)], -2)
        cov = np.where(ok[..., None, None], cov / det[..., None, None], np.nan)
    return a, b, rss, cov


def neighbour_pairs(labels):
    """Unique neighbouring label pairs (i < j), 4-connectivity, sorted by (i, j).

    A block of rows at a time (with the row below it for the vertical pairs), each block's
    pairs made unique before the next: the memory of a block's boundary pixels and of the
    pairs, not of every boundary pixel of the image (~25 bytes a pixel at 4 MP).

    >>> neighbour_pairs(np.array([[0, 0, 1], [2, 2, 1]])).tolist()
    [[0, 1], [0, 2], [1, 2]]
    """
    labels = np.asarray(labels)
    if labels.size == 0:
        return np.zeros((0, 2), np.int64)
    h, w = labels.shape
    n = int(labels.max()) + 1
    keys = []
    for a, b in row_chunks(labels.shape):
        blk = labels[a:min(h, b + 1)]
        for x, y in ((blk[:b - a, :-1], blk[:b - a, 1:]), (blk[:-1, :], blk[1:, :])):
            differ = x != y                        # compress first: boundaries are few
            if differ.any():
                keys.append(_sorted_unique(_pair_keys(x[differ], y[differ], n)))
    if not keys:
        return np.zeros((0, 2), np.int64)
    key = _sorted_unique(np.concatenate(keys))
    return np.stack([key // n, key % n], axis=1)


def _pair_keys(a, b, n):
    """``min(a, b) · n + max(a, b)`` as int64: one key per unordered pair."""
    a, b = a.astype(np.int64), b.astype(np.int64)
    lo = np.minimum(a, b)
    np.maximum(a, b, out=b)
    lo *= n
    lo += b
    return lo


def _sorted_unique(key):
    """The distinct values of ``key``, sorted (one sort; numpy 2.4's ``np.unique`` hashes)."""
    key = np.sort(key)
    return key[np.concatenate(([True], key[1:] != key[:-1]))]


def _unique_pairs(a, b):
    """Unique unordered pairs of non-negative ints as rows (i < j) sorted by (i, j): one
    1-D sort of ``i * n + j`` keys (``np.unique(axis=0)`` sorts rows ~20× slower, and
    numpy 2.4's ``np.unique`` of the keys, which hashes them, 15-60× slower than the sort on
    2·10⁵-2·10⁶ keys: 0.97 s of the segmentation at 4 MP)."""
    if a.size == 0:
        return np.zeros((0, 2), np.int64)
    n = int(np.maximum(a, b).max()) + 1
    key = _sorted_unique(_pair_keys(np.asarray(a), np.asarray(b), n))
    return np.stack([key // n, key % n], axis=1)


#: Per-pixel slope noise below which the height map's slopes help draw facet edges: facets
#: differ in slope by a few degrees (0.05 ≈ 3°). Heights from focus (σ ~ 0.05-0.1 µm at
#: 0.2 µm pixels: slope noise ~ 0.5) never qualify; precise exports do.
MAX_SLOPE_NOISE = 0.05


def _precise_slopes(height_um, height_sigma_um, pixel_size_um):
    """Slope channels in units of their noise, or None where the heights are too noisy."""
    if height_um is None or height_sigma_um is None:
        return None
    h = np.asarray(height_um)
    sg = np.asarray(height_sigma_um)
    ok = np.isfinite(h) & np.isfinite(sg)
    if ok.mean() < 0.5:
        return None
    py, px = pixel_size_yx(pixel_size_um)
    # decided before any float64 copy of the maps (heights from focus never qualify)
    s_slope = math.sqrt(2.0) * float(np.median(sg[ok].astype(np.float64))) / np.array([px, py])
    if not np.all((s_slope > 0) & (s_slope <= MAX_SLOPE_NOISE)):
        return None
    h = h.astype(np.float64)
    hf = np.where(ok, h, float(np.median(h[ok])))
    gy, gx = np.gradient(hf, py, px)
    return np.stack([np.where(ok, gx, 0.0), np.where(ok, gy, 0.0)], axis=-1) / s_slope


#: Side of the tiles Felzenszwalb runs on (pixels): its graph costs a few hundred bytes per
#: pixel, so a tile bounds that memory whatever the image size. The tile edges are blob edges
#: too; the statistical merging that follows joins blobs across them like any other pair.
#: On the 1-megapixel nd stack of the speed-analyze study, 512-px tiles against one
#: whole-image tile (``python -m pipelines run speed-memory``): peak
#: memory of the analysis 518 vs 739 MB, 0.2 % more facets, thickness MAE 0.652 vs 0.661 nm,
#: tilt W1 1.637° vs 1.639° against the truth. 256-px tiles against 512 (2026-11-28, the same
#: study): a fifth of the graph's memory (about 20 against 80-100 MB at the segmentation's and
#: the self-check's peaks); at 1 MP 0.5 % more facets, MAE 0.671 vs 0.652 nm, W1 1.628° vs
#: 1.626°; at 4 MP 0.4 % more facets, MAE 1.065 vs 1.078 nm, W1 1.471° vs 1.467°. Images of
#: at most 256 px a side (the sweep's, the bundled fixture) are one tile either way.
FELZENSZWALB_TILE_PX = 256


def _felzenszwalb_tiles(img, scale, slope, *, min_size, tile=None):
    """Blobs: skimage's Felzenszwalb (scale 1e-3, σ 0.5) on ``img · scale`` (and the
    ``slope`` channels, if any), tile by tile, each blob split into its 4-connected pieces
    (Felzenszwalb's may touch only diagonally). Labels 0..S-1 (int32), numbered tile by
    tile in raster order; channels are built per tile, never for the whole image. The tiles
    run on :func:`~microfacet.core.threads.thread_map`'s threads (skimage's graph releases
    the GIL): each thread holds one tile's graph, ~20 MB at 256 px."""
    h, w = img.shape[:2]
    tile = FELZENSZWALB_TILE_PX if tile is None else int(tile)
    tiles = [(slice(r0, r0 + tile), slice(c0, c0 + tile))
             for r0 in range(0, h, tile) for c0 in range(0, w, tile)]

    def blobs(sl):
        part = img[sl] * np.float32(scale)
        if slope is not None:
            part = np.concatenate([part, slope[sl].astype(np.float32)], axis=-1)
        b = segmentation.felzenszwalb(part, scale=1e-3, sigma=0.5, min_size=min_size,
                                      channel_axis=-1)
        return measure.label(b + 1, connectivity=1, background=0).astype(np.int32)  # 1..n

    with warnings.catch_warnings():   # skimage warns about more than 4 channels; the
        warnings.filterwarnings("ignore", message=".*third dimension.*")  # filters are global
        found = thread_map(blobs, tiles)
    out = np.empty((h, w), np.int32)
    offset = 0
    for sl, pieces in zip(tiles, found):
        out[sl] = pieces - 1 + offset
        offset += int(pieces.max())
    return out


def _first_pairs(pi, pj, score, S):
    """Which of the pairs to merge: exact ties could put a segment in two pairs; in the
    order of ``score`` (stable), a pair is kept unless one of its segments is in a pair
    kept before it. Only the pairs sharing a segment are walked one by one."""
    times = np.bincount(pi, minlength=S) + np.bincount(pj, minlength=S)
    shared = (times[pi] > 1) | (times[pj] > 1)
    keep = ~shared
    used = np.zeros(S, bool)
    k_shared = np.flatnonzero(shared)
    for k in k_shared[np.argsort(score[k_shared], kind="stable")]:
        if not used[pi[k]] and not used[pj[k]]:
            used[pi[k]] = used[pj[k]] = True
            keep[k] = True
    return keep


def relabel(labels):
    """Labels renumbered 0..S-1 in the order of their values (int32)."""
    _, inv = np.unique(labels, return_inverse=True)
    return inv.reshape(labels.shape).astype(np.int32)


def segment_facets(lab, *, facet_px, noise_de=None, height_um=None, height_sigma_um=None,
                   pixel_size_um=1.0, options=None):
    """Segment a Lab image into facets that follow colour and height edges.

    Parameters
    ----------
    lab : ndarray, shape (H, W, 3)
        CIELAB image (NaN allowed: segmented as mid grey).
    facet_px : float
        Expected mean facet diameter in pixels (sets the smallest segment, a quarter of a
        facet's area, and the largest, ``max_area_factor`` facet areas).
    noise_de : float, optional
        Colour noise per Lab component (ΔE units). Default: estimated from the differences
        of horizontal neighbours (median absolute deviation).
    height_um, height_sigma_um : ndarray, shape (H, W), optional
        Height and its 1-σ error per pixel (NaN = no height there). Without them segments
        are merged on colour alone.
    pixel_size_um : float or (float, float)
        Lateral pixel size, ``(y, x)`` for non-square pixels (only the ratio to the height
        units matters).
    options : JointOptions, optional
        ``merge_alpha`` (significance of the merge tests: a true edge is kept when its colour
        or plane difference would arise by chance with a smaller probability),
        ``max_area_factor`` (largest segment, in facet areas π/4 · facet_px²) and
        ``merge_rounds`` (each merges mutual best pairs).

    Returns
    -------
    ndarray of int32, shape (H, W)
        Labels 0..S-1, each segment 4-connected.

    Examples
    --------
    >>> yy, xx = np.mgrid[0:40, 0:60]
    >>> lab = np.where((xx < 25)[..., None], [50.0, 30, 0], [50.0, -30, 0])
    >>> labels = segment_facets(lab, facet_px=12, noise_de=1.0)
    >>> bool(np.all(labels[:, 24:25] != labels[:, 25:26]))
    True
    """
    lab = np.asarray(lab)
    if lab.ndim != 3 or lab.shape[-1] != 3:
        raise ValueError(f"lab: expected an (H, W, 3) image, got shape {lab.shape}")
    facet_px = float(facet_px)
    if not (math.isfinite(facet_px) and facet_px > 0):
        raise ValueError(f"facet_px: must be finite and > 0, got {facet_px!r}")
    options = JointOptions() if options is None else options
    # float32 (the analysis' Lab is float32 already): half the memory of float64
    img = np.where(np.isfinite(lab), lab, np.array(_NAN_LAB, np.float32)).astype(
        np.float32, copy=False)
    h, w = img.shape[:2]
    area = math.pi / 4.0 * max(facet_px, 2.0) ** 2
    if noise_de is None or not np.isfinite(noise_de) or noise_de <= 0:
        d = np.diff(img.astype(np.float64), axis=1).reshape(-1, 3)
        mad = np.median(np.abs(d - np.median(d, axis=0)), axis=0)
        noise_de = max(float(np.mean(mad)) * 1.4826 / math.sqrt(2.0), 0.05)
    # 1. blobs: Felzenszwalb with a colour threshold far below the noise (skimage divides
    #    ``scale`` by 255), so that regions grow along the weakest edges to ``min_size``;
    #    heights precise enough to show facet edges pixel by pixel add their slopes
    slope = _precise_slopes(height_um, height_sigma_um, pixel_size_um)
    min_size = max(2, int(round(area / 4.0)))
    labels = _felzenszwalb_tiles(img, 1.0 / noise_de, slope, min_size=min_size)
    del slope
    # 2. statistical merging
    S = int(labels.max()) + 1
    flat = labels.ravel()
    colour = np.stack([np.bincount(flat, minlength=S).astype(np.float64)]
                      + [np.bincount(flat, weights=img[..., c].ravel(), minlength=S)
                         for c in range(3)], axis=1)
    if height_um is not None:
        sig = np.ones((h, w)) if height_sigma_um is None else np.asarray(height_sigma_um)
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            wt = np.square(sig, dtype=np.float64)  # 1/σ² in place: one (H, W) float64
            np.divide(1.0, wt, out=wt)
        wt[~(np.isfinite(sig) & (sig > 0))] = 0.0
        del sig
        planes = plane_moments(labels, height_um, wt, pixel_size_um=pixel_size_um,
                               n_labels=S)
    else:
        planes = np.zeros((S, 10))
    thr = float(special.chdtri(3, options.merge_alpha))   # scipy.stats.chi2.isf, to the bit
    max_area = options.max_area_factor * area

    def colour_stat(ci, cj):
        ni, nj = ci[:, 0], cj[:, 0]
        diff = ci[:, 1:] / ni[:, None] - cj[:, 1:] / nj[:, None]
        return np.sum(diff * diff, axis=1) / (noise_de ** 2 * (1.0 / ni + 1.0 / nj))

    def absorb(mi, mj):   # pieces cut off by the 4-connectivity split join a neighbour
        small = (mi[:, 0] < min_size / 2.0) | (mj[:, 0] < min_size / 2.0)
        return small, colour_stat(mi[:, :4], mj[:, :4])

    def cost(mi, mj):
        dc = colour_stat(mi[:, :4], mj[:, :4])
        _, _, rss_i, _ = plane_from_moments(mi[:, 4:])
        _, _, rss_j, _ = plane_from_moments(mj[:, 4:])
        au, _, rss_u, _ = plane_from_moments(mi[:, 4:] + mj[:, 4:])
        dp = np.where(np.isfinite(au), np.maximum(rss_u - rss_i - rss_j, 0.0), 0.0)
        ok = (dc < thr) & (dp < thr) & (mi[:, 0] + mj[:, 0] <= max_area)
        return ok, dc + dp

    moments = np.concatenate([colour, planes], axis=1)
    labels, moments = merge_adjacent(labels, moments, absorb, max_rounds=options.merge_rounds)
    labels, _ = merge_adjacent(labels, moments, cost, max_rounds=options.merge_rounds)
    return labels


def merge_adjacent(labels, moments, cost, *, max_rounds, pairs=None):
    """Merge neighbouring segments, mutual best pairs first, while ``cost`` allows.

    Parameters
    ----------
    labels : ndarray of int, shape (H, W)
        Segments 0..S-1.
    moments : ndarray, shape (S, m)
        Additive statistics per segment (those of a union are the sums).
    cost : callable
        ``cost(moments_i, moments_j) -> (ok, score)`` for arrays of neighbour pairs: whether
        the pair may merge and how well it fits (lower is better).
    max_rounds : int
        Each round merges every pair that is the other's best candidate.
    pairs : ndarray of int, shape (P, 2), optional
        :func:`neighbour_pairs` of ``labels``, when the caller has them already.

    Returns
    -------
    labels : ndarray of int32, shape (H, W)
    moments : ndarray, shape (S', m)
    """
    S = int(labels.max()) + 1
    if not np.all(_label_counts(labels, S)):                   # labels 0..S-1 with gaps
        labels = relabel(labels)
        S, pairs = int(labels.max()) + 1, None
    moments = np.asarray(moments, dtype=np.float64)
    # the segment graph: merged segments neighbour the union of their parts' neighbours, so
    # the pixels are read once and each round works on the (small) list of edges
    pairs = neighbour_pairs(labels) if pairs is None else np.asarray(pairs, np.int64)
    mapping = np.arange(S)
    for _ in range(max_rounds):
        if pairs.size == 0:
            break
        i, j = pairs[:, 0], pairs[:, 1]
        ok, score = np.empty(i.size, bool), np.empty(i.size)
        # the pairs' moments a chunk of pairs at a time (2 × 8 bytes × m per pair at once
        # were ~100 MB at 4 MP); the cost is per pair, so the same numbers
        for a, b in chunks(i.size, BLOCK_VALUES // max(1, moments.shape[1])):
            ok[a:b], score[a:b] = cost(moments[i[a:b]], moments[j[a:b]])
        if not ok.any():
            break
        score = np.where(ok, score, np.inf)
        best = np.full(S, np.inf)
        np.minimum.at(best, i, score)
        np.minimum.at(best, j, score)
        pick = ok & (score == best[i]) & (score == best[j])
        pi, pj = i[pick], j[pick]
        keep = _first_pairs(pi, pj, score[pick], S)
        pi, pj = pi[keep], pj[keep]
        if pi.size == 0:
            break
        parent = np.arange(S)
        parent[pj] = pi
        _, new = np.unique(parent, return_inverse=True)
        S = int(new.max()) + 1
        moments = np.stack([np.bincount(new, weights=moments[:, c], minlength=S)
                            for c in range(moments.shape[1])], axis=1)
        mapping = new[mapping]
        a, b = new[i], new[j]
        differ = a != b
        pairs = _unique_pairs(a[differ], b[differ])
    return _mapped(mapping.astype(np.int32), labels), moments


def _label_counts(labels, S):
    """``np.bincount(labels.ravel(), minlength=S)``, a block of rows at a time (bincount
    converts its input to intp: 8 bytes a pixel for the whole image at once)."""
    counts = np.zeros(S, np.int64)
    for a, b in row_chunks(labels.shape):
        counts += np.bincount(labels[a:b].ravel(), minlength=S)
    return counts


def _mapped(mapping, labels):
    """``mapping[labels]`` a block of rows at a time (the index converted to intp a block's
    worth at a time)."""
    out = np.empty(labels.shape, mapping.dtype)
    for a, b in row_chunks(labels.shape):
        out[a:b] = mapping[labels[a:b]]
    return out
