"""Registration of focus-stack slices that drift or change magnification.

Used by :func:`~microfacet.focus.height.height_from_focus`
with ``align=...``. One extra streaming pass
over the stack in ``z`` order estimates the warp between *neighbouring* slices (neighbours have
similar defocus, so intensity-based registration is reliable) on copies downscaled to at most
``max_side`` pixels, and composes them. Only the previous downscaled slice is kept, so memory
does not grow with the number of slices.

Methods
-------
``"ecc"``
    OpenCV's enhanced-correlation-coefficient maximisation (Evangelidis & Psarakis 2008) with
    an affine motion model: drift, magnification change (lens refocus), small rotation/shear.
``"phase"``
    Phase correlation: translation only (stage drift).

The reference frame is the slice whose field of view is covered by the most other slices
(for a lens that zooms while focusing, the most magnified slice), unless given. Every slice
is then warped into that frame (bilinear, border replicated).

References
----------
.. [1] N. Nagata, M. Kamei, K. Takahashi, K. Tobitani, T. Akagi, S. Yamamura, "Simulation
   Technology for Titanium Oxide Layer Interference Color", Technical Report (the seed paper),
   §3.3.2 (the focus stack of the optical microscope).
.. [2] G. D. Evangelidis, E. Z. Psarakis, "Parametric image alignment using enhanced correlation
   coefficient maximization", IEEE Trans. Pattern Anal. Mach. Intell. 30(10) (2008) 1858-1865,
   doi:10.1109/TPAMI.2008.113.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Sequence

import numpy as np

from ..core.errors import InputError
from ..core.lazy import load
from .measures import to_grey

cv2 = load("cv2")

__all__ = ["estimate_warps", "warped_loader"]

log = logging.getLogger(__name__)


def _small_grey(img: np.ndarray, scale: float) -> np.ndarray:
    g = to_grey(img)
    if scale != 1.0:
        g = cv2.resize(g, None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA)
    return g


def _pair_warp(prev: np.ndarray, cur: np.ndarray, method: str) -> np.ndarray:
    """3×3 matrix mapping prev pixel coordinates to cur pixel coordinates."""
    W = np.eye(3, dtype=np.float64)
    if method == "phase":
        win = cv2.createHanningWindow(prev.shape[::-1], cv2.CV_32F)
        (dx, dy), _ = cv2.phaseCorrelate(prev, cur, win)
        W[0, 2], W[1, 2] = dx, dy
        return W
    warp = np.eye(2, 3, dtype=np.float32)
    crit = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 200, 1e-6)
    try:
        _, warp = cv2.findTransformECC(prev, cur, warp, cv2.MOTION_AFFINE, crit, None, 5)
    except cv2.error as exc:
        log.warning("ECC did not converge (%s); assuming no motion between neighbours", exc)
        warp = np.eye(2, 3, dtype=np.float32)
    W[:2] = warp
    return W


def estimate_warps(load: Callable[[int], np.ndarray], order: Sequence[int], shape,
                   *, method: str = "ecc", reference: int | None = None,
                   max_side: int = 640):
    """Estimate the warp of every slice into a reference slice's frame.

    Parameters
    ----------
    load : callable(file_index) -> ndarray
        Decodes one slice, (H, W) or (H, W, 3) float.
    order : sequence of int
        File indices in increasing ``z`` (neighbours in this order are registered pairwise).
    shape : (H, W)
        Image size.
    method : {"ecc", "phase"}
    reference : int, optional
        File index of the reference slice; default: the slice covered by most others.
    max_side : int
        Registration runs on copies downscaled to at most this many pixels per side.

    Returns
    -------
    warps : list of ndarray, shape (2, 3), float32, indexed by file index
        Maps reference-frame pixel coordinates to the slice's pixel coordinates (the
        ``WARP_INVERSE_MAP`` convention of ``cv2.warpAffine``).
    reference : int
        The reference's file index.
    """
    if method not in ("ecc", "phase"):
        raise ValueError(f"align method must be 'ecc' or 'phase', not {method!r}")
    H, W = shape
    order = [int(i) for i in order]
    n = len(order)
    if reference is not None and reference not in order:
        raise InputError(f"alignment reference {reference} is not a slice index (0..{n - 1})")
    scale = min(1.0, max_side / max(H, W))
    S = np.diag([scale, scale, 1.0])
    Si = np.diag([1 / scale, 1 / scale, 1.0])
    M = {order[0]: np.eye(3)}            # rank-0 frame -> slice frame (full resolution)
    prev = _small_grey(load(order[0]), scale)
    for k in range(1, n):
        cur = _small_grey(load(order[k]), scale)
        Wsmall = _pair_warp(prev, cur, method)
        M[order[k]] = (Si @ Wsmall @ S) @ M[order[k - 1]]
        prev = cur
    if reference is None:
        # sample the frame of each candidate; count points inside every slice
        gy, gx = np.mgrid[0:H:complex(0, 24), 0:W:complex(0, 24)]
        pts = np.stack([gx.ravel(), gy.ravel(), np.ones(gx.size)])
        best, best_cov = order[n // 2], -1.0
        for r in sorted(order, key=lambda i: abs(order.index(i) - n // 2)):
            Mr_inv = np.linalg.inv(M[r])
            inside = np.ones(pts.shape[1], bool)
            for i in order:
                q = (M[i] @ Mr_inv) @ pts
                inside &= (q[0] >= -0.5) & (q[0] <= W - 0.5) & (q[1] >= -0.5) & (q[1] <= H - 0.5)
            cov = inside.mean()
            if cov > best_cov + 1e-9:
                best, best_cov = r, cov
        reference = best
        log.info("alignment reference: slice %d (%.0f%% of its field in every slice)",
                 reference, 100 * best_cov)
    Mr_inv = np.linalg.inv(M[reference])
    warps = [None] * n
    for i in order:
        warps[i] = (M[i] @ Mr_inv)[:2].astype(np.float32)
    return warps, reference


def warp_to_reference(img: np.ndarray, warp: np.ndarray) -> np.ndarray:
    """Warp one slice into the reference frame.

    Parameters
    ----------
    img : ndarray, shape (H, W) or (H, W, 3)
    warp : ndarray, shape (2, 3)
        Reference coordinates -> slice coordinates, from :func:`estimate_warps`.

    Returns
    -------
    ndarray, same shape and dtype as ``img``
    """
    H, W = img.shape[:2]
    return cv2.warpAffine(img, warp, (W, H), flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
                          borderMode=cv2.BORDER_REPLICATE)


def warped_loader(load: Callable[[int], np.ndarray], warps, shape):
    """Wrap a slice loader so that it returns slices warped into the reference frame."""

    def load_warped(i):
        return warp_to_reference(load(i), warps[i])

    return load_warped
