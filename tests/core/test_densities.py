"""Densities on grids (microfacet.core.densities): histograms, mixture densities per cell,
the NDF per steradian from a tilt histogram, Wasserstein distances."""

import numpy as np
import pytest
from scipy import integrate

from microfacet.core.densities import (
    cell_edges,
    histogram_density,
    mixture_cdf,
    ndf_D_from_tilt_histogram,
    pdf_table,
    wasserstein1,
    wasserstein1_pdf,
)
from microfacet.core.distributions import NDFMixture, ThicknessMixture


def test_histogram_density_integrates_to_one():
    rng = np.random.default_rng(12)
    c, d = histogram_density(rng.normal(0, 1, 1000), bins=20, range=(-2, 2))
    assert c.shape == d.shape == (20,)
    assert np.sum(d) * 0.2 == pytest.approx(1.0)
    with pytest.raises(ValueError, match="values"):
        histogram_density([10.0, np.nan], bins=5, range=(0, 1))


def test_pdf_table_thickness_and_tilt(thickness_samples, tilt_samples):
    rng = np.random.default_rng(13)
    g = ThicknessMixture([(0.5, 120, 3), (0.5, 140, 3)])
    d = thickness_samples(rng, g.components, 20000)
    grid = np.arange(100.0, 160.0, 1.0) + 0.5
    t = pdf_table(d, g, grid=grid)
    assert t.shape == (60, 3)
    np.testing.assert_array_equal(t[:, 0], grid)
    assert np.sum(t[:, 1]) * 1.0 == pytest.approx(1.0)
    assert np.sum(t[:, 2]) * 1.0 == pytest.approx(1.0)
    np.testing.assert_allclose(t[:, 2], g.pdf(grid), atol=4e-4)  # cell average ≈ point value
    assert np.max(np.abs(t[:, 1] - t[:, 2])) < 0.01

    # the tilt histogram matches tilt_pdf directly: no sin θ division
    f = NDFMixture([(0.6, 3.0), (0.4, 9.0)])
    tilt = tilt_samples(rng, f.components, 20000)
    grid = np.arange(0.0, 30.0, 0.5) + 0.25
    t = pdf_table(tilt, f, grid=grid)
    assert np.sum(t[:, 1]) * 0.5 == pytest.approx(1.0)
    assert np.sum(t[:, 2]) * 0.5 == pytest.approx(1.0)   # renormalised over [0, 30]
    assert wasserstein1_pdf(grid, t[:, 1], t[:, 2]) < 0.1
    np.testing.assert_allclose(t[:, 2], f.tilt_pdf(grid) / np.trapezoid(f.tilt_pdf(grid), grid),
                               atol=3e-3)


def test_pdf_table_errors():
    with pytest.raises(ValueError, match="grid"):
        pdf_table([1.0], ThicknessMixture([(1, 1, 1)]), grid=[2.0, 1.0])
    with pytest.raises(ValueError, match="mixture"):
        pdf_table([1.0], object(), grid=[0.0, 1.0, 2.0])


def test_ndf_D_from_tilt_histogram():
    f = NDFMixture([(0.6, 3.0), (0.4, 9.0)])
    th = np.linspace(0.0, 60.0, 121)
    D = ndf_D_from_tilt_histogram(th, f.tilt_pdf(th))
    assert np.isnan(D[0])
    np.testing.assert_allclose(D[1:], f.D(th[1:]), rtol=1e-9)


def test_wasserstein():
    rng = np.random.default_rng(14)
    a = rng.normal(130, 3, 5000)
    assert wasserstein1(a, a) == 0.0
    assert wasserstein1(a, a + 2.5) == pytest.approx(2.5)
    assert wasserstein1(np.append(a, np.nan), a) == 0.0
    with pytest.raises(ValueError, match="samples_b"):
        wasserstein1(a, [np.nan])
    x = np.linspace(80, 180, 4001)
    p = ThicknessMixture([(0.5, 120, 3), (0.5, 140, 3)]).pdf(x)
    q = ThicknessMixture([(0.5, 124, 3), (0.5, 144, 3)]).pdf(x)
    assert wasserstein1_pdf(x, p, p) == 0.0
    assert wasserstein1_pdf(x, p, q) == pytest.approx(4.0, abs=1e-3)
    with pytest.raises(ValueError, match="pdf_b"):
        wasserstein1_pdf(x, p, q[:-1])


def test_mixture_cdf_is_the_integral_of_the_density():
    g = ThicknessMixture([(0.5, 120, 3), (0.5, 140, 6)])
    x = np.linspace(80.0, 200.0, 120_001)
    np.testing.assert_allclose(mixture_cdf(g, x),
                               integrate.cumulative_trapezoid(g.pdf(x), x, initial=0.0),
                               atol=1e-8)
    f = NDFMixture([(0.6, 3.0), (0.4, 9.0)])
    th = np.linspace(0.0, 89.999, 200_001)
    np.testing.assert_allclose(mixture_cdf(f, th),
                               integrate.cumulative_trapezoid(f.tilt_pdf(th), th, initial=0.0),
                               atol=1e-7)
    np.testing.assert_allclose(mixture_cdf(f, np.array([90.0, 120.0])), 1.0)
    with pytest.raises(ValueError, match="mixture"):
        mixture_cdf(object(), x)


def test_cell_edges_are_halfway_and_the_outer_cells_symmetric():
    g = np.array([0.25, 0.75, 1.5, 3.0])
    grid, edges = cell_edges(g)
    np.testing.assert_array_equal(grid, g)
    np.testing.assert_allclose(edges, [0.0, 0.5, 1.125, 2.25, 3.75])
    assert np.all((edges[:-1] < g) & (g < edges[1:]))
    for bad in ([1.0], [2.0, 1.0], [0.0, np.nan]):
        with pytest.raises(ValueError, match="grid"):
            cell_edges(bad)
