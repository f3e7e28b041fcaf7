"""The seed's eq. 6 (microfacet.forward.eq6): against a literal double sum, convergence in
the tilt step, 3-D pairs and tabulated NDFs, errors."""

import math

import numpy as np
import pytest

from microfacet.core.distributions import NDFMixture, ThicknessMixture
from microfacet.forward.eq6 import eq6_reflectance, eq6_reflectance_inplane, inplane_tilt_density
from microfacet.forward.halfvector import in_plane_directions
from microfacet.optics import DEFAULT_FILM, DEFAULT_SUBSTRATE
from microfacet.optics.thinfilm import reflectance

G3 = ThicknessMixture([(0.3, 112.0, 3.0), (0.45, 130.0, 3.0), (0.25, 149.0, 3.0)])
F2 = NDFMixture([(0.6, 3.0), (0.4, 9.0)])
WL5 = np.array([420.0, 480.0, 550.0, 610.0, 680.0])

def _f_slope_marginal(th_deg, comps):
    """In-plane tilt density written out independently: atan of N(0, s²) slopes."""
    t = math.tan(math.radians(th_deg))
    tot = 0.0
    wsum = sum(w for w, _ in comps)
    for w, sd in comps:
        s = math.tan(math.radians(sd))
        tot += w / wsum * math.exp(-0.5 * (t / s) ** 2) / (s * math.sqrt(2 * math.pi))
    return tot * (1 + t * t)


def _eq6_slow(t_in, t_out, d_grid, g, comps, n, step, wl):
    """Literal double sum of eq. 6 (one thin-film call per (θ_m, d) term)."""
    c = lambda x: max(math.cos(math.radians(x)), 0.0)  # noqa: E731
    gw = np.array(g) * np.gradient(d_grid)  # trapezoid on a uniform grid...
    gw[0] /= 2
    gw[-1] /= 2  # ...has half weights at the ends
    gw = gw / gw.sum()
    total = np.zeros(len(wl))
    nm = int(round(180 / step))
    for k in range(nm):
        tm = -90 + step * (k + 0.5)
        a = t_in + tm
        if abs(a) >= 90:
            continue
        geo = c(t_in + tm) * c(t_out - tm) * c(t_out - t_in - 2 * tm) ** n
        fm = _f_slope_marginal(tm, comps) * math.radians(step)
        if geo * fm == 0:
            continue
        for d, w in zip(d_grid, gw):
            r = reflectance(wl, abs(a), d, DEFAULT_FILM, DEFAULT_SUBSTRATE)
            total += r * w * fm * geo
    return total


@pytest.mark.slow
def test_eq6_equals_a_direct_slow_summation():
    comps = [(0.6, 3.0), (0.4, 9.0)]
    d_grid = np.linspace(120.0, 140.0, 11)
    g = np.exp(-0.5 * ((d_grid - 130) / 4) ** 2)
    pairs = [(10.0, 30.0), (40.0, 45.0), (0.0, 12.0), (35.0, -20.0), (70.0, 68.0)]
    fast = eq6_reflectance_inplane([p[0] for p in pairs], [p[1] for p in pairs],
                                   thickness=(d_grid, g), ndf=NDFMixture(comps), n=30,
                                   wavelength_nm=WL5, theta_m_step_deg=1.0)
    for (ti, to), got in zip(pairs, fast):
        ref = _eq6_slow(ti, to, d_grid, g, comps, 30, 1.0, WL5)
        np.testing.assert_allclose(got, ref, rtol=1e-9, atol=1e-15)
    assert np.all(fast[0] > 0)


def test_eq6_converges_in_the_tilt_step_and_peaks_at_the_mirror():
    tv = np.arange(0.0, 86.0, 1.0)
    a = eq6_reflectance_inplane(30.0, tv, thickness=G3, ndf=F2, n=40, wavelength_nm=WL5,
                                theta_m_step_deg=0.5)
    b = eq6_reflectance_inplane(30.0, tv, thickness=G3, ndf=F2, n=40, wavelength_nm=WL5,
                                theta_m_step_deg=0.1)
    np.testing.assert_allclose(a, b, rtol=1e-4, atol=1e-8 * b.max())
    assert abs(tv[np.argmax(b[:, 2])] - 30.0) <= 1.0


def test_eq6_3d_pairs_match_in_plane_and_tabulated_ndf_matches_mixture():
    light, view = in_plane_directions([10.0, 40.0], [30.0, 45.0])
    ref = eq6_reflectance_inplane([10.0, 40.0], [30.0, 45.0], thickness=G3, ndf=F2, n=20,
                                  wavelength_nm=WL5)
    np.testing.assert_allclose(eq6_reflectance(light, view, thickness=G3, ndf=F2, n=20,
                                               wavelength_nm=WL5), ref, rtol=1e-12)
    th = np.linspace(-89.9, 89.9, 36001)
    tab = (th, inplane_tilt_density(F2, th))
    got = eq6_reflectance_inplane([10.0, 40.0], [30.0, 45.0], thickness=G3, ndf=tab, n=20,
                                  wavelength_nm=WL5)
    np.testing.assert_allclose(got, ref, rtol=1e-4)


def test_eq6_nan_and_argument_errors():
    r = eq6_reflectance_inplane([np.nan, 10.0], 20.0, thickness=130.0, ndf=F2, n=10,
                                wavelength_nm=WL5)
    assert np.all(np.isnan(r[0])) and np.all(np.isfinite(r[1]))
    with pytest.raises(ValueError, match="n:"):
        eq6_reflectance_inplane(10.0, 20.0, thickness=130.0, ndf=F2, n=-1)
    with pytest.raises(ValueError, match="theta_out_deg"):
        eq6_reflectance_inplane(10.0, 95.0, thickness=130.0, ndf=F2, n=1)
    with pytest.raises(ValueError, match="thickness"):
        eq6_reflectance_inplane(10.0, 20.0, thickness=-3.0, ndf=F2, n=1)
