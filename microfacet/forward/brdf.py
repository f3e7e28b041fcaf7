"""Forward models: the seed's eq. 6 and a microfacet thin-film BRDF (Walter et al. 2007).

Both turn the two measured distributions — oxide thickness ``g(d)`` and facet normals
``f`` / ``D`` — into the spectral reflectance for a light and a view direction. The film
enters only through the **thickness-averaged film reflectance**

    ⟨R⟩(θ, λ) = ∫ R(λ; θ, d) g(d) dd,

with R the exact Airy reflectance (:func:`microfacet.optics.thinfilm.reflectance`, seed eqs.
2-4) of a facet seen at incidence θ. ⟨R⟩ is evaluated once, at the distinct incidence
angles a whole map needs (or on a fine θ table with linear interpolation when there are
too many distinct angles), over the thickness nodes that carry probability mass
(:func:`thickness_nodes`), and reused for every direction pair.

Geometry and sign conventions
-----------------------------
z is the macroscopic normal. Directions point away from the surface. In the plane of
incidence (as in :mod:`microfacet.forward.halfvector`) the light is at ``l = (−sin θ_in, 0,
cos θ_in)`` and the view at ``v = (sin θ_out, 0, cos θ_out)``: θ_out is counted positive
on the mirror side, so ``θ_out = θ_in`` is the specular direction. A facet tilted by θ_m
towards +x has normal ``m = (sin θ_m, 0, cos θ_m)``.

Seed eq. 6 (the interpretation implemented here)
------------------------------------------------
The printed equation (seed §3.4) is garbled in its cosine terms. Implemented:

    R(θ_in, θ_out) = Σ_θm Σ_d  r(|θ_in + θ_m|, d) g(d) Δd · f(θ_m) Δθ_m
                     · c(θ_in + θ_m) · c(θ_out − θ_m) · c(θ_out − θ_in − 2θ_m)^n,

    c(x) = max(cos x, 0).

* ``θ_in + θ_m`` is the angle of incidence of the light on the facet (the seed's
  ``r(θ_in + θ_m, d)``); r is the film reflectance at that angle.
* ``c(θ_in + θ_m)`` is the foreshortening of the facet seen from the light (irradiance
  on the facet), ``c(θ_out − θ_m)`` the foreshortening seen from the viewer (the facet's
  projected area in the view direction); both vanish when the facet faces away.
* ``c(θ_out − θ_in − 2θ_m)^n`` is a Phong cosine lobe of exponent n about the facet's
  mirror direction: the light reflected by the facet leaves at ``θ_in + 2θ_m`` on the
  mirror side, and the lobe weights the view by its angular distance from there.
* ``f(θ_m)`` is the in-plane density of facet tilts per radian. For the Gaussian-slope
  lobes of :class:`~microfacet.core.distributions.NDFMixture` it is the density of the
  signed angle ``θ_m = atan(p)`` of one slope component ``p ~ N(0, s²)``:
  ``f(θ) = Σ w_i φ(tan θ / s_i) sec²θ / s_i``, mode 0°. A tabulated ``(θ_deg, density)``
  pair is also accepted (linearly interpolated, zero outside, normalised to unit mass).
* ``g(d)`` is a :class:`~microfacet.core.distributions.ThicknessMixture` or a tabulated
  ``(d_nm, density)`` pair; its quadrature weights are normalised to sum to 1.

The overall scale of eq. 6 is arbitrary (the seed fits n and compares colours after
exposure), so R is returned as the plain double sum written above. The θ_m sum is a
midpoint rule with step ``theta_m_step_deg`` on ``(−90°, 90°)``, restricted to the
tilts where f carries mass.

Microfacet BRDF
---------------
The physically based form (Cook–Torrance; Walter et al. 2007, eq. 20):

    f_r(l, v; λ) = ⟨R⟩(θ_d, λ) D(h) G₂(l, v) / (4 cos θ_l cos θ_v),

with ``h = (l + v)/|l + v|``, θ_d = ∠(l, h) = half the angle between l and v (seed
eq. 5), D the Beckmann-mixture NDF of :meth:`NDFMixture.D` (∫ D cos θ_h dω = 1), and
the height-correlated Smith masking-shadowing ``G₂ = 1/(1 + Λ(l) + Λ(v))`` with the
mixture's own Λ (:meth:`NDFMixture.smith_lambda`; Λ is linear in a slope mixture, so
G₂ is exactly consistent with D). It is symmetric in l and v (reciprocal), and since
⟨R⟩ ≤ 1 and the Smith G₁ satisfies ∫ G₁(v) ⟨v, h⟩⁺ D dω_h = cos θ_v, its directional
albedo is ≤ 1. ⟨R⟩, D and G₂ are separable, so the spectral shape at every pair is the
half-vector model's (the film at θ_d); the NDF sets the brightness. For a very narrow
NDF the reflected light concentrates at the mirror direction and the directional
albedo tends to ⟨R⟩(θ_v), the flat-film (= half-vector at θ_view = θ_light) spectrum.

Functions accept any direction pairs (``(..., 3)`` vectors) or in-plane angles.

References
----------
.. [1] N. Nagata, M. Kamei, K. Takahashi, K. Tobitani, T. Akagi, S. Yamamura, "Simulation
   Technology for Titanium Oxide Layer Interference Color", Technical Report (the seed paper),
   §3.4 eq. (6) and §2.3-2.4 eq. (5).
.. [2] B. Walter, S. R. Marschner, H. Li, K. E. Torrance, "Microfacet models for refraction
   through rough surfaces", Eurographics Symposium on Rendering (2007) 195-206,
   doi:10.2312/EGWR/EGSR07/195-206.
.. [3] E. Heitz, "Understanding the masking-shadowing function in microfacet-based BRDFs", J.
   Comput. Graph. Tech. 3(2) (2014), https://jcgt.org/published/0003/02/03/.
.. [4] S. Fujimoto, K. Tobitani, M. Kamei, N. Nagata, T. Akagi, K. Takahashi, S. Yamamura,
   "Normal Distribution Model of Microfacets Based on Color Image Analysis for Titanium Surface
   with Thin Film Interference Color", J. Japan Soc. Precision Eng. 86(12) (2020) 1051-1056 (the
   seed's ref. 2).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..colour.colorimetry import spectral_weights
from ..core.defaults import DEFAULT_ILLUMINANT, DEFAULT_OBSERVER
from ..core.distributions import NDFMixture, ThicknessMixture
from ..optics.constants import DEFAULT_FILM, DEFAULT_SUBSTRATE
from ..optics.thinfilm import reflectance
from .halfvector import in_plane_directions

__all__ = ["FilmAverage", "default_wavelengths", "microfacet_brdf", "microfacet_brdf_inplane",
           "microfacet_geometry", "thickness_nodes"]

_DEG = math.pi / 180.0
#: Largest number of distinct incidence angles evaluated exactly; beyond it a table.
_MAX_EXACT_ANGLES = 4096
#: Step of the fallback incidence-angle table (degrees), linear interpolation.
_TABLE_STEP_DEG = 0.05
#: Most quadrature nodes of a thickness density (a mixture whose widest component spans
#: thousands of its narrowest SD needs more; it is refused, not allocated).
MAX_THICKNESS_NODES = 20_000


def default_wavelengths():
    """380-780 nm in 5 nm steps (81 samples), the default spectral grid."""
    return np.arange(380.0, 781.0, 5.0)


def wavelength_grid(wavelength_nm):
    """``wavelength_nm`` as a checked 1-D array, or :func:`default_wavelengths` for None."""
    if wavelength_nm is None:
        return default_wavelengths()
    wl = np.atleast_1d(np.asarray(wavelength_nm, dtype=np.float64))
    if wl.ndim != 1 or wl.size == 0 or not np.all(np.isfinite(wl)) or np.any(wl <= 0):
        raise ValueError("wavelength_nm: expected a 1-D array of positive wavelengths")
    return wl


# --------------------------------------------------------------------------- thickness
def thickness_nodes(thickness, *, n_sd=5.0, max_step_nm=2.0):
    """Quadrature nodes and weights of a thickness density (only where it has mass).

    Parameters
    ----------
    thickness : float, ThicknessMixture, or (d_nm, density) pair
        A single thickness (nm), a Gaussian mixture, or a tabulated density on a grid.
    n_sd : float
        A mixture is integrated over ``support_nm(n_sd=n_sd)`` (clipped at 0 nm).
    max_step_nm : float
        Largest node spacing for a mixture; the spacing is ``min(max_step_nm, σ_min/2)``
        (a Gaussian times the slowly varying R(d) is integrated to ~1e-6 by the
        trapezoid rule at that spacing).

    Returns
    -------
    d_nm : ndarray (K,)
    weight : ndarray (K,)
        Non-negative, summing to 1 (trapezoid × density, renormalised so a truncated
        or clipped density keeps unit mass).

    Examples
    --------
    >>> d, w = thickness_nodes(ThicknessMixture([(1.0, 100.0, 2.0)]))
    >>> round(float(np.sum(w * d)), 6)
    100.0
    """
    if isinstance(thickness, ThicknessMixture):
        lo, hi = thickness.support_nm(n_sd=n_sd)
        step = min(float(max_step_nm), float(np.min(thickness.sds_nm)) / 2.0)
        n_f = (hi - lo) / step + 1 if step > 0 else math.inf
        if not n_f <= MAX_THICKNESS_NODES:
            raise ValueError(f"thickness: the mixture spans {lo:g}-{hi:g} nm with a narrowest "
                             f"SD of {np.min(thickness.sds_nm):g} nm: {n_f:,.0f} quadrature "
                             f"nodes, more than the limit of {MAX_THICKNESS_NODES:,}")
        n = max(3, int(math.ceil(n_f - 1)) + 1)
        d = np.linspace(lo, hi, n)
        w = thickness.pdf(d) * trapezoid_weights(d)
    elif isinstance(thickness, tuple) and len(thickness) == 2:
        d = np.asarray(thickness[0], dtype=np.float64)
        p = np.asarray(thickness[1], dtype=np.float64)
        if d.ndim != 1 or p.shape != d.shape or d.size < 2:
            raise ValueError("thickness: a tabulated density needs 1-D d_nm and density of "
                             "the same length >= 2")
        if not (np.all(np.isfinite(d)) and np.all(np.isfinite(p))):
            raise ValueError("thickness: tabulated density has non-finite values")
        if np.any(np.diff(d) <= 0) or d[0] < 0:
            raise ValueError("thickness: d_nm must be increasing and >= 0")
        if np.any(p < 0):
            raise ValueError("thickness: density must be >= 0")
        w = p * trapezoid_weights(d)
    else:
        try:
            v = float(thickness)
        except (TypeError, ValueError):
            raise ValueError("thickness: expected a number (nm), a ThicknessMixture or a "
                             f"(d_nm, density) pair, got {type(thickness).__name__}") from None
        if not (math.isfinite(v) and v >= 0):
            raise ValueError(f"thickness: must be finite and >= 0 nm, got {thickness!r}")
        return np.array([v]), np.array([1.0])
    total = float(np.sum(w))
    if not total > 0:
        raise ValueError("thickness: the density has no mass")
    w = w / total
    keep = w > 1e-12
    return d[keep], w[keep] / np.sum(w[keep])


def trapezoid_weights(x):
    """Trapezoid-rule weights of the sample points ``x`` (1-D, increasing)."""
    dx = np.diff(x)
    w = np.zeros_like(x)
    w[:-1] += dx / 2
    w[1:] += dx / 2
    return w


# --------------------------------------------------------------------- film average
@dataclass
class FilmAverage:
    """Thickness-averaged film reflectance ⟨R⟩(θ, λ) on a set of incidence angles.

    Built once per map (:meth:`build`) and looked up for every direction pair.

    Attributes
    ----------
    theta_deg : ndarray (T,)
        Sorted incidence angles (degrees, 0 ≤ θ < 90) where ⟨R⟩ was evaluated.
    wavelength_nm : ndarray (N,)
    spectra : ndarray (T, N)
        ⟨R⟩ at those angles.
    exact : bool
        True when the angles are exactly the requested ones (lookups hit nodes); False
        for a uniform fallback table (linear interpolation, step 0.05°).
    d_nm, weight : ndarray (K,)
        The thickness nodes used.
    """

    theta_deg: np.ndarray
    wavelength_nm: np.ndarray
    spectra: np.ndarray
    exact: bool
    d_nm: np.ndarray
    weight: np.ndarray

    @classmethod
    def build(cls, theta_deg, thickness, *, wavelength_nm=None, film=DEFAULT_FILM,
              substrate=DEFAULT_SUBSTRATE, n_ambient=1.0, max_exact=_MAX_EXACT_ANGLES):
        """Evaluate ⟨R⟩ at the distinct finite values of ``theta_deg`` (any shape).

        Parameters
        ----------
        theta_deg : array_like
            All incidence angles (degrees) that will be looked up; NaN ignored.
        thickness : float, ThicknessMixture or (d_nm, density)
            See :func:`thickness_nodes`.
        wavelength_nm : array_like (N,), optional
            Default :func:`default_wavelengths`.
        film, substrate : str or complex
            Optical-constant set names (or constant indices).
        max_exact : int
            Beyond this many distinct angles, a uniform 0.05° table over their range is
            used instead (linear interpolation error < 1e-6 in R).

        Returns
        -------
        FilmAverage
        """
        wl = wavelength_grid(wavelength_nm)
        th = np.asarray(theta_deg, dtype=np.float64).ravel()
        th = th[np.isfinite(th)]
        if th.size and (th.min() < 0 or th.max() >= 90):
            raise ValueError("theta_deg: incidence angles must be in [0, 90)")
        u = np.unique(th) if th.size else np.array([0.0])
        exact = u.size <= max_exact
        if not exact:
            lo = math.floor(u[0] / _TABLE_STEP_DEG) * _TABLE_STEP_DEG
            hi = min(math.ceil(u[-1] / _TABLE_STEP_DEG) * _TABLE_STEP_DEG, 89.999)
            u = np.linspace(lo, hi, int(round((hi - lo) / _TABLE_STEP_DEG)) + 1)
        d, w = thickness_nodes(thickness)
        out = np.empty((u.size, wl.size))
        # Blocks of angles keep the (angle, thickness, wavelength) temporary small.
        block = max(1, 2_000_000 // max(1, d.size * wl.size))
        for s in range(0, u.size, block):
            R = reflectance(wl, u[s:s + block, None, None], d[None, :, None], film, substrate,
                            n_ambient=n_ambient)
            out[s:s + block] = np.einsum("tkn,k->tn", R, w)
        return cls(u, wl, out, exact, d, w)

    def lookup(self, theta_deg, values=None):
        """⟨R⟩ (or rows of ``values``, shape (T, C)) at ``theta_deg``; NaN stays NaN.

        Returns
        -------
        ndarray, shape theta_deg.shape + (N,) (or + (C,))
        """
        vals = self.spectra if values is None else values
        th = np.asarray(theta_deg, dtype=np.float64)
        i, f, ok = self.index_of(th)
        out = vals[i] * (1 - f)[..., None] + vals[np.minimum(i + 1, len(vals) - 1)] * f[..., None]
        if not np.all(ok):
            out = np.where(ok[..., None], out, np.nan)
        return out

    def index_of(self, th):
        """``(i, f, ok)``: table row below each angle, the fraction towards the next, and
        whether the angle is finite."""
        g = self.theta_deg
        ok = np.isfinite(th)
        t = np.where(ok, th, g[0])
        if g.size == 1:
            return np.zeros(t.shape, np.intp), np.zeros(t.shape), ok
        i = np.clip(np.searchsorted(g, t, side="right") - 1, 0, g.size - 2)
        f = np.clip((t - g[i]) / (g[i + 1] - g[i]), 0.0, 1.0)
        return i, f, ok

    def xyz(self, *, illuminant=DEFAULT_ILLUMINANT, observer=DEFAULT_OBSERVER):
        """XYZ of every row (perfect reflector Y = 1), shape (T, 3)."""
        return self.spectra @ spectral_weights(self.wavelength_nm, illuminant=illuminant,
                                                     observer=observer)


# ---------------------------------------------------------------------- microfacet BRDF
def unit_directions(x, name):
    """Directions ``(..., 3)`` normalised to unit length; ValueError names ``name``."""
    v = np.asarray(x, dtype=np.float64)
    if v.shape[-1:] != (3,):
        raise ValueError(f"{name}: expected an array of 3-vectors (..., 3), got shape {v.shape}")
    with np.errstate(invalid="ignore", divide="ignore"):
        n = np.linalg.norm(v, axis=-1, keepdims=True)
        if np.any(n == 0):
            raise ValueError(f"{name}: zero-length direction vector")
        return v / n


def _check_ndf(ndf, name="ndf"):
    """``ndf`` if it is an :class:`NDFMixture`, else ValueError naming ``name``."""
    if not isinstance(ndf, NDFMixture):
        raise ValueError(f"{name}: expected an NDFMixture, got {type(ndf).__name__}")
    return ndf


def microfacet_geometry(light, view, ndf):
    """The achromatic factor ``D G₂ / (4 cos θ_l cos θ_v)`` and θ_d of direction pairs.

    Parameters
    ----------
    light, view : array_like (..., 3)
        Directions away from the surface (z = macroscopic normal); they broadcast;
        normalised here.
    ndf : NDFMixture

    Returns
    -------
    geometry : ndarray (...,)
        Per steradian; 0 where either direction is at or below the horizon; NaN where an
        input is NaN.
    theta_d_deg : ndarray (...,)
        Half the angle between light and view (the incidence angle on the reflecting
        facets), degrees.

    Examples
    --------
    >>> g, td = microfacet_geometry([0, 0, 1], [0, 0, 1], NDFMixture([(1.0, 10.0)]))
    >>> float(td), round(float(g), 3)   # D(0) / 4 = 1 / (4 π α²), α = √2 tan 10°
    (0.0, 1.28)
    """
    ndf = _check_ndf(ndf)
    lu = unit_directions(light, "light")
    vu = unit_directions(view, "view")
    lu, vu = np.broadcast_arrays(lu, vu)
    bad = ~(np.all(np.isfinite(lu), axis=-1) & np.all(np.isfinite(vu), axis=-1))
    cl = lu[..., 2]
    cv = vu[..., 2]
    s = lu + vu
    sn = np.linalg.norm(s, axis=-1)
    with np.errstate(invalid="ignore", divide="ignore"):
        cos_h = np.clip(s[..., 2] / sn, -1.0, 1.0)
        theta_d = np.rad2deg(np.arctan2(np.linalg.norm(lu - vu, axis=-1), sn))
    up = (cl > 0) & (cv > 0) & (sn > 0) & ~bad
    th_h = np.where(up, np.rad2deg(np.arccos(np.where(up, cos_h, 1.0))), 0.0)
    th_l = np.where(up, np.rad2deg(np.arccos(np.where(up, cl, 1.0))), 0.0)
    th_v = np.where(up, np.rad2deg(np.arccos(np.where(up, cv, 1.0))), 0.0)
    D = ndf.D(th_h)
    G2 = 1.0 / (1.0 + ndf.smith_lambda(th_l) + ndf.smith_lambda(th_v))
    with np.errstate(invalid="ignore", divide="ignore"):
        geom = np.where(up, D * G2 / (4.0 * np.where(up, cl * cv, 1.0)), 0.0)
    geom = np.where(bad, np.nan, geom)
    theta_d = np.where(bad, np.nan, np.where(up, theta_d, 0.0))
    return geom, theta_d


def microfacet_brdf(light, view, *, thickness, ndf, wavelength_nm=None, film=DEFAULT_FILM,
                    substrate=DEFAULT_SUBSTRATE, n_ambient=1.0, film_average=None):
    """Spectral microfacet thin-film BRDF f_r(l, v; λ) for any direction pairs.

    ``f_r = ⟨R⟩(θ_d, λ) D(h) G₂(l, v) / (4 cos θ_l cos θ_v)`` (see the module docstring;
    Walter et al. 2007 with the seed's measured distributions).

    Parameters
    ----------
    light, view : array_like (..., 3)
        Directions away from the surface, z = macroscopic normal; they broadcast (S).
    thickness : float, ThicknessMixture or (d_nm, density)
        Oxide thickness density g(d).
    ndf : NDFMixture
        Facet-normal distribution (D and the consistent Smith Λ).
    wavelength_nm : array_like (N,), optional
        Default 380-780 nm in 5 nm steps.
    film, substrate : str
        Optical-constant set names.
    film_average : FilmAverage, optional
        Reuse a table already built for these θ_d (then ``thickness``, ``film`` … are
        not re-evaluated).

    Returns
    -------
    ndarray, shape S + (N,)
        BRDF in 1/sr (multiply by π for the reflectance factor an sBRDF instrument
        reports relative to a white diffuser). 0 below the horizon, NaN for NaN input.

    Seed
    ----
    §3.4: the physically based counterpart of eq. 6, with g(d) and the NDF of §3.3.3.

    Examples
    --------
    >>> f = microfacet_brdf([0, 0, 1], [0.1, 0, 1], thickness=51.0,
    ...                     ndf=NDFMixture([(1.0, 10.0)]), wavelength_nm=[450, 550, 650])
    >>> f.shape
    (3,)
    """
    geom, theta_d = microfacet_geometry(light, view, ndf)
    fa = film_average or FilmAverage.build(theta_d, thickness, wavelength_nm=wavelength_nm,
                                           film=film, substrate=substrate,
                                           n_ambient=n_ambient)
    return fa.lookup(theta_d) * geom[..., None]


def microfacet_brdf_inplane(theta_light_deg, theta_view_deg, **kwargs):
    """:func:`microfacet_brdf` for in-plane zenith angles (view positive on the mirror side).

    Parameters
    ----------
    theta_light_deg, theta_view_deg : array_like
        Degrees, ``-90 < θ < 90``; they broadcast (S).
    **kwargs
        As :func:`microfacet_brdf`.

    Returns
    -------
    ndarray, shape S + (N,)

    Examples
    --------
    >>> f = microfacet_brdf_inplane(30.0, 30.0, thickness=51.0,
    ...                             ndf=NDFMixture([(1.0, 5.0)]), wavelength_nm=[550.0])
    >>> bool(f[0] > 1.0)   # bright at the specular direction
    True
    """
    light, view = in_plane_directions(theta_light_deg, theta_view_deg)
    return microfacet_brdf(light, view, **kwargs)


# ----------------------------------------------------------------------------- eq. 6
