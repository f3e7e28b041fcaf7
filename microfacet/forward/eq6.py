"""Seed eq. 6: the microfacet thin-film model as the paper writes it (§3.4).

    R(in, out) = Σ_θm Σ_d r(θ_in + θ_m, d) g(d) f(θ_m)
                 cos(θ_in + θ_m) cos(θ_out − θ_m) cos(θ_out − θ_in − 2θ_m)^n

in the plane of incidence, with r the film reflectance (:mod:`microfacet.optics.thinfilm`)
averaged over the thickness density g(d) (:class:`~microfacet.forward.brdf.FilmAverage`), f
the in-plane facet-tilt density (:func:`inplane_tilt_density`) and n the cosine-lobe
exponent. The overall scale is arbitrary (the seed fits n and compares colours after
exposure). :class:`Eq6Kernel` tabulates everything but n, so fitting n costs one weighted sum
per trial. The physically based counterpart: :mod:`microfacet.forward.brdf`.

References
----------
.. [1] N. Nagata, M. Kamei, K. Takahashi, K. Tobitani, T. Akagi, S. Yamamura, "Simulation
   Technology for Titanium Oxide Layer Interference Color", Technical Report (the seed paper),
   §3.4, eq. (6).
.. [2] S. Fujimoto, K. Tobitani, M. Kamei, N. Nagata, T. Akagi, K. Takahashi, S. Yamamura,
   "Normal Distribution Model of Microfacets Based on Color Image Analysis for Titanium Surface
   with Thin Film Interference Color", J. Japan Soc. Precision Eng. 86(12) (2020) 1051-1056 (the
   seed's ref. 2).
.. [3] R. L. Cook, K. E. Torrance, "A reflectance model for computer graphics", ACM Trans.
   Graph. 1(1) (1982) 7-24, doi:10.1145/357290.357293.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..core.defaults import DEFAULT_ILLUMINANT, DEFAULT_OBSERVER
from ..core.distributions import NDFMixture
from ..optics.constants import DEFAULT_FILM, DEFAULT_SUBSTRATE
from .brdf import FilmAverage, trapezoid_weights, unit_directions
from .halfvector import signed_angles

__all__ = ["Eq6Kernel", "eq6_reflectance", "eq6_reflectance_inplane", "inplane_tilt_density"]

_DEG = math.pi / 180.0


def inplane_tilt_density(ndf, theta_m_deg):
    """In-plane facet-tilt density f(θ_m) of eq. 6, per radian, at signed ``theta_m_deg``.

    Parameters
    ----------
    ndf : NDFMixture or (theta_deg, density) pair
        For a mixture, the density of ``atan(p)`` with one slope component
        ``p ~ Σ w_i N(0, s_i²)``, ``s_i = tan(sd_deg_i)``. A tabulated pair (signed
        degrees, density per any unit) is interpolated linearly, zero outside, and
        normalised to unit integral per radian.
    theta_m_deg : array_like
        Signed tilt in degrees (−90, 90).

    Returns
    -------
    ndarray, shape of ``theta_m_deg``

    Examples
    --------
    >>> th = np.linspace(-89.99, 89.99, 20001)
    >>> f = inplane_tilt_density(NDFMixture([(0.6, 3.0), (0.4, 9.0)]), th)
    >>> round(float(np.trapezoid(f, np.deg2rad(th))), 6)
    1.0
    """
    th = np.asarray(theta_m_deg, dtype=np.float64)
    if isinstance(ndf, NDFMixture):
        t = np.tan(th * _DEG)[..., None]
        s = ndf.slope_sd
        with np.errstate(over="ignore", invalid="ignore"):
            p = ndf.weights * np.exp(-0.5 * (t / s) ** 2) / (s * math.sqrt(2 * math.pi))
            p = np.sum(p, axis=-1) * (1.0 + t[..., 0] ** 2)
        return np.where(np.abs(th) < 90, np.nan_to_num(p, nan=0.0, posinf=0.0), 0.0) + th * 0
    if isinstance(ndf, tuple) and len(ndf) == 2:
        g = np.asarray(ndf[0], dtype=np.float64)
        p = np.asarray(ndf[1], dtype=np.float64)
        if g.ndim != 1 or p.shape != g.shape or g.size < 2 or np.any(np.diff(g) <= 0):
            raise ValueError("ndf: a tabulated tilt density needs increasing 1-D theta_deg "
                             "and a density of the same length >= 2")
        if not (np.all(np.isfinite(p)) and np.all(p >= 0)) or np.any(np.abs(g) > 90):
            raise ValueError("ndf: tabulated density must be finite, >= 0, |theta| <= 90")
        mass = float(np.sum(p * trapezoid_weights(g * _DEG)))
        if not mass > 0:
            raise ValueError("ndf: the tabulated density has no mass")
        return np.interp(th, g, p / mass, left=0.0, right=0.0) + th * 0
    raise ValueError(f"ndf: expected an NDFMixture or a (theta_deg, density) pair, got "
                     f"{type(ndf).__name__}")


def theta_m_grid(ndf, step_deg):
    """``(θ_m, f, step)``: the midpoint grid of eq. 6's facet tilts (degrees) where the
    in-plane tilt density f carries mass, and the step."""
    if not (math.isfinite(step_deg) and 0 < step_deg <= 5):
        raise ValueError(f"theta_m_step_deg: must be in (0, 5], got {step_deg!r}")
    n = int(round(180.0 / step_deg))
    step = 180.0 / n
    grid = -90.0 + step * (np.arange(n) + 0.5)  # midpoints: never ±90
    f = inplane_tilt_density(ndf, grid)
    keep = f > 1e-10 * np.max(f)
    return grid[keep], f[keep], step


@dataclass
class Eq6Kernel:
    """Eq. 6 for a fixed set of in-plane direction pairs, reusable for any exponent n.

    The n-independent part of each term is stored once:
    ``R(n) = Σ_k base[s, k] · lobe[s, k]^n · ⟨R⟩(|θ_in + θ_m,k|)``, so fitting n costs
    one weighted sum per trial, and colours use the (T, 3) XYZ table instead of spectra.

    Build with :meth:`build`; evaluate with :meth:`spectra` or :meth:`xyz`.
    """

    shape: tuple
    base: np.ndarray      # (S, K) f Δθ c(θ_in+θ_m) c(θ_out−θ_m), 0 where the lobe is
    log_lobe: np.ndarray  # (S, K) log c(θ_out − θ_in − 2θ_m) (0 where base is 0)
    index: np.ndarray     # (S, K) row of the film table at |θ_in + θ_m|
    film: FilmAverage
    nan: np.ndarray       # (S,) NaN inputs

    @classmethod
    def build(cls, theta_in_deg, theta_out_deg, *, thickness, ndf, wavelength_nm=None,
              film=DEFAULT_FILM, substrate=DEFAULT_SUBSTRATE, n_ambient=1.0,
              theta_m_step_deg=0.5):
        """Tabulate everything eq. 6 needs for these angle pairs (see :func:`eq6_reflectance`)."""
        ti = signed_angles(theta_in_deg, "theta_in_deg")
        to = signed_angles(theta_out_deg, "theta_out_deg")
        ti, to = np.broadcast_arrays(ti, to)
        shape = ti.shape
        ti = ti.ravel()
        to = to.ravel()
        nan = ~(np.isfinite(ti) & np.isfinite(to))
        ti = np.where(nan, 0.0, ti)
        to = np.where(nan, 0.0, to)
        tm, f, step = theta_m_grid(ndf, float(theta_m_step_deg))
        alpha = ti[:, None] + tm[None, :]                  # incidence on the facet (signed)
        c_in = np.cos(alpha * _DEG)
        c_out = np.cos((to[:, None] - tm[None, :]) * _DEG)
        c_lobe = np.cos((to[:, None] - ti[:, None] - 2 * tm[None, :]) * _DEG)
        live = (c_in > 0) & (c_out > 0) & (c_lobe > 0) & (np.abs(alpha) < 90)
        base = np.where(live, f[None, :] * (step * _DEG) * c_in * c_out, 0.0)
        with np.errstate(divide="ignore"):
            log_lobe = np.where(live, np.log(np.where(live, c_lobe, 1.0)), 0.0)
        # Keep only the tilts that contribute to some pair.
        cols = np.any(live, axis=0)
        base, log_lobe, alpha = base[:, cols], log_lobe[:, cols], alpha[:, cols]
        a = np.where(live[:, cols], np.abs(alpha), np.nan)
        fa = FilmAverage.build(a, thickness, wavelength_nm=wavelength_nm, film=film,
                               substrate=substrate, n_ambient=n_ambient)
        if fa.exact:
            index = np.searchsorted(fa.theta_deg, np.where(np.isfinite(a), a, fa.theta_deg[0]))
            index = np.minimum(index, fa.theta_deg.size - 1)
        else:  # nearest node of the fine table (0.05°): pairs off the grid
            i, fr, _ = fa.index_of(a)
            index = np.where(fr > 0.5, i + 1, i)
        return cls(shape, base, log_lobe, index, fa, nan)

    def weights(self, n):
        """Per-term weights ``base · lobe^n``, shape (S, K)."""
        if not (math.isfinite(n) and n >= 0):
            raise ValueError(f"n: the cosine-lobe exponent must be finite and >= 0, got {n!r}")
        return self.base * np.exp(n * self.log_lobe)

    def _matrix(self, n):
        """Scatter the term weights onto film-table rows: A (S, T), ``R = A @ ⟨R⟩``."""
        w = self.weights(n)
        T = self.film.theta_deg.size
        S = w.shape[0]
        flat = (np.arange(S)[:, None] * T + self.index).ravel()
        return np.bincount(flat, weights=w.ravel(), minlength=S * T).reshape(S, T)

    def spectra(self, n):
        """Eq. 6 spectra, shape ``shape + (N,)``."""
        out = self._matrix(n) @ self.film.spectra
        out[self.nan] = np.nan
        return out.reshape(self.shape + (out.shape[-1],))

    def xyz(self, n, *, illuminant=DEFAULT_ILLUMINANT, observer=DEFAULT_OBSERVER, table_xyz=None):
        """Eq. 6 XYZ (perfect reflector Y = 1), shape ``shape + (3,)``.

        ``table_xyz`` (T, 3): the film table's XYZ, if already computed (fitting loops).
        """
        tx = self.film.xyz(illuminant=illuminant, observer=observer) if table_xyz is None \
            else table_xyz
        out = self._matrix(n) @ tx
        out[self.nan] = np.nan
        return out.reshape(self.shape + (3,))


def eq6_reflectance_inplane(theta_in_deg, theta_out_deg, *, thickness, ndf, n,
                            wavelength_nm=None, film=DEFAULT_FILM,
                            substrate=DEFAULT_SUBSTRATE, n_ambient=1.0,
                            theta_m_step_deg=0.5):
    """Seed eq. 6 spectra for in-plane light and view zenith angles.

    Parameters
    ----------
    theta_in_deg, theta_out_deg : array_like
        Light and view zenith angles in degrees (−90, 90); view positive on the mirror
        side (θ_out = θ_in is specular). They broadcast (S).
    thickness : float, ThicknessMixture or (d_nm, density)
        g(d) (see :func:`thickness_nodes`).
    ndf : NDFMixture or (theta_deg, density)
        f(θ_m) (see :func:`inplane_tilt_density`).
    n : float
        Cosine-lobe exponent, ≥ 0.
    wavelength_nm : array_like (N,), optional
    theta_m_step_deg : float
        Step of the θ_m sum (midpoint rule on (−90°, 90°)), default 0.5°: the one step that
        holds ≤ 0.003 ΔE00 up to n = 5000, the top of ``fit_eq6``'s scan
        (docs/speed-vs-error.md §5).

    Returns
    -------
    ndarray, shape S + (N,)
        The double sum of the module docstring (arbitrary overall scale); NaN where an
        angle is NaN.

    Seed
    ----
    §3.4, eq. (6); the interpretation of its cosine terms is in the module docstring.

    Examples
    --------
    >>> R = eq6_reflectance_inplane([10, 30], 30.0, thickness=130.0,
    ...                             ndf=NDFMixture([(1.0, 5.0)]), n=50, wavelength_nm=[550])
    >>> R.shape, bool(R[1, 0] > R[0, 0])
    ((2, 1), True)
    """
    k = Eq6Kernel.build(theta_in_deg, theta_out_deg, thickness=thickness, ndf=ndf,
                        wavelength_nm=wavelength_nm, film=film, substrate=substrate,
                        n_ambient=n_ambient, theta_m_step_deg=theta_m_step_deg)
    return k.spectra(float(n))


def eq6_reflectance(light, view, **kwargs):
    """Seed eq. 6 for 3-D direction pairs, evaluated in the plane of incidence.

    Eq. 6 is a one-dimensional (in-plane) model; a 3-D pair is reduced to the plane that
    contains both directions and the normal's projection: θ_in and θ_out are the zenith
    angles of light and view, with θ_out signed positive when the view lies on the
    mirror side of the light's plane (``(l_xy · v_xy) ≤ 0``). Out-of-plane pairs are thus
    treated as if in-plane — eq. 6 carries no azimuthal information.

    Parameters
    ----------
    light, view : array_like (..., 3)
    **kwargs
        As :func:`eq6_reflectance_inplane` (``thickness``, ``ndf``, ``n`` …).

    Returns
    -------
    ndarray, shape broadcast + (N,)
    """
    lu = unit_directions(light, "light")
    vu = unit_directions(view, "view")
    lu, vu = np.broadcast_arrays(lu, vu)
    if np.any(lu[..., 2] <= 0) or np.any(vu[..., 2] <= 0):
        raise ValueError("light, view: directions must be above the surface (z > 0)")
    ti = np.rad2deg(np.arccos(np.clip(lu[..., 2], -1, 1)))
    tv = np.rad2deg(np.arccos(np.clip(vu[..., 2], -1, 1)))
    mirror = np.sum(lu[..., :2] * vu[..., :2], axis=-1) <= 0
    return eq6_reflectance_inplane(ti, np.where(mirror, tv, -tv), **kwargs)
