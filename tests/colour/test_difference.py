"""microfacet.colour.difference (kept ours: docs/benchmarks.md, the speed-colour study).

References: Sharma, Wu & Dalal (2005) Table 1 (fixtures/ciede2000_sharma2005.csv), and
colour-science and scikit-image as independent implementations of the same formulas.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from microfacet.colour.difference import (
    METHODS,
    delta_e,
    delta_e_76,
    delta_e_94,
    delta_e_2000,
)


def test_sharma_pairs_float64(sharma):
    lab1, lab2, expected = sharma
    # Table 1 gives 4 decimals, so agreement is to rounding (<= 5e-5).
    np.testing.assert_allclose(delta_e_2000(lab1, lab2), expected, rtol=0, atol=1e-4)


def test_sharma_pairs_swapped(sharma):
    lab1, lab2, expected = sharma
    np.testing.assert_allclose(delta_e_2000(lab2, lab1), expected, rtol=0, atol=1e-4)
    np.testing.assert_allclose(
        delta_e_2000(lab2, lab1), delta_e_2000(lab1, lab2), rtol=0, atol=1e-12
    )


def test_sharma_pairs_float32(sharma):
    lab1, lab2, expected = sharma
    out = delta_e_2000(lab1.astype(np.float32), lab2.astype(np.float32))
    assert out.dtype == np.float32
    # float32 passes the same 1e-4 tolerance (rounding of the table + ~1e-6 float32)
    np.testing.assert_allclose(out, expected, rtol=0, atol=1e-4)
    swapped = delta_e_2000(lab2.astype(np.float32), lab1.astype(np.float32))
    np.testing.assert_allclose(swapped, expected, rtol=0, atol=1e-4)


def test_delta_e_2000_vs_colour_science_random(colour_science, random_lab):
    rng = np.random.default_rng(7)
    lab1 = random_lab(rng, 20000)
    near = lab1 + rng.normal(0, 3, lab1.shape)
    far = random_lab(rng, 20000)
    # neutral and exactly opposite / equal hues, zero chroma
    special = np.array(
        [[50, 0, 0], [60, 0, 0], [50, 3, 4], [50, -3, -4], [50, -6, -8], [50, 6, 8],
         [50, 0, -5], [50, 0, 5], [50, -2, 0], [50, 2, 0]], dtype=float
    )
    s1 = np.repeat(special, len(special), axis=0)
    s2 = np.tile(special, (len(special), 1))
    for a, b in ((lab1, near), (lab1, far), (s1, s2)):
        ref = colour_science.delta_E(a, b, method="CIE 2000")
        np.testing.assert_allclose(delta_e_2000(a, b), ref, rtol=0, atol=1e-9)
        # float32: compare with the float64 reference on the same (rounded) inputs
        a32, b32 = a.astype(np.float32), b.astype(np.float32)
        ref32 = colour_science.delta_E(a32.astype(float), b32.astype(float), method="CIE 2000")
        np.testing.assert_allclose(delta_e_2000(a32, b32), ref32, rtol=0, atol=2e-4)


def test_delta_e_2000_vs_skimage(random_lab):
    skc = pytest.importorskip("skimage.color")
    rng = np.random.default_rng(3)
    a, b = random_lab(rng, 5000), random_lab(rng, 5000)
    np.testing.assert_allclose(delta_e_2000(a, b), skc.deltaE_ciede2000(a, b), atol=1e-9)


def test_delta_e_2000_broadcast_nan_and_shape(sharma):
    lab1, lab2, expected = sharma
    grid = np.broadcast_to(lab1[:4], (2, 3, 4, 3)).copy()
    out = delta_e_2000(grid, lab2[:4])
    assert out.shape == (2, 3, 4)
    np.testing.assert_allclose(out[1, 2], expected[:4], atol=1e-4)
    one = delta_e_2000(grid, lab2[0])  # (..., 3) against (3,)
    np.testing.assert_allclose(one[0, 0, 0], expected[0], atol=1e-4)
    assert np.ndim(delta_e_2000(lab1[0], lab2[0])) == 0
    bad = grid.copy()
    bad[0, 1, 2, 1] = np.nan
    out = delta_e_2000(bad, lab2[:4])
    assert np.isnan(out[0, 1, 2]) and np.isnan(out).sum() == 1
    for fn in (delta_e_76, delta_e_94):
        out = fn(bad, lab2[:4])
        assert out.shape == (2, 3, 4) and np.isnan(out[0, 1, 2]) and np.isnan(out).sum() == 1


def test_delta_e_76_and_94_vs_colour_science(colour_science, random_lab):
    rng = np.random.default_rng(5)
    a, b = random_lab(rng, 1000), random_lab(rng, 1000)
    np.testing.assert_allclose(delta_e_76(a, b), colour_science.delta_E(a, b, method="CIE 1976"))
    np.testing.assert_allclose(
        delta_e_94(a, b), colour_science.delta_E(a, b, method="CIE 1994"), rtol=1e-12
    )


def test_delta_e_76_is_euclidean():
    assert float(delta_e_76([50.0, 0.0, 0.0], [50.0, 3.0, 4.0])) == 5.0
    assert float(delta_e_76([10.0, 1.0, 2.0], [22.0, 1.0, -3.0])) == 13.0


def test_delta_e_dispatches_by_name(sharma):
    lab1, lab2, expected = sharma
    assert METHODS == ("CIEDE2000", "CIE94", "CIE76")
    for name in ("CIEDE2000", "2000", "de2000", "ciede2000"):
        np.testing.assert_allclose(delta_e(lab1, lab2, method=name), expected, atol=1e-4)
    np.testing.assert_array_equal(delta_e(lab1, lab2, method="CIE94"), delta_e_94(lab1, lab2))
    np.testing.assert_array_equal(delta_e(lab1, lab2, method="76"), delta_e_76(lab1, lab2))
    with pytest.raises(ValueError, match="method.*CIEDE2000"):
        delta_e(lab1, lab2, method="CMC")


lab_values = st.tuples(
    st.floats(0, 100), st.floats(-128, 128), st.floats(-128, 128)
).map(np.array)


@pytest.mark.slow
@settings(max_examples=300, deadline=None)
@given(lab_values, lab_values)
def test_delta_e_2000_properties(x, y):
    d = delta_e_2000(x, y)
    assert d >= 0
    assert d == pytest.approx(float(delta_e_2000(y, x)), abs=1e-9)
    assert delta_e_2000(x, x) == 0


def _near_opposite(x, y):
    h1 = np.arctan2(x[2], x[1])
    h2 = np.arctan2(y[2], y[1])
    return abs(abs((h1 - h2 + np.pi) % (2 * np.pi) - np.pi) - np.pi) < 1e-3


@pytest.mark.slow
@settings(max_examples=200, deadline=None)
@given(lab_values, lab_values)
def test_delta_e_2000_float32_close_to_float64(x, y):
    x32, y32 = x.astype(np.float32), y.astype(np.float32)
    d64 = float(delta_e_2000(x32.astype(float), y32.astype(float)))
    d32 = float(delta_e_2000(x32, y32))
    # float32 error grows near the CIEDE2000 mean-hue discontinuity (opposite hues,
    # where the formula itself jumps); elsewhere it stays ~1e-5.
    assert d32 == pytest.approx(d64, abs=2e-4, rel=1e-5) or _near_opposite(x, y)


@pytest.mark.parametrize("fn", [delta_e_2000, delta_e_76, delta_e_94])
def test_delta_e_bad_input(fn):
    with pytest.raises(ValueError, match="lab1"):
        fn(np.zeros((4, 2)), np.zeros((4, 3)))
    with pytest.raises(ValueError, match="lab2"):
        fn(np.zeros((4, 3)), np.zeros((4, 4)))


def test_delta_e_2000_no_shape_mismatch_crash():
    with pytest.raises(ValueError, match="broadcast"):
        delta_e_2000(np.zeros((4, 3)), np.zeros((5, 3)))
