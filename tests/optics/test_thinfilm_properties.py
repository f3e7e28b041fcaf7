"""Property tests (hypothesis) of the thin-film reflectance (microfacet.optics.thinfilm).

Only properties that tests/optics/test_thinfilm.py does not already check (there: R in
[0, 1] and agreement with ``tmm``, d = 0 is the bare interface, lossless-film periodicity in
d); here: the scale invariances of Airy's formula, s = p at normal incidence, unpolarised
between s and p, Brewster's angle. No ``tmm`` needed.
"""

from __future__ import annotations

import math

import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from microfacet.optics.thinfilm import fresnel_reflectance, reflectance

FAST = settings(max_examples=60, deadline=None)

wavelength = st.floats(380.0, 780.0)
theta = st.floats(0.0, 89.99)
thickness = st.floats(0.0, 5000.0)
n_real = st.floats(1.0, 4.0)
k_film = st.floats(0.0, 2.0)
k_metal = st.floats(0.0, 10.0)
polarization = st.sampled_from(["s", "p", "unpolarized"])


@pytest.mark.slow
@FAST
@given(wl=wavelength, th=theta, d=thickness, n1r=n_real, n1i=k_film, n2r=n_real, n2i=k_metal,
       n0=st.floats(1.0, 1.6), c=st.floats(0.25, 4.0), pol=polarization)
def test_scaling_every_index_and_the_wavelength_together_changes_nothing(
        wl, th, d, n1r, n1i, n2r, n2i, n0, c, pol):
    # Fresnel coefficients depend on index ratios, the film phase on d·n/λ
    n1, n2 = complex(n1r, n1i), complex(n2r, n2i)
    a = reflectance(wl, th, d, n1, n2, n_ambient=n0, polarization=pol)
    b = reflectance(wl * c, th, d, n1 * c, n2 * c, n_ambient=n0 * c, polarization=pol)
    assert b == pytest.approx(a, abs=1e-9)


@pytest.mark.slow
@FAST
@given(wl=wavelength, th=theta, d=thickness, n1r=n_real, n1i=k_film, n2r=n_real, n2i=k_metal,
       c=st.floats(0.25, 4.0), pol=polarization)
def test_scaling_thickness_and_wavelength_together_changes_nothing(
        wl, th, d, n1r, n1i, n2r, n2i, c, pol):
    # constant (dispersion-free) indices: only d/λ enters
    n1, n2 = complex(n1r, n1i), complex(n2r, n2i)
    a = reflectance(wl, th, d, n1, n2, polarization=pol)
    b = reflectance(wl * c, th, d * c, n1, n2, polarization=pol)
    assert b == pytest.approx(a, abs=1e-9)


@pytest.mark.slow
@FAST
@given(wl=wavelength, d=thickness, n1r=n_real, n1i=k_film, n2r=n_real, n2i=k_metal)
def test_s_and_p_agree_at_normal_incidence(wl, d, n1r, n1i, n2r, n2i):
    n1, n2 = complex(n1r, n1i), complex(n2r, n2i)
    rs = reflectance(wl, 0.0, d, n1, n2, polarization="s")
    rp = reflectance(wl, 0.0, d, n1, n2, polarization="p")
    assert rs == pytest.approx(rp, abs=1e-12)


@pytest.mark.slow
@FAST
@given(wl=wavelength, th=theta, d=thickness, n1r=n_real, n1i=k_film, n2r=n_real, n2i=k_metal)
def test_unpolarized_lies_between_s_and_p(wl, th, d, n1r, n1i, n2r, n2i):
    n1, n2 = complex(n1r, n1i), complex(n2r, n2i)
    rs = float(reflectance(wl, th, d, n1, n2, polarization="s"))
    rp = float(reflectance(wl, th, d, n1, n2, polarization="p"))
    ru = float(reflectance(wl, th, d, n1, n2))
    assert min(rs, rp) - 1e-12 <= ru <= max(rs, rp) + 1e-12


@pytest.mark.slow
@FAST
@given(n1=st.floats(1.0, 2.0), n2=st.floats(1.05, 4.0))
def test_p_reflectance_vanishes_at_brewsters_angle(n1, n2):
    assume(abs(n2 - n1) > 1e-3)
    theta_b = math.degrees(math.atan(n2 / n1))
    assert fresnel_reflectance(theta_b, n1, n2, polarization="p") == pytest.approx(0, abs=1e-12)
    # and through the film formula: a film of the ambient's index hides nothing
    assert reflectance(550.0, theta_b, 123.0, n1, n2, n_ambient=n1,
                       polarization="p") == pytest.approx(0, abs=1e-12)
    # s is not extinguished: at Brewster's angle R_s = ((n1² − n2²) / (n1² + n2²))²
    # (analytic; the former "> 1e-6" failed for indices 1e-3 apart, where R_s ~ 1e-6)
    r_s = ((n1 ** 2 - n2 ** 2) / (n1 ** 2 + n2 ** 2)) ** 2
    assert fresnel_reflectance(theta_b, n1, n2, polarization="s") == pytest.approx(r_s,
                                                                                rel=1e-9)
    assert r_s > 0
