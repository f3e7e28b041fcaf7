"""Angular colour maps (seed Figs. 5, 10, 20), colour-difference maps and fitting.

An angular map is a grid of in-plane light zenith angles θ_light (rows, L) × view zenith
angles θ_view (columns, V), view positive on the mirror side (θ_view = θ_light is the
specular direction; conventions of :mod:`microfacet.forward.halfvector`). Each cell holds a
reflectance spectrum, its CIE XYZ (perfect reflector Y = 1), CIELAB (relative to the
perfect white diffuser under the illuminant) and an sRGB display colour.

Models (:func:`simulate_map`)
    ``"half-vector"`` — the film at θ_d averaged over g(d) (seed §2.3, eq. 5);
    ``"microfacet"`` — the reflectance factor π f_r of
    :func:`~microfacet.forward.brdf.microfacet_brdf`
    (what a gonio-spectrophotometer reports relative to a white diffuser);
    ``"eq6"`` — :func:`microfacet.forward.brdf.eq6_reflectance_inplane` (arbitrary scale).
    Every map is multiplied by ``exposure`` before colours are computed.

Display exposure (:func:`display_exposure`)
    One rule for every picture of a map (``microfacet simulate`` and the report): a
    half-vector map is shown at exposure 1 (a white diffuser is white); a microfacet or eq. 6
    map, whose specular peak and grazing rise are far above 1, is scaled so that the 98th
    percentile of Y over light and view angles up to :data:`DISPLAY_CORE_DEG` is 0.9 of white.

References
----------
.. [1] N. Nagata, M. Kamei, K. Takahashi, K. Tobitani, T. Akagi, S. Yamamura, "Simulation
   Technology for Titanium Oxide Layer Interference Color", Technical Report (the seed paper),
   Figs. 5, 10 and 20 (angular colour distributions).
.. [2] CIE 015:2018, *Colorimetry*, 4th ed., CIE, Vienna (2018), doi:10.25039/TR.015.2018.
.. [3] B. Walter, S. R. Marschner, H. Li, K. E. Torrance, "Microfacet models for refraction
   through rough surfaces", Eurographics Symposium on Rendering (2007) 195-206,
   doi:10.2312/EGWR/EGSR07/195-206.
"""

from __future__ import annotations

import math
import time

import numpy as np

from ..colour.srgb import colours_from_spectra
from ..core.angular import AngularMap
from ..core.defaults import DEFAULT_ILLUMINANT, DEFAULT_OBSERVER
from ..io.angular_map import check_angles
from ..optics.constants import DEFAULT_FILM, DEFAULT_SUBSTRATE
from . import brdf, eq6
from .halfvector import half_angle_deg

__all__ = ["DISPLAY_CORE_DEG", "display_exposure", "film_average_inplane", "simulate_map",
           "simulate_memory_bytes", "with_exposure"]

MODELS = ("microfacet", "eq6", "half-vector")
#: Light and view angles up to this set the display scale of a microfacet or eq. 6 map.
DISPLAY_CORE_DEG = 60.0


def positive(x, name):
    """``float(x)``, which must be finite and > 0; a ValueError names ``name``."""
    try:
        v = float(x)
    except (TypeError, ValueError):
        raise ValueError(f"{name}: expected a number, got {x!r}") from None
    if not (math.isfinite(v) and v > 0):
        raise ValueError(f"{name}: must be finite and > 0, got {x!r}")
    return v


def simulate_memory_bytes(*, model: str, n_light: int, n_view: int, n_wavelengths: int,
                          max_tilt_deg: float = 60.0, theta_m_step_deg: float = 0.5) -> float:
    """Rough peak memory of :func:`simulate_map` for a grid (bytes), to refuse before
    allocating.

    The spectra (L·V·N float64) and their lookup temporaries dominate the microfacet and
    half-vector models; eq. 6 adds per-pair tables over the θ_m grid and a pair × table-row
    matrix (up to 4096 rows).
    """
    cells = float(n_light) * float(n_view)
    need = 8.0 * cells * n_wavelengths * 6
    if model == "eq6":
        k = 2.0 * max_tilt_deg / max(theta_m_step_deg, 1e-3) + 1
        need += 8.0 * cells * (k * 6 + 4096)
    return need + (64 << 20)


def simulate_map(*, model="microfacet", thickness, ndf=None, n=None, theta_light_deg=None,
                 theta_view_deg=None, exposure=1.0, wavelength_nm=None, film=DEFAULT_FILM,
                 substrate=DEFAULT_SUBSTRATE, illuminant=DEFAULT_ILLUMINANT,
                 observer=DEFAULT_OBSERVER, n_ambient=1.0,
                 theta_m_step_deg=0.5, film_average=None) -> AngularMap:
    """Angular map of a forward model over an in-plane (θ_light, θ_view) grid.

    Parameters
    ----------
    model : {"microfacet", "eq6", "half-vector"}
    thickness : float, ThicknessMixture or (d_nm, density)
        Oxide thickness density g(d).
    ndf : NDFMixture (or, for eq6, a (theta_deg, density) pair)
        Required by "microfacet" and "eq6".
    n : float
        Cosine-lobe exponent of eq. 6 (required by "eq6").
    theta_light_deg, theta_view_deg : array_like (L,), (V,)
        Default 0-89° in 1° steps.
    exposure : float
        Scale applied to the spectra before colours.
    wavelength_nm : array_like (N,), optional
        Default 380-780 nm in 5 nm steps.
    film_average : brdf.FilmAverage, optional
        The film's reflectance averaged over ``thickness`` at the grid's half angles
        (:func:`film_average_inplane`), which the half-vector and microfacet maps of one
        thickness share: given, it is not built again (its wavelengths must be
        ``wavelength_nm``; the caller vouches for its thickness and optics). Eq. 6 reads the
        film at other angles and builds its own.

    Returns
    -------
    AngularMap
        With spectra (L, V, N), xyz, lab, srgb; ``meta["timings_s"]``.

    Seed
    ----
    Fig. 10 (half-vector model), Fig. 20a (microfacet model, eq. 6).

    Examples
    --------
    >>> from microfacet.core.distributions import NDFMixture
    >>> m = simulate_map(model="microfacet", thickness=51.0, ndf=NDFMixture([(1.0, 8.0)]),
    ...                  theta_light_deg=[0, 30], theta_view_deg=[0, 30, 60])
    >>> m.lab.shape, m.spectra.shape
    ((2, 3, 3), (2, 3, 81))
    """
    if model not in MODELS:
        raise ValueError(f"model: expected one of {', '.join(MODELS)}, got {model!r}")
    exposure = positive(exposure, "exposure")
    tl = check_angles(np.arange(90.0) if theta_light_deg is None else theta_light_deg,
               "theta_light_deg")
    tv = check_angles(np.arange(90.0) if theta_view_deg is None else theta_view_deg,
               "theta_view_deg")
    wl = brdf.wavelength_grid(wavelength_nm)
    opt = dict(film=film, substrate=substrate, n_ambient=n_ambient)
    t0 = time.perf_counter()
    TL, TV = tl[:, None], tv[None, :]
    if model in ("half-vector", "microfacet"):
        if model == "microfacet" and ndf is None:
            raise ValueError("ndf: the microfacet model needs an NDF")
        fa = _film_average(film_average, tl, tv, thickness, wl, opt)
    if model == "half-vector":
        spectra = fa.lookup(np.broadcast_to(half_angle_deg(TL, TV), (tl.size, tv.size)))
    elif model == "microfacet":
        # ⟨R⟩ at θ_d: the half angles (the directions' θ_d equal them to ~1e-14°, but
        # rounding makes 426 distinct values of the report's 171, each evaluated)
        spectra = math.pi * brdf.microfacet_brdf_inplane(TL, TV, thickness=thickness, ndf=ndf,
                                                         wavelength_nm=wl, film_average=fa,
                                                         **opt)
    else:
        if ndf is None:
            raise ValueError("ndf: eq. 6 needs an NDF")
        if n is None:
            raise ValueError("n: eq. 6 needs the cosine-lobe exponent")
        spectra = eq6.eq6_reflectance_inplane(TL, TV, thickness=thickness, ndf=ndf, n=n,
                                               wavelength_nm=wl,
                                               theta_m_step_deg=theta_m_step_deg, **opt)
    t1 = time.perf_counter()
    spectra = exposure * spectra
    xyz, lab, srgb, _ = colours_from_spectra(spectra, wl, illuminant=illuminant,
                                             observer=observer)
    t2 = time.perf_counter()
    meta = {"model": model, "exposure": exposure, "film": str(film),
            "substrate": str(substrate), "timings_s": {"spectra": t1 - t0, "colour": t2 - t1}}
    if model == "eq6":
        meta["n"] = float(n)
    return AngularMap(tl, tv, lab, xyz, srgb, spectra, wl, illuminant, str(observer), meta)


def film_average_inplane(theta_light_deg, theta_view_deg, *, thickness, wavelength_nm=None,
                         film=DEFAULT_FILM, substrate=DEFAULT_SUBSTRATE, n_ambient=1.0):
    """The film's reflectance averaged over ``thickness`` at the half angles of an in-plane
    (θ_light, θ_view) grid (:class:`~microfacet.forward.brdf.FilmAverage`): what
    :func:`simulate_map`'s half-vector and microfacet maps of that grid read; built once, it
    serves both (its ``film_average``).

    Examples
    --------
    >>> fa = film_average_inplane([0, 30], [0, 30, 60], thickness=51.0,
    ...                           wavelength_nm=[450, 550, 650])
    >>> fa.theta_deg.tolist(), fa.spectra.shape
    ([0.0, 15.0, 30.0, 45.0], (4, 3))
    """
    tl = check_angles(theta_light_deg, "theta_light_deg")
    tv = check_angles(theta_view_deg, "theta_view_deg")
    return _film_average(None, tl, tv, thickness, brdf.wavelength_grid(wavelength_nm),
                         dict(film=film, substrate=substrate, n_ambient=n_ambient))


def _film_average(given, tl, tv, thickness, wl, opt):
    """``given`` (its wavelengths checked against ``wl``) or the film average built at the
    half angles of the grid ``tl`` × ``tv``."""
    if given is not None:
        if not np.array_equal(given.wavelength_nm, wl):
            raise ValueError("film_average: built at other wavelengths than wavelength_nm")
        return given
    th_d = half_angle_deg(tl[:, None], tv[None, :])
    return brdf.FilmAverage.build(th_d, thickness, wavelength_nm=wl, **opt)


def display_exposure(m: AngularMap, *, core_deg=DISPLAY_CORE_DEG) -> float:
    """The exposure to show map ``m`` at (see the module notes): 1 for a half-vector map,
    else 0.9 / (98th percentile of Y over light and view angles ≤ ``core_deg``).

    ``m`` must have been simulated at exposure 1 (its ``xyz`` with the perfect reflector at
    Y = 1).

    Examples
    --------
    >>> from microfacet.core.distributions import NDFMixture
    >>> m = simulate_map(model="microfacet", thickness=51.0, ndf=NDFMixture([(1.0, 8.0)]),
    ...                  theta_light_deg=np.arange(0, 61, 10.0),
    ...                  theta_view_deg=np.arange(0, 61, 10.0))
    >>> e = display_exposure(m)
    >>> y = with_exposure(m, e).xyz[..., 1].ravel()
    >>> round(float(np.percentile(y, 98)), 3)
    0.9
    """
    if m.meta.get("model") == "half-vector":
        return 1.0
    tl = np.abs(m.theta_light_deg) <= core_deg + 1e-9
    tv = np.abs(m.theta_view_deg) <= core_deg + 1e-9
    y = np.asarray(m.xyz)[np.ix_(tl, tv)][..., 1]
    y = y[np.isfinite(y)]
    p98 = float(np.percentile(y, 98)) if y.size else 0.0
    return 0.9 / p98 if p98 > 0 else 1.0


def with_exposure(m: AngularMap, exposure: float) -> AngularMap:
    """A copy of map ``m`` (simulated at exposure 1) with its spectra and colours scaled."""
    spectra = m.spectra * exposure
    xyz, lab, srgb, _ = colours_from_spectra(spectra, m.wavelength_nm, illuminant=m.illuminant,
                                             observer=m.observer)
    return AngularMap(m.theta_light_deg, m.theta_view_deg, lab, xyz, srgb, spectra,
                      m.wavelength_nm, m.illuminant, m.observer,
                      {**m.meta, "exposure": float(exposure)})
