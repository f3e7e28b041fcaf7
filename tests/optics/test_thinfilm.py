"""Thin-film reflectance against the independent transfer-matrix code ``tmm``."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from microfacet.optics.thinfilm import (
    fresnel_reflectance,
    normal_wavevector,
    reflectance,
    reflectance_period_nm,
)

tmm = pytest.importorskip("tmm")


def _tmm_R(pol, n1, n2, d, theta_deg, wl, n0=1.0):
    return tmm.coh_tmm(pol, [n0, n1, n2], [np.inf, d, np.inf], np.deg2rad(theta_deg), wl)["R"]


def _random_cases(seed, count):
    """Randomised cases covering grazing incidence, d = 0, d = 2 µm, film k ≤ 1, substrate k ≤ 5."""
    rng = np.random.default_rng(seed)
    cases = []
    for _ in range(count):
        wl = rng.uniform(250.0, 1000.0)
        theta = rng.choice([0.0, rng.uniform(0, 89.9), 60.0, 89.9])
        d = rng.choice([0.0, rng.uniform(0, 400), rng.uniform(400, 2000), 2000.0])
        n1 = rng.uniform(1.0, 3.2) + 1j * rng.choice([0.0, rng.uniform(0, 0.1), rng.uniform(0, 1)])
        n2 = rng.uniform(0.2, 4.0) + 1j * rng.choice([0.0, rng.uniform(0, 5)])
        cases.append((wl, theta, d, n1, n2))
    return cases


@pytest.mark.slow
@pytest.mark.parametrize("pol", ["s", "p"])
def test_matches_tmm_randomised(pol):
    cases = _random_cases(1 if pol == "s" else 2, 600)
    wl, th, d, n1, n2 = (np.array(c) for c in zip(*cases))
    ours = reflectance(wl, th, d, n1, n2, polarization=pol)  # one vectorised call
    ref = np.array([_tmm_R(pol, *c[3:], c[2], c[1], c[0]) for c in cases])
    assert np.max(np.abs(ours - ref)) <= 1e-10


def test_required_corner_cases_match_tmm():
    # θ = 89.9°, d = 0, d = 2 µm, film k = 1, substrate k = 5, each combined.
    for th in (0.0, 45.0, 89.9):
        for d in (0.0, 51.0, 2000.0):
            for n1 in (2.45 + 0j, 2.2 + 1.0j):
                for n2 in (2.54 + 3.43j, 1.0 + 5.0j):
                    for pol in ("s", "p"):
                        ours = reflectance(550.0, th, d, n1, n2, polarization=pol)
                        assert abs(ours - _tmm_R(pol, n1, n2, d, th, 550.0)) <= 1e-10


def test_unpolarized_is_mean_of_s_and_p():
    wl = np.linspace(380, 780, 41)[:, None]
    th = np.linspace(0, 85, 18)
    rs = reflectance(wl, th, 120.0, 2.4, 2.5 + 3.4j, polarization="s")
    rp = reflectance(wl, th, 120.0, 2.4, 2.5 + 3.4j, polarization="p")
    ru = reflectance(wl, th, 120.0, 2.4, 2.5 + 3.4j)
    np.testing.assert_allclose(ru, 0.5 * (rs + rp), rtol=0, atol=1e-15)


def test_colour_science_counterexample():
    # Air -> 2.5 + 3.4i at 60°: the exact R_s is 0.764 (a real-part-only Snell gives 0.743).
    assert reflectance(550.0, 60.0, 0.0, 1.5, 2.5 + 3.4j, polarization="s") == pytest.approx(
        _tmm_R("s", 1.5, 2.5 + 3.4j, 0.0, 60.0, 550.0), abs=1e-12
    )
    assert reflectance(550.0, 60.0, 0.0, 1.5, 2.5 + 3.4j, polarization="s") == pytest.approx(
        0.764, abs=5e-4
    )


def test_broadcast_shape_and_dtype():
    wl = np.linspace(400, 700, 7)[:, None, None]
    th = np.linspace(0, 80, 5)[None, :, None]
    d = np.linspace(0, 300, 4)
    R = reflectance(wl, th, d, 2.4, 2.5 + 3.4j)
    assert R.shape == (7, 5, 4) and R.dtype == np.float64
    R32 = reflectance(wl, th, d, 2.4, 2.5 + 3.4j, dtype=np.float32)
    assert R32.dtype == np.float32
    np.testing.assert_allclose(R32, R, rtol=1e-6, atol=1e-7)
    assert np.ndim(reflectance(500.0, 10.0, 50.0, 2.4, 2.5 + 3.4j)) == 0


def test_named_optical_constants_equal_explicit_indices():
    from microfacet.optics import optical_constants

    wl = np.linspace(380, 780, 81)
    named = reflectance(wl, 30.0, 80.0, "TiO2_Jolivet2023_amorphous", "Ti_JohnsonChristy1974")
    explicit = reflectance(
        wl, 30.0, 80.0,
        optical_constants("TiO2_Jolivet2023_amorphous", wl),
        optical_constants("Ti_JohnsonChristy1974", wl),
    )
    np.testing.assert_array_equal(named, explicit)


def test_nan_propagates_without_error():
    th = np.array([10.0, np.nan, 20.0])
    d = np.array([50.0, 60.0, np.nan])
    R = reflectance(550.0, th, d, 2.4, 2.5 + 3.4j)
    assert np.isfinite(R[0]) and np.isnan(R[1]) and np.isnan(R[2])


@pytest.mark.parametrize(
    "kwargs, name",
    [
        (dict(theta_deg=90.0), "theta_deg"),
        (dict(theta_deg=-1.0), "theta_deg"),
        (dict(theta_deg=np.inf), "theta_deg"),
        (dict(thickness_nm=-1.0), "thickness_nm"),
        (dict(wavelength_nm=0.0), "wavelength_nm"),
        (dict(n_film=2.4 - 0.1j), "n_film"),
        (dict(n_substrate=-2.0 + 3j), "n_substrate"),
        (dict(n_substrate="Unobtainium"), "n_substrate"),
        (dict(n_film="TiO2_Jolivet2023_amorphous", wavelength_nm=900.0), "n_film"),
        (dict(n_ambient=1.0 + 0.1j), "n_ambient"),
        (dict(polarization="x"), "polarization"),
    ],
)
def test_out_of_range_input_names_the_argument(kwargs, name):
    args = dict(wavelength_nm=550.0, theta_deg=10.0, thickness_nm=50.0, n_film=2.4,
                n_substrate=2.5 + 3.4j)
    args.update(kwargs)
    with pytest.raises(ValueError, match=name):
        reflectance(**args)


def test_branch_of_normal_wavevector_decays_into_absorbing_and_evanescent_media():
    # Lossless medium beyond the critical angle, with a signed -0.0 imaginary part.
    q = normal_wavevector(np.complex128(complex(1.0, -0.0)), 1.5)
    assert q.imag > 0 and q.real == 0
    q = normal_wavevector(2.5 + 3.4j, np.sin(np.deg2rad(89.9)))
    assert q.imag > 0 and q.real > 0


index_real = st.floats(1.0, 4.0)
index_imag = st.floats(0.0, 5.0)


@pytest.mark.slow
@settings(max_examples=200, deadline=None)
@given(
    wl=st.floats(300, 1000), th=st.floats(0, 89.99), d=st.floats(0, 5000),
    n1r=index_real, n1i=st.floats(0, 1), n2r=st.floats(0.1, 5), n2i=index_imag,
    pol=st.sampled_from(["s", "p", "unpolarized"]),
)
def test_reflectance_is_a_fraction(wl, th, d, n1r, n1i, n2r, n2i, pol):
    R = reflectance(wl, th, d, complex(n1r, n1i), complex(n2r, n2i), polarization=pol)
    assert -1e-12 <= R <= 1 + 1e-12


def _textbook_fresnel(theta_deg, n, pol):
    """Air -> n, written independently: r_s = (cos - w)/(cos + w),
    r_p = (n² cos - w)/(n² cos + w)."""
    c = np.cos(np.deg2rad(theta_deg))
    w = np.sqrt(complex(n) ** 2 - np.sin(np.deg2rad(theta_deg)) ** 2)
    if w.imag < 0:
        w = -w
    n2 = complex(n) ** 2
    r = (c - w) / (c + w) if pol == "s" else (n2 * c - w) / (n2 * c + w)
    return abs(r) ** 2


@pytest.mark.slow
@settings(max_examples=200, deadline=None)
@given(th=st.floats(0, 89.99), n1r=index_real, n1i=st.floats(0, 1), n2r=st.floats(0.1, 5),
       n2i=index_imag, pol=st.sampled_from(["s", "p"]))
def test_zero_thickness_is_the_bare_substrate(th, n1r, n1i, n2r, n2i, pol):
    n2 = complex(n2r, n2i)
    R0 = reflectance(550.0, th, 0.0, complex(n1r, n1i), n2, polarization=pol)
    assert R0 == pytest.approx(_textbook_fresnel(th, n2, pol), abs=1e-12)
    assert R0 == pytest.approx(fresnel_reflectance(th, 1.0, n2, polarization=pol), abs=1e-12)


@pytest.mark.slow
@settings(max_examples=200, deadline=None)
@given(wl=st.floats(350, 900), th=st.floats(0, 89), d=st.floats(0, 1000),
       n1=st.floats(1.2, 3.0), n2r=st.floats(0.2, 4), n2i=index_imag,
       m=st.integers(1, 3))
def test_lossless_film_is_periodic_in_thickness(wl, th, d, n1, n2r, n2i, m):
    period = reflectance_period_nm(wl, th, n1)
    expected = wl / (2 * n1 * np.sqrt(1 - (np.sin(np.deg2rad(th)) / n1) ** 2))
    assert period == pytest.approx(expected, rel=1e-12)
    n2 = complex(n2r, n2i)
    assert reflectance(wl, th, d + m * period, n1, n2) == pytest.approx(
        reflectance(wl, th, d, n1, n2), abs=1e-9
    )


def test_thick_absorbing_film_hides_the_substrate():
    # 5 µm of a film with k = 1: the substrate no longer matters.
    a = reflectance(500.0, 30.0, 5000.0, 2.2 + 1.0j, 2.5 + 3.4j)
    b = reflectance(500.0, 30.0, 5000.0, 2.2 + 1.0j, 1.0 + 0.5j)
    bare = fresnel_reflectance(30.0, 1.0, 2.2 + 1.0j)
    assert np.isfinite(a) and a == pytest.approx(b, abs=1e-15)
    assert a == pytest.approx(bare, abs=1e-15)
