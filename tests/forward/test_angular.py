"""Angular colour maps (microfacet.forward.angular) of the three models: the half-vector
map against the film at each cell's half angle and against colour-science on a ``tmm``
spectrum, argument errors, and the one film table per map that keeps a 90×90 map fast.
ΔE00 maps and fitting: test_compare.py; the map files: tests/io/test_angular_map.py."""

import numpy as np
import pytest

from microfacet import colour as color
from microfacet.colour.srgb import colours_from_spectra
from microfacet.core.distributions import NDFMixture, ThicknessMixture
from microfacet.forward import brdf
from microfacet.forward.angular import simulate_map
from microfacet.forward.halfvector import spectra
from microfacet.optics.thinfilm import reflectance

G3 = ThicknessMixture([(0.3, 112.0, 3.0), (0.45, 130.0, 3.0), (0.25, 149.0, 3.0)])
F2 = NDFMixture([(0.6, 3.0), (0.4, 9.0)])
GRID = np.arange(0.0, 86.0, 5.0)


def test_half_vector_map_of_one_film_equals_the_film_at_the_half_angle():
    """The map (film reflectance tabulated over θ_d, averaged over g(d)) equals the film
    evaluated directly at each cell's half angle (:func:`halfvector.spectra`)."""
    m = simulate_map(model="half-vector", thickness=51.0, theta_light_deg=GRID,
                     theta_view_deg=GRID, exposure=0.7)
    wl, R = spectra(GRID[:, None], GRID[None, :], 51.0, wavelength_nm=m.wavelength_nm)
    _, ref_lab, ref_srgb, _ = colours_from_spectra(R, wl, exposure=0.7)
    assert np.max(color.delta_e_2000(m.lab.astype(float), ref_lab.astype(float))) < 1e-3
    assert np.abs(m.srgb.astype(int) - ref_srgb.astype(int)).max() <= 1


def test_half_vector_map_is_constant_along_the_antidiagonal_and_blue_at_51nm():
    m = simulate_map(model="half-vector", thickness=51.0,
                     theta_light_deg=np.arange(0, 61, 10.0),
                     theta_view_deg=np.arange(0, 61, 10.0))
    assert m.lab.shape == (7, 7, 3) and m.srgb.dtype == np.uint8
    # Cells with equal theta_light + theta_view see the film at the same angle.
    np.testing.assert_allclose(m.lab[1, 3], m.lab[3, 1], atol=1e-5)
    np.testing.assert_allclose(m.lab[0, 4], m.lab[2, 2], atol=1e-5)
    hue = np.rad2deg(np.arctan2(m.lab[0, 0, 2], m.lab[0, 0, 1])) % 360
    assert 220 < hue < 300  # blue




def test_angular_map_cell_equals_colour_science_on_the_tmm_spectrum():
    colour = pytest.importorskip("colour")
    tmm = pytest.importorskip("tmm")
    from microfacet.optics import optical_constants

    wl = np.arange(380.0, 781.0, 1.0)
    m = simulate_map(model="half-vector", thickness=120.0, theta_light_deg=[10.0],
                     theta_view_deg=[40.0], wavelength_nm=wl)
    n1 = optical_constants("TiO2_Jolivet2023_amorphous", wl)
    n2 = optical_constants("Ti_JohnsonChristy1974", wl)
    R = [np.mean([tmm.coh_tmm(p, [1, a, b], [np.inf, 120.0, np.inf], np.deg2rad(25.0), w)["R"]
                  for p in "sp"]) for w, a, b in zip(wl, n1, n2)]
    shape = colour.SpectralShape(380, 780, 1)
    cmfs = colour.MSDS_CMFS["CIE 1931 2 Degree Standard Observer"].copy().align(shape)
    ill = colour.SDS_ILLUMINANTS["D65"].copy().align(shape)
    xyz = colour.sd_to_XYZ(colour.SpectralDistribution(dict(zip(wl, R))), cmfs, ill,
                           method="Integration") / 100
    white = colour.sd_to_XYZ(colour.SpectralDistribution(dict(zip(wl, np.ones(wl.size)))),
                             cmfs, ill, method="Integration") / 100
    ref = colour.XYZ_to_Lab(xyz, colour.XYZ_to_xy(white))
    assert color.delta_e_2000(m.lab[0, 0].astype(float), ref) < 0.1


def test_colours_white_is_lab_100_and_nan_propagates():
    # colours_from_spectra (microfacet.colour.srgb) computes every map's colours; this
    # belongs with the colour tests (tests/colour/) and stays here until they take it
    wl = np.arange(380.0, 781.0, 5.0)
    R = np.ones((2, wl.size))
    R[1, 3] = np.nan
    xyz, lab, rgb, white = colours_from_spectra(R, wl)
    np.testing.assert_allclose(lab[0], [100, 0, 0], atol=1e-3)
    assert np.all(np.isnan(lab[1]))
    with pytest.raises(ValueError, match="exposure"):
        colours_from_spectra(R, wl, exposure=0)


def test_simulate_map_argument_errors():
    with pytest.raises(ValueError, match="model"):
        simulate_map(model="phong", thickness=100.0)
    with pytest.raises(ValueError, match="ndf"):
        simulate_map(model="microfacet", thickness=100.0)
    with pytest.raises(ValueError, match="n:"):
        simulate_map(model="eq6", thickness=100.0, ndf=F2)
    with pytest.raises(ValueError, match="theta_view_deg"):
        simulate_map(model="half-vector", thickness=100.0, theta_view_deg=[0, 90])


@pytest.mark.slow
def test_a_90x90_map_evaluates_the_film_once_per_distinct_angle(monkeypatch):
    """What keeps a full 90×90 in-plane map fast (its speed is measured by pipelines/, not
    asserted here): the thin-film reflectance, the expensive part, is evaluated on one table
    per map, once per distinct incidence angle, never per cell or per facet tilt."""
    builds, evaluated = [], []
    build = brdf.FilmAverage.build.__func__

    def counting_build(cls, theta_deg, thickness, **kw):
        fa = build(cls, theta_deg, thickness, **kw)
        builds.append((np.asarray(theta_deg, dtype=float), fa))
        return fa

    def counting_reflectance(wavelength_nm, theta_deg, *args, **kw):
        evaluated.append(np.shape(theta_deg)[0])         # angles in this block
        return reflectance(wavelength_nm, theta_deg, *args, **kw)

    monkeypatch.setattr(brdf.FilmAverage, "build", classmethod(counting_build))
    monkeypatch.setattr(brdf, "reflectance", counting_reflectance)
    t = np.arange(90.0)
    # in-plane pairs see the film at the half angle (θ_l + θ_v)/2: 179 values on this grid
    half_angles = np.unique(np.add.outer(t, t) / 2)
    assert half_angles.size == 179
    for model in ("microfacet", "half-vector", "eq6"):
        builds.clear()
        evaluated.clear()
        m = simulate_map(model=model, thickness=G3, ndf=F2, n=50, theta_light_deg=t,
                         theta_view_deg=t)
        assert m.spectra.shape[:2] == (90, 90) and np.isfinite(m.lab).all(), model
        assert len(builds) == 1, model                    # one film table per map
        requested, fa = builds[0]
        assert fa.exact, model
        np.testing.assert_array_equal(fa.theta_deg,
                                      np.unique(requested[np.isfinite(requested)]))
        assert sum(evaluated) == fa.theta_deg.size, model  # each angle evaluated once
        if model == "eq6":
            # |θ_in + θ_m| on the 0.5° midpoint grid of facet tilts: ≤ 180 distinct angles
            # for 8100 cells × ~100 tilts
            assert fa.theta_deg.size <= 180
            np.testing.assert_allclose(fa.theta_deg % 0.5, 0.25)
        else:
            # the half angles themselves, for both models (the microfacet model's θ_d from
            # unit vectors equals them to ~1e-14°, whose rounding used to split some values
            # into two or three table rows: 443 for these 179)
            np.testing.assert_array_equal(fa.theta_deg, half_angles)


def test_one_film_average_serves_the_half_vector_and_microfacet_maps(monkeypatch):
    """A film average built once (film_average_inplane) gives each model's map as it builds
    it itself, to rounding, and no map builds another; one of other wavelengths is refused,
    naming the argument."""
    from microfacet.forward.angular import film_average_inplane

    kw = dict(thickness=G3, theta_light_deg=GRID, theta_view_deg=GRID)
    fa = film_average_inplane(GRID, GRID, thickness=G3)
    own = {m: simulate_map(model=m, ndf=F2, **kw) for m in ("half-vector", "microfacet")}
    builds = []
    build = brdf.FilmAverage.build.__func__
    monkeypatch.setattr(brdf.FilmAverage, "build", classmethod(
        lambda cls, *a, **k: builds.append(1) or build(cls, *a, **k)))
    for model in ("half-vector", "microfacet"):
        shared = simulate_map(model=model, ndf=F2, film_average=fa, **kw)
        np.testing.assert_allclose(shared.spectra, own[model].spectra, rtol=1e-12, atol=0)
        np.testing.assert_array_equal(shared.srgb, own[model].srgb)
    assert builds == []                          # the given film average, not a new one
    other = film_average_inplane(GRID, GRID, thickness=G3, wavelength_nm=[450, 550, 650])
    with pytest.raises(ValueError, match="film_average"):
        simulate_map(model="half-vector", film_average=other, **kw)
