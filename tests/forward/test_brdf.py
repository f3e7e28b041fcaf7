"""The microfacet thin-film BRDF (microfacet.forward.brdf): energy, reciprocity, the limit of
a flat surface, achromatic D and G, the thickness-averaged film table. Seed eq. 6:
test_eq6.py."""

import numpy as np
import pytest

from microfacet import colour as color
from microfacet.core.distributions import NDFMixture, ThicknessMixture
from microfacet.forward.brdf import (
    FilmAverage,
    microfacet_brdf,
    microfacet_brdf_inplane,
    microfacet_geometry,
    thickness_nodes,
)
from microfacet.forward.halfvector import spectra
from microfacet.optics import DEFAULT_FILM, DEFAULT_SUBSTRATE
from microfacet.optics.thinfilm import reflectance

G3 = ThicknessMixture([(0.3, 112.0, 3.0), (0.45, 130.0, 3.0), (0.25, 149.0, 3.0)])
F2 = NDFMixture([(0.6, 3.0), (0.4, 9.0)])
WL5 = np.array([420.0, 480.0, 550.0, 610.0, 680.0])


def _sphere_dirs(theta_deg, phi_deg):
    t, p = np.broadcast_arrays(np.deg2rad(theta_deg), np.deg2rad(phi_deg))
    return np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)], axis=-1)


def _albedo(view, ndf, *, thickness=None, wl=WL5, n_theta=900, n_phi=720):
    """∫ f_r(l, v) cos θ_l dω_l over the light hemisphere, midpoint rule in (θ, φ)."""
    dt, dp = 90.0 / n_theta, 360.0 / n_phi
    th = (np.arange(n_theta) + 0.5) * dt
    ph = (np.arange(n_phi) + 0.5) * dp
    L = _sphere_dirs(th[:, None], ph[None, :])
    dw = (np.sin(np.deg2rad(th)) * np.deg2rad(dt) * np.deg2rad(dp))[:, None]
    cos_l = np.cos(np.deg2rad(th))[:, None]
    geom, _ = microfacet_geometry(L, view, ndf)
    geom_albedo = float(np.sum(geom * cos_l * dw))
    if thickness is None:
        return geom_albedo
    f = microfacet_brdf(L, view, thickness=thickness, ndf=ndf, wavelength_nm=wl)
    return geom_albedo, np.sum(f * (cos_l * dw)[..., None], axis=(0, 1))


# ---------------------------------------------------------------- energy conservation
@pytest.mark.slow
@pytest.mark.parametrize("theta_v", [0.0, 45.0, 75.0])
@pytest.mark.parametrize("ndf", [F2, NDFMixture([(1.0, 25.0)])], ids=["3+9deg", "25deg"])
def test_directional_albedo_is_at_most_one(theta_v, ndf):
    view = _sphere_dirs(theta_v, 0.0)
    geom_albedo, spectral = _albedo(view, ndf, thickness=G3)
    # Geometric part (Fresnel = 1): Smith G keeps it <= 1; single scattering loses a
    # little at grazing / rough, almost nothing for a smooth surface at normal incidence.
    assert geom_albedo <= 1.0 + 2e-3
    assert geom_albedo > (0.97 if theta_v < 60 and ndf is F2 else 0.6)
    # With the averaged thin-film Fresnel term (< 1) the spectral albedo is smaller still.
    assert np.all(spectral <= geom_albedo + 1e-9) and np.all(spectral > 0)


@pytest.mark.slow
def test_geometric_albedo_matches_an_integral_over_half_vectors():
    """The same albedo in half-vector coordinates (dω_l = 4 (v·h) dω_h) — independent check
    of the numerical hemisphere integral and of the Jacobian-free BRDF form."""
    ndf = NDFMixture([(1.0, 12.0)])
    view = _sphere_dirs(30.0, 0.0)
    direct = _albedo(view, ndf)
    n_t, n_p = 1200, 720
    th = (np.arange(n_t) + 0.5) * (90.0 / n_t)
    ph = (np.arange(n_p) + 0.5) * (360.0 / n_p)
    H = _sphere_dirs(th[:, None], ph[None, :])
    vh = H @ view
    L = 2 * vh[..., None] * H - view
    ok = (L[..., 2] > 0) & (vh > 0)
    dw_h = (np.sin(np.deg2rad(th)) * np.deg2rad(90.0 / n_t) * np.deg2rad(360.0 / n_p))[:, None]
    D = ndf.D(th)[:, None]
    lam = ndf.smith_lambda
    th_l = np.rad2deg(np.arccos(np.clip(L[..., 2], -1, 1)))
    G2 = 1 / (1 + lam(np.where(ok, th_l, 0)) + lam(30.0))
    half = np.sum(np.where(ok, D * G2 * vh / view[2] * dw_h, 0.0))
    assert direct == pytest.approx(half, rel=2e-3)


# ---------------------------------------------------------------------- reciprocity
def test_reciprocity_for_random_direction_pairs():
    rng = np.random.default_rng(3)
    a = rng.normal(size=(400, 3))
    b = rng.normal(size=(400, 3))
    a[:, 2] = np.abs(a[:, 2]) + 0.05
    b[:, 2] = np.abs(b[:, 2]) + 0.05
    f_ab = microfacet_brdf(a, b, thickness=G3, ndf=F2, wavelength_nm=WL5)
    f_ba = microfacet_brdf(b, a, thickness=G3, ndf=F2, wavelength_nm=WL5)
    assert np.all(f_ab >= 0) and np.any(f_ab > 0)
    np.testing.assert_allclose(f_ab, f_ba, rtol=1e-12, atol=0)


def test_below_horizon_is_zero_and_nan_propagates():
    f = microfacet_brdf([[0, 0, 1], [0.3, 0, -1], [np.nan, 0, 1]], [0.2, 0, 1], thickness=60.0,
                        ndf=F2, wavelength_nm=WL5)
    assert np.all(f[0] > 0) and np.all(f[1] == 0) and np.all(np.isnan(f[2]))


# ---------------------------------------------------------- limit to the half-vector model
@pytest.mark.parametrize("theta_v", [0.0, 35.0, 60.0])
def test_narrow_ndf_albedo_is_the_flat_film_reflectance(theta_v):
    """A nearly flat surface (0.2° lobe) reflects ⟨R⟩(θ_v) of the film into the mirror
    direction: the half-vector model at θ_view = θ_light (θ_d = θ_v)."""
    ndf = NDFMixture([(1.0, 0.2)])
    view = _sphere_dirs(theta_v, 0.0)
    # Half-vector-space integral (the lobe is far too narrow for a light-direction grid).
    n_t, n_p = 400, 360
    tmax = 2.0
    th = (np.arange(n_t) + 0.5) * (tmax / n_t)
    ph = (np.arange(n_p) + 0.5) * (360.0 / n_p)
    H = _sphere_dirs(th[:, None], ph[None, :])
    vh = H @ view
    L = 2 * vh[..., None] * H - view
    dw_h = (np.sin(np.deg2rad(th)) * np.deg2rad(tmax / n_t) * np.deg2rad(360.0 / n_p))[:, None]
    f = microfacet_brdf(L, view, thickness=130.0, ndf=ndf, wavelength_nm=WL5)
    # f cos θ_l dω_l = f cos θ_l 4 (v·h) dω_h
    albedo = np.sum(f * (L[..., 2] * 4 * vh * dw_h)[..., None], axis=(0, 1))
    _, ref = spectra(theta_v, theta_v, 130.0, wavelength_nm=WL5)
    np.testing.assert_allclose(albedo, ref, rtol=3e-3)


def test_colour_at_every_pair_is_the_half_vector_colour():
    """D and G are achromatic: the chromaticity of the microfacet map is that of the film at
    each cell's half angle (computed directly, :func:`halfvector.spectra`)."""
    grid = np.arange(0.0, 86.0, 5.0)
    wl = np.linspace(380, 780, 81)
    _, R = spectra(grid[:, None], grid[None, :], 51.0, wavelength_nm=wl)
    hv_xyz = R @ color.spectral_weights(wl)
    f = microfacet_brdf_inplane(grid[:, None], grid[None, :], thickness=51.0,
                                ndf=NDFMixture([(1.0, 20.0)]), wavelength_nm=wl)
    xyz = f @ color.spectral_weights(wl)
    Y = xyz[..., 1]
    assert np.all(Y > 0)
    xy = xyz[..., :2] / xyz.sum(-1, keepdims=True)
    xy_hv = hv_xyz[..., :2] / hv_xyz.sum(-1, keepdims=True)
    np.testing.assert_allclose(xy, xy_hv, atol=1e-10)


def test_thickness_average_against_brute_force_integral():
    d_fine = np.linspace(80, 180, 20001)
    p = G3.pdf(d_fine)
    R = reflectance(WL5, 25.0, d_fine[:, None], DEFAULT_FILM, DEFAULT_SUBSTRATE)
    ref = np.trapezoid(R * p[:, None], d_fine, axis=0) / np.trapezoid(p, d_fine)
    fa = FilmAverage.build([25.0], G3, wavelength_nm=WL5)
    np.testing.assert_allclose(fa.lookup(25.0), ref, rtol=2e-5)
    d, w = thickness_nodes(G3)
    assert np.sum(w) == pytest.approx(1.0)
    assert np.sum(w * d) == pytest.approx(np.sum(G3.weights * G3.means_nm), abs=1e-6)


def test_film_table_fallback_interpolates_accurately():
    th = np.linspace(0, 80, 5001)  # more distinct angles than the exact limit
    fa = FilmAverage.build(th, 130.0, wavelength_nm=WL5, max_exact=100)
    assert not fa.exact
    np.testing.assert_allclose(fa.lookup(th[::97]),
                               reflectance(WL5, th[::97, None], 130.0, DEFAULT_FILM,
                                           DEFAULT_SUBSTRATE), atol=2e-6)


def test_brdf_argument_errors():
    with pytest.raises(ValueError, match="ndf"):
        microfacet_brdf([0, 0, 1], [0, 0, 1], thickness=100.0, ndf="beckmann")
    with pytest.raises(ValueError, match="light"):
        microfacet_brdf([0, 0, 0], [0, 0, 1], thickness=100.0, ndf=F2)
