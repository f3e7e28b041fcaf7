"""The tabulated material (microfacet.forward.material): the table against the exact Airy
average, the BRDF through it against microfacet_brdf, the file round trip, results folders."""

import json

import numpy as np
import pytest

from microfacet.core.distributions import NDFMixture, ThicknessMixture
from microfacet.core.errors import InputError
from microfacet.forward.brdf import FilmAverage, microfacet_brdf
from microfacet.forward.material import Material

G2 = ThicknessMixture([(0.6, 112.0, 3.0), (0.4, 150.0, 0.2)])
F2 = NDFMixture([(0.7, 6.0), (0.3, 20.0)])


@pytest.fixture(scope="module")
def material():
    return Material.build(thickness=G2, ndf=F2)


def _dirs(rng, n):
    v = rng.normal(size=(n, 3))
    v[:, 2] = np.abs(v[:, 2])
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def test_the_table_is_the_thickness_average_of_airy(material):
    """At the grid's nodes the table is FilmAverage over the whole mixture (one quadrature
    for all components) to 1e-5, although it is built component by component."""
    rows = np.arange(0, material.theta_d_deg.size, 37)
    cols = np.arange(0, material.wavelength_nm.size, 23)
    exact = FilmAverage.build(material.theta_d_deg[rows], G2,
                              wavelength_nm=material.wavelength_nm[cols]).spectra
    np.testing.assert_allclose(material.film_average[np.ix_(rows, cols)], exact, atol=1e-5)


def test_brdf_through_the_table_matches_microfacet_brdf(material):
    """Between the nodes: |Δf| ≤ 1e-3 of the lobe's peak on random directions (the bilinear
    table's error; docs/rendering.md), and ≤ 2e-4 in R (f / geometry) where θ_d < 85°."""
    rng = np.random.default_rng(0)
    light, view = _dirs(rng, 400), _dirs(rng, 400)
    wl = rng.uniform(380.0, 780.0, 7)
    got = material.brdf(light, view, wavelength_nm=wl)
    ref = microfacet_brdf(light, view, thickness=G2, ndf=F2, wavelength_nm=wl)
    assert np.max(np.abs(got - ref)) <= 1e-3 * ref.max()
    h = light + view
    cos_d = np.sum(light * h, axis=1) / np.linalg.norm(h, axis=1)
    keep = (np.degrees(np.arccos(cos_d)) < 85) & (ref.max(axis=1) > 0)
    r_got = got[keep] / np.maximum(ref[keep].max(axis=1, keepdims=True), 1e-300)
    r_ref = ref[keep] / np.maximum(ref[keep].max(axis=1, keepdims=True), 1e-300)
    assert np.max(np.abs(r_got - r_ref)) < 5e-3


def test_interpolation_is_exact_at_nodes_and_clamped_outside(material):
    i, j = 100, 200
    t, w = material.theta_d_deg[i], material.wavelength_nm[j]
    assert material.film_reflectance(t, w) == pytest.approx(float(material.film_average[i, j]))
    last = material.film_average[:, -1].astype(float)
    np.testing.assert_allclose(material.film_reflectance(material.theta_d_deg, 900.0), last)
    assert np.isnan(material.film_reflectance(np.nan, 500.0))


def test_the_file_round_trips(material, tmp_path):
    path = material.write(tmp_path / "m.npz")
    back = Material.read(path)
    np.testing.assert_array_equal(back.film_average, material.film_average)
    assert back.ndf == material.ndf and back.thickness == material.thickness
    assert (back.film, back.substrate) == (material.film, material.substrate)
    # readable with numpy alone
    with np.load(path) as f:
        meta = json.loads(f["metadata.json"])
        assert f["film_average"].shape == material.film_average.shape
    assert meta["format"] == "microfacet-brdf/1" and "erf" in meta["brdf"]


def test_a_single_thickness(tmp_path):
    m = Material.build(thickness=51.0, ndf=F2, theta_step_deg=1.0, wavelength_step_nm=5.0)
    back = Material.read(m.write(tmp_path / "m.npz"))
    assert back.thickness == 51.0


def test_from_a_results_folder_without_an_ndf(tmp_path):
    (tmp_path / "summary.json").write_text(json.dumps({
        "format": "microfacet-results/1", "thickness": {"mixture": G2.to_json()}}))
    with pytest.raises(InputError, match=r"summary.json.*ndf\.mixture"):
        Material.from_results(tmp_path)


def test_bad_grid_steps_are_named():
    with pytest.raises(InputError, match="theta_step_deg"):
        Material.build(thickness=51.0, ndf=F2, theta_step_deg=0.0)
    with pytest.raises(InputError, match="ndf"):
        Material.build(thickness=51.0, ndf="8")
