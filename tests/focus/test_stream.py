"""The streaming peak tracker (microfacet.focus.stream) against a brute-force search over the
whole focus volume."""

from __future__ import annotations

import numpy as np
import pytest

from microfacet.focus.stream import PeakTracker


@pytest.mark.parametrize("n, radius", [(3, 1), (3, 2), (7, 1), (12, 2), (12, 3), (30, 2)])
def test_tracker_equals_brute_force(n, radius):
    rng = np.random.default_rng(n * 10 + radius)
    vol = rng.random((n, 9, 11)).astype(np.float32)
    tr = PeakTracker((9, 11), radius=radius, n_slices=n)
    for k in range(n):
        tr.push(vol[k], k)
    tr.finish()
    best = np.argmax(vol, axis=0)
    np.testing.assert_array_equal(tr.best_rank, best)
    np.testing.assert_array_equal(tr.best, vol.max(0))
    # the 2r+1 values around the best slice, NaN beyond the stack
    for j in range(2 * radius + 1):
        rk = best - radius + j
        inside = (rk >= 0) & (rk < n)
        ref = np.where(inside, np.take_along_axis(vol, np.clip(rk, 0, n - 1)[None], 0)[0],
                       np.nan)
        np.testing.assert_array_equal(tr.window[j], ref)
    np.testing.assert_allclose(tr.fsum, vol.astype(np.float64).sum(0), rtol=1e-5)
    d2 = np.diff(vol.astype(np.float64), 2, axis=0)
    np.testing.assert_allclose(tr.d2sum, (d2 * d2).sum(0), rtol=1e-4, atol=1e-6)


def test_tracker_many_slices_uses_double_sums():
    """Above 1000 slices the running sums are float64 (no loss on long stacks)."""
    rng = np.random.default_rng(0)
    n = 1201
    vol = (1000.0 + rng.random((n, 2, 3))).astype(np.float32)
    vol[700, 1, 2] = 5000.0
    tr = PeakTracker((2, 3), radius=2, n_slices=n)
    for k in range(n):
        tr.push(vol[k], k)
    tr.finish()
    assert tr.fsum.dtype == np.float64
    assert tr.best_rank[1, 2] == 700
    np.testing.assert_allclose(tr.fsum, vol.astype(np.float64).sum(0), rtol=1e-12)
    tr.release_ring()
    assert tr.ring is None
