"""Filling the holes (unreliable pixels) of a height map."""

from __future__ import annotations

import numpy as np

from ..core.lazy import load

cv2 = load("cv2")
ndimage = load("scipy.ndimage")

__all__ = ["fill_missing"]


def fill_missing(height: np.ndarray, *, method: str = "smooth") -> np.ndarray:
    """Fill NaN pixels of a height map.

    Parameters
    ----------
    height : ndarray, shape (H, W)
        Height map with NaN holes.
    method : {"smooth", "nearest"}
        ``"nearest"``: value of the nearest valid pixel. ``"smooth"``: normalised convolution
        with a Gaussian whose σ doubles (from 2 px) until every hole is covered, each hole
        taking the value from the smallest σ that reaches it.

    Returns
    -------
    ndarray of float32, shape (H, W)
        Valid pixels unchanged; all NaN only if the input has no valid pixel.
    """
    h = np.asarray(height, dtype=np.float32)
    miss = ~np.isfinite(h)
    if not miss.any() or miss.all():
        return h.copy()
    if method == "nearest":
        idx = ndimage.distance_transform_edt(miss, return_distances=False, return_indices=True)
        return h[idx[0], idx[1]]
    if method != "smooth":
        raise ValueError(f"method must be 'smooth' or 'nearest', not {method!r}")
    out = h.copy()
    todo = miss.copy()
    m = (~miss).astype(np.float32)
    hv = np.where(miss, 0.0, h).astype(np.float32)
    sigma = 2.0
    while todo.any():
        if sigma > 4 * max(h.shape):
            near = fill_missing(h, method="nearest")
            out[todo] = near[todo]
            break
        num = cv2.GaussianBlur(hv, (0, 0), sigma, borderType=cv2.BORDER_REFLECT)
        den = cv2.GaussianBlur(m, (0, 0), sigma, borderType=cv2.BORDER_REFLECT)
        reach = todo & (den > 1e-3)
        out[reach] = num[reach] / den[reach]
        todo &= ~reach
        sigma *= 2.0
    return out
