"""Half-vector thin-film interference model (seed §2.3-2.4).

On an optically rough surface, the facets that send light from the light direction ``l``
into the view direction ``v`` are those whose normal is the half vector
``h = (l + v) / |l + v|``. They reflect specularly, so the film is seen at the incidence
angle

    θ_d = ½ ∠(l, v) = ½ arccos(l · v),

and the colour is that of the thin film at θ_d (seed eq. 5). In the plane of incidence,
with both zenith angles measured from the macroscopic normal and the view angle counted
positive on the mirror side (so θ_view = θ_light is the specular direction),
``l = (−sin θ_light, 0, cos θ_light)``, ``v = (sin θ_view, 0, cos θ_view)`` and

    θ_d = |θ_light + θ_view| / 2,   tilt of h = (θ_view − θ_light) / 2.

This module gives θ_d for in-plane angles and for 3-D unit vectors and the reflectance
spectra there; angular colour maps like the seed's Fig. 10 are
``simulate_map(model="half-vector")`` (:mod:`microfacet.forward.angular`).

References
----------
.. [1] N. Nagata, M. Kamei, K. Takahashi, K. Tobitani, T. Akagi, S. Yamamura, "Simulation
   Technology for Titanium Oxide Layer Interference Color", Technical Report (the seed paper),
   §2.3-2.4, eq. (5), Figs. 9-10.
.. [2] H. Fujii, K. Tobitani, Y. Tani, M. Kamei, N. Nagata, T. Akagi, K. Takahashi, S. Yamamura,
   "Color of Oxide Layered Coating on Titanium Considering Interference from Fine Structure",
   IEICE Trans. Inf. & Syst. (Japanese ed.) J102-D(6) (2019) 464-472,
   doi:10.14923/transinfj.2018JDP7030 (the half-vector model; the seed's ref. 1).
.. [3] B. Walter, S. R. Marschner, H. Li, K. E. Torrance, "Microfacet models for refraction
   through rough surfaces", Eurographics Symposium on Rendering (2007) 195-206,
   doi:10.2312/EGWR/EGSR07/195-206 (the half vector).
"""

from __future__ import annotations

import numpy as np

from ..optics.constants import DEFAULT_FILM, DEFAULT_SUBSTRATE
from ..optics.thinfilm import reflectance

__all__ = ["half_angle_deg", "half_angle_from_vectors", "half_vector", "in_plane_directions",
           "spectra"]


def signed_angles(x, name):
    """``x`` as a float array of angles in (-90, 90) degrees (NaN kept); ValueError names
    ``name``."""
    a = np.asarray(x, dtype=np.float64)
    if np.any(np.isinf(a)) or np.any(np.abs(a) >= 90):
        raise ValueError(f"{name}: zenith angles must satisfy -90 < theta < 90 degrees")
    return a


def half_angle_deg(theta_light_deg, theta_view_deg):
    """θ_d for in-plane light and view zenith angles (seed eq. 5).

    Parameters
    ----------
    theta_light_deg, theta_view_deg : array_like
        Zenith angles in degrees, ``-90 < θ < 90``, in the plane of incidence; the view
        angle is positive on the mirror side of the normal (θ_view = θ_light is specular).

    Returns
    -------
    ndarray
        ``|θ_light + θ_view| / 2`` in degrees, the broadcast shape.

    Examples
    --------
    >>> float(half_angle_deg(10.0, 45.0))
    27.5
    """
    tl = signed_angles(theta_light_deg, "theta_light_deg")
    tv = signed_angles(theta_view_deg, "theta_view_deg")
    return np.abs(tl + tv) / 2.0


def in_plane_directions(theta_light_deg, theta_view_deg):
    """Unit light and view vectors (z = macroscopic normal) for in-plane zenith angles.

    Returns
    -------
    light, view : ndarray, shape broadcast + (3,)
    """
    tl = np.deg2rad(signed_angles(theta_light_deg, "theta_light_deg"))
    tv = np.deg2rad(signed_angles(theta_view_deg, "theta_view_deg"))
    tl, tv = np.broadcast_arrays(tl, tv)
    zero = np.zeros_like(tl)
    light = np.stack([-np.sin(tl), zero, np.cos(tl)], axis=-1)
    view = np.stack([np.sin(tv), zero, np.cos(tv)], axis=-1)
    return light, view


def _unit(v, name):
    v = np.asarray(v, dtype=np.float64)
    if v.shape[-1:] != (3,):
        raise ValueError(f"{name}: expected an array of 3-vectors (..., 3), got shape {v.shape}")
    norm = np.linalg.norm(v, axis=-1, keepdims=True)
    if np.any(norm == 0):
        raise ValueError(f"{name}: zero-length direction vector")
    return v / norm


def half_vector(light, view):
    """Unit half vector ``(l + v)/|l + v|`` of unit (or unnormalised) directions (..., 3).

    Where light and view are exactly opposite the half vector is undefined (NaN).
    """
    h = _unit(light, "light") + _unit(view, "view")
    norm = np.linalg.norm(h, axis=-1, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(norm > 0, h / norm, np.nan)


def half_angle_from_vectors(light, view):
    """θ_d = ½ ∠(light, view) in degrees for 3-D directions (..., 3) pointing away from the
    surface.

    Uses ``2·atan2(|l − v|, |l + v|)`` for the angle, which is accurate at all angles
    (``arccos`` of the dot product loses precision near 0°).

    Examples
    --------
    >>> float(half_angle_from_vectors([0, 0, 1], [1, 0, 1]))
    22.5
    """
    lu = _unit(light, "light")
    vu = _unit(view, "view")
    ang = 2.0 * np.arctan2(np.linalg.norm(lu - vu, axis=-1), np.linalg.norm(lu + vu, axis=-1))
    return np.rad2deg(ang) / 2.0


def spectra(theta_light_deg, theta_view_deg, thickness_nm, *, wavelength_nm=None,
            film=DEFAULT_FILM, substrate=DEFAULT_SUBSTRATE, n_ambient=1.0):
    """Half-vector reflectance spectra R(λ; θ_d, d) for in-plane light and view angles.

    Parameters
    ----------
    theta_light_deg, theta_view_deg, thickness_nm : array_like
        Broadcast against each other (leading shape S).
    wavelength_nm : array_like (N,), optional
        Default 380-780 nm in 5 nm steps.

    Returns
    -------
    wavelength_nm : ndarray (N,)
    R : ndarray, shape S + (N,)
    """
    wl = (np.arange(380.0, 781.0, 5.0) if wavelength_nm is None
          else np.asarray(wavelength_nm, dtype=np.float64))
    th = half_angle_deg(theta_light_deg, theta_view_deg)
    d = np.asarray(thickness_nm, dtype=np.float64)
    th, d = np.broadcast_arrays(th, d)
    R = reflectance(wl, th[..., None], d[..., None], film, substrate, n_ambient=n_ambient)
    return wl, R
