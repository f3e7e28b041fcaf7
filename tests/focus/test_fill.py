"""Filling holes of a height map (microfacet.focus.fill)."""

import numpy as np

from microfacet.focus.fill import fill_missing


def test_fill_missing():
    h = np.add.outer(np.arange(20.0), np.arange(30.0)).astype(np.float32)
    holed = h.copy()
    holed[5:9, 10:14] = np.nan
    for method in ("smooth", "nearest"):
        f = fill_missing(holed, method=method)
        assert np.isfinite(f).all()
        ok = np.isfinite(holed)
        np.testing.assert_array_equal(f[ok], h[ok])
        assert np.abs(f - h)[5:9, 10:14].max() < 4.0
