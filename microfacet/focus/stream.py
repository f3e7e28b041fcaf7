"""Streaming state of one focus window: the running peak of the focus curve of every pixel.

Slices arrive one at a time in increasing ``z`` rank. :class:`PeakTracker` keeps, per pixel,
a fixed number of image-sized buffers whatever the number of slices:

* a ring of the last ``max(r, 2) + 1`` focus images (the ``r`` before a new best value and the
  three of a second difference);
* the best focus value so far, its rank and the ``2r+1`` values around it: the ``r + 1`` up to
  it copied from the ring when it is found, the ``r`` after it filled in as they arrive (NaN
  beyond the stack);
* the running sum of the focus values and of the squared second differences along ``z``
  (the tails' level and noise, for the significance of the peak).

Memory: ``(2r+1) + max(r, 2) + 3.5`` float32 buffers of the tracker's grid and a bool one
(10.5 at r = 2: the best value is the window's middle row and its rank an int16; 12 with
planes of their own for both, 14 with a ring of ``2r+1``), of which
one float32 and the bool are work planes that trackers of the same grid, pushed one after
another, share (``work_from``). The focus image of a rank can be computed straight into the
ring (:meth:`PeakTracker.next_slot`): :meth:`PeakTracker.push` then copies nothing.

Examples
--------
>>> import numpy as np
>>> t = PeakTracker((1, 1), radius=1, n_slices=5)
>>> for k, f in enumerate([1.0, 2.0, 5.0, 3.0, 1.0]):
...     t.push(np.full((1, 1), f, np.float32), k)
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
        The largest focus value so far (-inf before any): the window's middle row, a view.
    best_rank : ndarray of int16 (int32 beyond 32768 slices)
        Its z rank.
    window : ndarray of float32, shape (2r+1, H, W)
        Focus values at ranks ``best_rank - r … best_rank + r`` (NaN beyond the stack; those
        after the best rank as far as pushed; the middle row -inf where no slice had a
        finite value).
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
        self.ring = np.zeros((max(self.r, 2) + 1,) + tuple(shape), np.float32)
        self.window = np.full((self.k,) + tuple(shape), np.nan, np.float32)
        # the best value is the window's middle row (no plane of its own): -inf until a
        # slice beats it
        self.best = self.window[self.r]
        self.best.fill(-np.inf)
        self.best_rank = np.zeros(shape, np.int16 if self.n <= np.iinfo(np.int16).max + 1
                                  else np.int32)
        self.fsum = np.zeros(shape, big)
        self.d2sum = np.zeros(shape, big)
        if work_from is not None and work_from._d2 is not None \
                and work_from._d2.shape == tuple(shape):
            self._d2, self._mask = work_from._d2, work_from._mask
        else:
            self._d2 = np.zeros(shape, np.float32)
            self._mask = np.empty(shape, bool)

    def next_slot(self, rank: int) -> np.ndarray:
        """The ring buffer (float32, the tracker's grid) that the focus image of z rank
        ``rank`` may be computed into before it is pushed (the rank it replaces is no longer
        read): :meth:`push` of that buffer copies nothing."""
        return self.ring[int(rank) % self.ring.shape[0]]

    def push(self, f: np.ndarray, rank: int) -> None:
        """Add the focus image of z rank ``rank`` (ranks 0, 1, 2, … in order)."""
        ring, m = self.ring, self.ring.shape[0]
        slot = ring[rank % m]
        if not _same_buffer(f, slot):
            np.copyto(slot, f)
        self.fsum += slot
        if rank >= 2:
            d2 = self._d2
            cv2.addWeighted(slot, 1.0, ring[(rank - 1) % m], -2.0, 0.0, dst=d2)
            cv2.add(d2, ring[(rank - 2) % m], dst=d2)
            if self.d2sum.dtype == np.float32:
                cv2.accumulateSquare(d2, self.d2sum)
            else:
                self.d2sum += np.square(d2, dtype=np.float64)
        self._fill_after(slot, rank)
        self._take(slot, rank)

    def _fill_after(self, f, rank):
        """``f`` (rank ``rank``) into the window of each pixel whose best so far is one of
        the ``r`` ranks before it."""
        m8 = self._mask.view(np.uint8)                  # 0/1, an OpenCV mask (no copy)
        for j in range(1, self.r + 1):
            if rank - j < 0:
                break
            np.equal(self.best_rank, rank - j, out=self._mask)
            if rank == j:                   # rank 0: also the zeros of pixels without a best
                self._mask &= self.best > -np.inf
            if self._mask.any():
                cv2.copyTo(f, m8, self.window[self.r + j])

    def _take(self, f, rank):
        """Rank ``rank`` where it beats the best so far: its value, rank, and the ``r`` values
        before it from the ring (NaN before the stack); those after it NaN until pushed."""
        ring, r, m = self.ring, self.r, self.ring.shape[0]
        np.greater(f, self.best, out=self._mask)
        if not self._mask.any():
            return
        m8 = self._mask.view(np.uint8)
        cv2.max(f, self.best, dst=self.best)
        np.copyto(self.best_rank, rank, where=self._mask)
        for j in range(self.k):
            rk = rank - r + j
            if 0 <= rk <= rank:
                cv2.copyTo(ring[rk % m], m8, self.window[j])
            else:                                       # before the stack, or not yet read
                np.copyto(self.window[j], np.nan, where=self._mask)

    def release_ring(self) -> None:
        """Free the ring and the scan's work arrays (after the last slice)."""
        self.ring = None
        self._d2 = self._mask = None

    def release_curves(self) -> None:
        """Free what only the peak fit reads — ``window``, ``fsum``, ``d2sum`` — once it has
        read them; ``best`` (copied out of the window) and ``best_rank`` stay."""
        if self.window is not None:
            self.best = self.best.copy()
        self.window = self.fsum = self.d2sum = None


def _same_buffer(a, b) -> bool:
    """Whether ``a`` is the array ``b`` (the same memory, shape, strides and type)."""
    return (isinstance(a, np.ndarray) and a.dtype == b.dtype and a.shape == b.shape
            and a.strides == b.strides
            and a.__array_interface__["data"][0] == b.__array_interface__["data"][0])
