"""microfacet.colour.adaptation: the Bradford transform (colour-science's operations).

Tested by its defining properties and a published matrix: Lam's (1985) cone matrix, the von
Kries form M⁻¹ diag(M w_dst / M w_src) M, source white -> target white, inverses, and
Lindbloom's D65 -> D50 Bradford matrix; and number for number against colour-science, whose
computation it repeats.
"""

from __future__ import annotations

import numpy as np
import pytest

from microfacet.colour.adaptation import BRADFORD, bradford_matrix

D65 = np.array([0.95047, 1.0, 1.08883])
D50 = np.array([0.96422, 1.0, 0.82521])
A = np.array([1.09850, 1.0, 0.35585])
SRGB = np.array([0.9505, 1.0, 1.0890])


def test_cone_matrix_is_lams():
    np.testing.assert_array_equal(BRADFORD, [[0.8951, 0.2664, -0.1614],
                                             [-0.7502, 1.7135, 0.0367],
                                             [0.0389, -0.0685, 1.0296]])
    assert not BRADFORD.flags.writeable


def test_d65_to_d50_matches_the_published_matrix():
    # Lindbloom, "Chromatic Adaptation", Bradford XYZ scaling, D65 -> D50
    expected = [[1.0478112, 0.0228866, -0.0501270],
                [0.0295424, 0.9904844, -0.0170491],
                [-0.0092345, 0.0150436, 0.7521316]]
    np.testing.assert_allclose(bradford_matrix(D65, D50), expected, rtol=0, atol=5e-8)


@pytest.mark.parametrize("src, dst", [(SRGB, A), (D65, D50), (A, D65), (SRGB, 2.0 * D50)])
def test_source_white_maps_to_target_white_by_von_kries(src, dst):
    m = bradford_matrix(src, dst)
    assert m.shape == (3, 3) and m.dtype == np.float64
    np.testing.assert_allclose(m @ src, dst, rtol=0, atol=1e-12)
    # von Kries in Bradford cone space: diagonal there, gains = cone ratio of the whites
    cone = BRADFORD @ m @ np.linalg.inv(BRADFORD)
    np.testing.assert_allclose(cone, np.diag((BRADFORD @ dst) / (BRADFORD @ src)), atol=1e-12)


def test_identity_and_inverse():
    np.testing.assert_allclose(bradford_matrix(D65, D65), np.eye(3), atol=1e-12)
    np.testing.assert_allclose(bradford_matrix(A, D50) @ bradford_matrix(D50, A), np.eye(3),
                               atol=1e-12)


@pytest.mark.parametrize("src, dst, name", [
    (np.ones(2), D65, "source_white"),
    (D65, np.ones((3, 3)), "target_white"),
    ([1.0, 0.0, 1.0], D65, "source_white"),
    (D65, [1.0, np.nan, 1.0], "target_white"),
])
def test_bad_whites_are_refused_by_name(src, dst, name):
    with pytest.raises(ValueError, match=name):
        bradford_matrix(src, dst)


def test_same_numbers_as_colour_science(colour_science):
    rng = np.random.default_rng(3)
    for _ in range(50):
        src, dst = rng.uniform(0.2, 1.3, 3), rng.uniform(0.2, 1.3, 3)
        src[1], dst[1] = 1.0, rng.uniform(0.5, 2.0)
        want = colour_science.adaptation.matrix_chromatic_adaptation_VonKries(
            src, dst, transform="Bradford")
        np.testing.assert_array_equal(bradford_matrix(src, dst), want)
