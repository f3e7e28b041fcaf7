"""Streaming state of one focus window: the running peak of the focus curve of every pixel.

Slices arrive one at a time in increasing ``z`` rank. :class:`PeakTracker` keeps, per pixel,
a fixed number of image-sized buffers whatever the number of slices:

* a ring of the last ``2r+1`` focus images (with a delay of ``r`` ranks each candidate peak
  has its ``2r+1`` neighbours known);
* the best focus value so far, its rank and the ``2r+1`` values around it;
* the running sum of the focus values and of the squared second differences along ``z``
  (the tails' level and noise, for the significance of the peak).

Memory: ``2(2r+1) + 4`` float32 buffers of the tracker's grid and a bool one, of which
one float32 and the bool are work planes that trackers of the same grid, pushed one after
another, share (``work_from``). The focus image of a rank can be computed straight into the
ring (:meth:`PeakTracker.next_slot`): :meth:`PeakTracker.push` then copies nothing.

Examples
--------
>>> import numpy as np
>>> t = PeakTracker((1, 1), radius=1, n_slices=5)
>>> for k, f in enumerate([1.0, 2.0, 5.0, 3.0, 1.0]):
...     t.push(np.full((1, 1), f, np.float32), k)
>>> t.finish()
>>> int(t.best_rank[0, 0]), t.window[:, 0, 0].tolist()
(2, [2.0, 5.0, 3.0])
"""

from __future__ import annotations

import numpy as np

from ..core.lazy import load

cv2 = load("cv2")

__all__ = ["PeakTracker"]


class PeakTracker:
    """Running arg-max of the focus curve with the ``2r+1`` values around it.

    Parameters
    ----------
    shape : (int, int)
        Grid of the focus images.
    radius : int
        ``r``: neighbours kept on each side of the best slice.
    n_slices : int
        Number of slices (sets the precision of the running sums).
    work_from : PeakTracker, optional
        A tracker of the same grid whose work planes this one shares: trackers that are
        pushed one after another (never concurrently) need one set between them.

    Attributes
    ----------
    best : ndarray of float32
        The largest focus value (after :meth:`finish`).
    best_rank : ndarray of int32
        Its z rank.
    window : ndarray of float32, shape (2r+1, H, W)
        Focus values at ranks ``best_rank - r … best_rank + r`` (NaN beyond the stack).
    fsum : ndarray
        Sum of the focus values over all slices.
    d2sum : ndarray
        Sum over all slices of the squared second difference ``F(k+1) − 2F(k) + F(k−1)``.
    """

    def __init__(self, shape, *, radius: int, n_slices: int,
                 work_from: PeakTracker | None = None):
        self.r = int(radius)
        self.k = 2 * self.r + 1
        self.n = int(n_slices)
        big = np.float64 if n_slices > 1000 else np.float32
        self.ring = np.zeros((self.k,) + tuple(shape), np.float32)
        self.window = np.full((self.k,) + tuple(shape), np.nan, np.float32)
        self.best = np.full(shape, -np.inf, np.float32)
        self.best_rank = np.zeros(shape, np.int32)
        self.fsum = np.zeros(shape, big)
        self.d2sum = np.zeros(shape, big)
        if work_from is not None and work_from._d2 is not None \
                and work_from._d2.shape == tuple(shape):
            self._d2, self._mask = work_from._d2, work_from._mask
        else:
            self._d2 = np.zeros(shape, np.float32)
            self._mask = np.empty(shape, bool)
        self._last = -1

    def next_slot(self, rank: int) -> np.ndarray:
        """The ring buffer (float32, the tracker's grid) that the focus image of z rank
        ``rank`` may be computed into before it is pushed (the rank ``2r+1`` before it, which
        it replaces, is no longer read): :meth:`push` of that buffer copies nothing."""
        return self.ring[int(rank) % self.k]

    def push(self, f: np.ndarray, rank: int) -> None:
        """Add the focus image of z rank ``rank`` (ranks 0, 1, 2, … in order)."""
        k = self.k
        slot = self.ring[rank % k]
        if not _same_buffer(f, slot):
            np.copyto(slot, f)
        self.fsum += f
        if rank >= 2:
            d2 = self._d2
            cv2.addWeighted(self.ring[rank % k], 1.0, self.ring[(rank - 1) % k], -2.0, 0.0,
                            dst=d2)
            cv2.add(d2, self.ring[(rank - 2) % k], dst=d2)
            if self.d2sum.dtype == np.float32:
                cv2.accumulateSquare(d2, self.d2sum)
            else:
                self.d2sum += np.square(d2, dtype=np.float64)
        self._last = rank
        c = rank - self.r
        if c >= 0:
            self._take(c, rank)

    def finish(self) -> None:
        """Take the last candidates (call once after the last slice)."""
        last = self._last
        for c in range(max(0, last - self.r + 1), last + 1):
            self._take(c, last)

    def _take(self, c, last):
        """Candidate rank c: its window ranks c-r..c+r are all known (or beyond the end)."""
        ring, k, r = self.ring, self.k, self.r
        np.greater(ring[c % k], self.best, out=self._mask)
        if not self._mask.any():
            return
        m8 = self._mask.view(np.uint8)                  # 0/1, an OpenCV mask (no copy)
        cv2.max(ring[c % k], self.best, dst=self.best)
        np.copyto(self.best_rank, c, where=self._mask)
        for j in range(k):
            rk = c - r + j
            if 0 <= rk <= last:
                cv2.copyTo(ring[rk % k], m8, self.window[j])
            else:                                       # beyond the stack (its first or
                np.copyto(self.window[j], np.nan, where=self._mask)     # last r ranks)

    def release_ring(self) -> None:
        """Free the ring and the scan's work arrays (after :meth:`finish`)."""
        self.ring = None
        self._d2 = self._mask = None

    def release_curves(self) -> None:
        """Free what only the peak fit reads — ``window``, ``fsum``, ``d2sum`` — once it has
        read them; ``best`` and ``best_rank`` stay."""
        self.window = self.fsum = self.d2sum = None


def _same_buffer(a, b) -> bool:
    """Whether ``a`` is the array ``b`` (the same memory, shape, strides and type)."""
    return (isinstance(a, np.ndarray) and a.dtype == b.dtype and a.shape == b.shape
            and a.strides == b.strides
            and a.__array_interface__["data"][0] == b.__array_interface__["data"][0])
