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
    assert tr.fsum.dtype == np.float64
    assert tr.best_rank[1, 2] == 700
    np.testing.assert_allclose(tr.fsum, vol.astype(np.float64).sum(0), rtol=1e-12)
    tr.release_ring()
    assert tr.ring is None


@pytest.mark.parametrize("n, radius", [(3, 2), (12, 2), (9, 1)])
def test_measures_computed_into_the_ring_and_shared_work_planes_change_nothing(n, radius):
    """Focus images written straight into the ring (next_slot) and two trackers of one grid
    sharing their work planes, pushed in turn, give every array bitwise as a tracker of its
    own fed copies does."""
    rng = np.random.default_rng(n + 7 * radius)
    vols = [rng.random((n, 6, 7)).astype(np.float32) for _ in range(2)]
    ref = [PeakTracker((6, 7), radius=radius, n_slices=n) for _ in range(2)]
    first = PeakTracker((6, 7), radius=radius, n_slices=n)
    got = [first, PeakTracker((6, 7), radius=radius, n_slices=n, work_from=first)]
    assert got[1]._d2 is got[0]._d2 and got[1]._mask is got[0]._mask
    for k in range(n):
        for vol, a, b in zip(vols, ref, got):
            a.push(vol[k].copy(), k)
            slot = b.next_slot(k)
            slot[...] = vol[k]
            b.push(slot, k)
    for a, b in zip(ref, got):
        for name in ("best", "best_rank", "window", "fsum", "d2sum"):
            np.testing.assert_array_equal(getattr(b, name), getattr(a, name), err_msg=name)


def test_work_planes_are_not_shared_across_grids():
    full = PeakTracker((6, 7), radius=2, n_slices=5)
    half = PeakTracker((3, 4), radius=2, n_slices=5, work_from=full)
    assert half._d2.shape == (3, 4) and half._d2 is not full._d2
