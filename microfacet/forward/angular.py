"""Angular colour maps (seed Figs. 5, 10, 20), colour-difference maps and fitting.

An angular map is a grid of in-plane light zenith angles θ_light (rows, L) × view zenith
angles θ_view (columns, V), view positive on the mirror side (θ_view = θ_light is the
specular direction; conventions of :mod:`microfacet.forward.halfvector`). Each cell holds a
reflectance spectrum, its CIE XYZ (perfect reflector Y = 1), CIELAB (relative to the
perfect white diffuser under the illuminant) and an sRGB display colour.

Models (:func:`simulate_map`)
    ``"half-vector"`` — the film at θ_d averaged over g(d) (seed §2.3, eq. 5);
    ``"microfacet"`` — the reflectance factor π f_r of :func:`microfacet.forward.brdf.microfacet_brdf`
    (what a gonio-spectrophotometer reports relative to a white diffuser);
    ``"eq6"`` — :func:`microfacet.forward.brdf.eq6_reflectance_inplane` (arbitrary scale).
    Every map is multiplied by ``exposure`` before colours are computed.

Comparison (seed §2.5 Table 2 and §3.5 Fig. 20)
    :func:`delta_e_map` gives the CIEDE2000 difference per cell; :func:`mean_delta_e` the
    mean over all cells and the mean outside the **specular region**
    ``|θ_view − θ_light| ≤ specular_halfwidth_deg`` (default 10°, a band about the mirror
    direction; the half-vector tilt is then ≤ 5°). The seed's half-vector evaluation
    excluded that region; its microfacet evaluation used all cells. Cells where either
    map is NaN (masked measurements) are left out of both means and counted.

Map file format ``microfacet-angular/1`` (:func:`save_map`, :func:`load_map`)
    One NumPy ``.npz`` with

    ================  ==============  ====================================================
    key               shape / type    meaning
    ================  ==============  ====================================================
    format            str             ``"microfacet-angular/1"``
    theta_light_deg   (L,) float      light zenith angles, degrees, −90 < θ < 90
    theta_view_deg    (V,) float      view zenith angles, positive on the mirror side
    lab               (L, V, 3)       CIELAB; required unless ``spectra`` is given
    spectra           (L, V, N)       reflectance factor (1 = white diffuser), optional
    wavelength_nm     (N,)            required with ``spectra``
    illuminant        str             default ``"D65"`` (for Lab from spectra)
    observer          str             ``"2"`` or ``"10"``, default ``"2"``
    ================  ==============  ====================================================

    If both ``lab`` and ``spectra`` are present, ``lab`` is used for comparisons. NaN
    marks cells not measured. ``xyz`` and ``srgb`` may also be stored (ignored on read).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..optics.constants import DEFAULT_FILM, DEFAULT_SUBSTRATE
from ..colour.colorimetry import lab_to_xyz, spectral_weights, white_xyz, xyz_to_lab
from ..colour.difference import delta_e_2000
from ..colour.srgb import model_xyz_to_linear_srgb, srgb_encode

__all__ = [
    "AngularMap",
    "Eq6Fit",
    "MAP_FORMAT",
    "MODELS",
    "colours_from_spectra",
    "delta_e_map",
    "fit_eq6",
    "fit_exposure",
    "load_map",
    "mean_delta_e",
    "plot_maps",
    "save_map",
    "simulate_map",
    "specular_mask",
]

MAP_FORMAT = "microfacet-angular/1"
MODELS = ("microfacet", "eq6", "half-vector")


@dataclass
class AngularMap:
    """Colours (and optionally spectra) over a (θ_light, θ_view) grid.

    Attributes
    ----------
    theta_light_deg : ndarray (L,)
    theta_view_deg : ndarray (V,)
    lab : ndarray (L, V, 3) float32
    xyz : ndarray (L, V, 3) or None
        Perfect reflector Y = 1 (exposure applied).
    srgb : ndarray (L, V, 3) uint8 or None
        Display image (rows = light angle, columns = view angle).
    spectra : ndarray (L, V, N) or None
        Reflectance (factor), exposure applied.
    wavelength_nm : ndarray (N,) or None
    illuminant, observer : str
    meta : dict
        Model name, parameters, exposure.
    """

    theta_light_deg: np.ndarray
    theta_view_deg: np.ndarray
    lab: np.ndarray
    xyz: np.ndarray | None = None
    srgb: np.ndarray | None = None
    spectra: np.ndarray | None = None
    wavelength_nm: np.ndarray | None = None
    illuminant: str = "D65"
    observer: str = "2"
    meta: dict = field(default_factory=dict)

    @property
    def shape(self):
        return (self.theta_light_deg.size, self.theta_view_deg.size)

    def save_png(self, path, *, scale=4):
        """Write the sRGB image, each cell ``scale`` × ``scale`` pixels, light angle down."""
        from ..io.images import write_image

        img = self.srgb if self.srgb is not None else _lab_to_srgb8(self.lab, self.illuminant,
                                                                    self.observer)
        write_image(path, np.repeat(np.repeat(img, int(scale), axis=0), int(scale), axis=1))


def _lab_to_srgb8(lab, illuminant, observer):
    xyz = lab_to_xyz(np.nan_to_num(np.asarray(lab, np.float64)),
                           white=white_xyz(illuminant=illuminant, observer=observer))
    rgb = model_xyz_to_linear_srgb(xyz, white=white_xyz(illuminant=illuminant,
                                                                    observer=observer),
                                         illuminant=illuminant, observer=observer)
    return srgb_encode(rgb, dtype=np.uint8)


def _grid(x, name):
    a = np.atleast_1d(np.asarray(x, dtype=np.float64))
    if a.ndim != 1 or a.size == 0:
        raise ValueError(f"{name}: expected a non-empty 1-D array of angles")
    if not np.all(np.isfinite(a)) or np.any(np.abs(a) >= 90):
        raise ValueError(f"{name}: angles must be finite and in (-90, 90) degrees")
    return a


def colours_from_spectra(spectra, wavelength_nm, *, exposure=1.0, illuminant="D65",
                         observer="2"):
    """XYZ, CIELAB and sRGB of reflectance spectra.

    Parameters
    ----------
    spectra : array_like (..., N)
        Reflectance (factor); multiplied by ``exposure``.
    wavelength_nm : array_like (N,)

    Returns
    -------
    xyz : ndarray (..., 3)
        Perfect reflector Y = 1.
    lab : ndarray (..., 3) float32
        Relative to the perfect reflector on this wavelength grid.
    srgb : ndarray (..., 3) uint8
        White-balanced to the illuminant, clipped.
    white : ndarray (3,)

    Examples
    --------
    >>> wl = np.arange(380.0, 781.0, 10.0)
    >>> xyz, lab, rgb, white = colours_from_spectra(np.ones(wl.size), wl)
    >>> [round(float(v), 3) for v in lab], rgb.tolist()
    ([100.0, 0.0, 0.0], [255, 255, 255])
    """
    _positive(exposure, "exposure")
    wl = np.asarray(wavelength_nm, dtype=np.float64)
    R = np.asarray(spectra, dtype=np.float64)
    if R.shape[-1:] != wl.shape:
        raise ValueError(f"spectra: last axis ({R.shape[-1:]}) must match wavelength_nm "
                         f"({wl.shape})")
    W = spectral_weights(wl, illuminant=illuminant, observer=observer)
    white = W.sum(axis=0)
    xyz = float(exposure) * (R @ W)
    lab = xyz_to_lab(xyz, white=white).astype(np.float32)
    rgb = model_xyz_to_linear_srgb(xyz, white=white, illuminant=illuminant,
                                         observer=observer)
    srgb = srgb_encode(np.nan_to_num(rgb), dtype=np.uint8)
    return xyz, lab, srgb, white


def _positive(x, name):
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
                 substrate=DEFAULT_SUBSTRATE, illuminant="D65", observer="2", n_ambient=1.0,
                 theta_m_step_deg=0.5) -> AngularMap:
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
    import time

    from . import brdf

    if model not in MODELS:
        raise ValueError(f"model: expected one of {', '.join(MODELS)}, got {model!r}")
    exposure = _positive(exposure, "exposure")
    tl = _grid(np.arange(90.0) if theta_light_deg is None else theta_light_deg,
               "theta_light_deg")
    tv = _grid(np.arange(90.0) if theta_view_deg is None else theta_view_deg,
               "theta_view_deg")
    wl = brdf._wavelengths(wavelength_nm)
    opt = dict(film=film, substrate=substrate, n_ambient=n_ambient)
    t0 = time.perf_counter()
    TL, TV = tl[:, None], tv[None, :]
    if model == "half-vector":
        from .halfvector import half_angle_deg

        th_d = np.broadcast_to(half_angle_deg(TL, TV), (tl.size, tv.size))
        fa = brdf.FilmAverage.build(th_d, thickness, wavelength_nm=wl, **opt)
        spectra = fa.lookup(th_d)
    elif model == "microfacet":
        if ndf is None:
            raise ValueError("ndf: the microfacet model needs an NDF")
        spectra = math.pi * brdf.microfacet_brdf_inplane(TL, TV, thickness=thickness, ndf=ndf,
                                                         wavelength_nm=wl, **opt)
    else:
        if ndf is None:
            raise ValueError("ndf: eq. 6 needs an NDF")
        if n is None:
            raise ValueError("n: eq. 6 needs the cosine-lobe exponent")
        spectra = brdf.eq6_reflectance_inplane(TL, TV, thickness=thickness, ndf=ndf, n=n,
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


def specular_mask(theta_light_deg, theta_view_deg, *, halfwidth_deg=10.0):
    """Cells of the specular region ``|θ_view − θ_light| ≤ halfwidth_deg``, shape (L, V).

    Examples
    --------
    >>> specular_mask([0, 40], [0, 45, 60], halfwidth_deg=10).tolist()
    [[True, False, False], [False, True, False]]
    """
    h = float(halfwidth_deg)
    if not (math.isfinite(h) and h >= 0):
        raise ValueError(f"halfwidth_deg: must be finite and >= 0, got {halfwidth_deg!r}")
    tl = np.asarray(theta_light_deg, dtype=np.float64).ravel()
    tv = np.asarray(theta_view_deg, dtype=np.float64).ravel()
    return np.abs(tv[None, :] - tl[:, None]) <= h + 1e-9


def _same_grid(a: AngularMap, b: AngularMap):
    for name in ("theta_light_deg", "theta_view_deg"):
        x, y = getattr(a, name), getattr(b, name)
        if x.shape != y.shape or not np.allclose(x, y, atol=1e-6):
            raise ValueError(f"{name}: the two maps are on different angle grids")


def delta_e_map(predicted: AngularMap, measured: AngularMap):
    """CIEDE2000 difference per cell between two maps on the same angle grid.

    Returns
    -------
    ndarray (L, V) float64
        NaN where either map is NaN.

    Examples
    --------
    >>> m = AngularMap(np.array([0.0]), np.array([0.0, 10.0]), np.full((1, 2, 3), 50.0))
    >>> delta_e_map(m, m).tolist()
    [[0.0, 0.0]]
    """
    _same_grid(predicted, measured)
    return delta_e_2000(np.asarray(predicted.lab, np.float64),
                              np.asarray(measured.lab, np.float64))


def mean_delta_e(delta_e, theta_light_deg, theta_view_deg, *, specular_halfwidth_deg=10.0):
    """The seed's two evaluations: mean ΔE over all cells and outside the specular region.

    Parameters
    ----------
    delta_e : array_like (L, V)
        From :func:`delta_e_map`; NaN cells are left out.
    specular_halfwidth_deg : float
        Specular region ``|θ_view − θ_light| ≤`` this.

    Returns
    -------
    dict
        ``mean`` (all cells), ``mean_excluding_specular``, ``median``, ``max``,
        ``n_cells``, ``n_cells_excluding_specular``, ``specular_halfwidth_deg``
        (means are NaN when no cell is left).
    """
    de = np.asarray(delta_e, dtype=np.float64)
    spec = specular_mask(theta_light_deg, theta_view_deg, halfwidth_deg=specular_halfwidth_deg)
    if de.shape != spec.shape:
        raise ValueError(f"delta_e: shape {de.shape} does not match the angle grids "
                         f"{spec.shape}")
    ok = np.isfinite(de)
    diff = ok & ~spec

    def _mean(mask):
        return float(np.mean(de[mask])) if np.any(mask) else float("nan")

    return {"mean": _mean(ok), "mean_excluding_specular": _mean(diff),
            "median": float(np.median(de[ok])) if np.any(ok) else float("nan"),
            "max": float(np.max(de[ok])) if np.any(ok) else float("nan"),
            "n_cells": int(ok.sum()), "n_cells_excluding_specular": int(diff.sum()),
            "specular_halfwidth_deg": float(specular_halfwidth_deg)}


# --------------------------------------------------------------------------- file format
def save_map(path, m: AngularMap):
    """Write ``m`` in the ``microfacet-angular/1`` .npz format (see the module docstring)."""
    data = {"format": np.array(MAP_FORMAT), "theta_light_deg": m.theta_light_deg,
            "theta_view_deg": m.theta_view_deg, "lab": np.asarray(m.lab, np.float32),
            "illuminant": np.array(m.illuminant), "observer": np.array(str(m.observer))}
    if m.spectra is not None:
        data["spectra"] = np.asarray(m.spectra, np.float32)
        data["wavelength_nm"] = np.asarray(m.wavelength_nm, np.float64)
    if m.xyz is not None:
        data["xyz"] = np.asarray(m.xyz, np.float32)
    with open(path, "wb") as fh:
        np.savez_compressed(fh, **data)


def load_map(path) -> AngularMap:
    """Read a ``microfacet-angular/1`` map (.npz); Lab from spectra if no ``lab`` key.

    Raises
    ------
    ValueError
        Naming the file and the missing or inconsistent key.
    """
    import zipfile

    try:
        z = np.load(path, allow_pickle=False)
    except FileNotFoundError:
        raise
    except (OSError, ValueError, zipfile.BadZipFile) as exc:
        raise ValueError(f"{path}: not a readable .npz angular map ({exc})") from None
    with z:
        keys = set(z.files)
        fmt = str(z["format"]) if "format" in keys else MAP_FORMAT
        if fmt != MAP_FORMAT:
            raise ValueError(f"{path}: format {fmt!r}, expected {MAP_FORMAT!r}")
        for k in ("theta_light_deg", "theta_view_deg"):
            if k not in keys:
                raise ValueError(f"{path}: missing key {k!r}")
        tl = _grid(z["theta_light_deg"], f"{path}: theta_light_deg")
        tv = _grid(z["theta_view_deg"], f"{path}: theta_view_deg")
        ill = str(z["illuminant"]) if "illuminant" in keys else "D65"
        obs = str(z["observer"]) if "observer" in keys else "2"
        spectra = wl = None
        if "spectra" in keys:
            if "wavelength_nm" not in keys:
                raise ValueError(f"{path}: 'spectra' needs 'wavelength_nm'")
            spectra = np.asarray(z["spectra"], np.float64)
            wl = np.asarray(z["wavelength_nm"], np.float64)
            if spectra.shape != (tl.size, tv.size, wl.size):
                raise ValueError(f"{path}: spectra shape {spectra.shape}, expected "
                                 f"{(tl.size, tv.size, wl.size)}")
        if "lab" in keys:
            lab = np.asarray(z["lab"], np.float32)
            if lab.shape != (tl.size, tv.size, 3):
                raise ValueError(f"{path}: lab shape {lab.shape}, expected "
                                 f"{(tl.size, tv.size, 3)}")
            xyz = srgb = None
        elif spectra is not None:
            xyz, lab, srgb, _ = colours_from_spectra(spectra, wl, illuminant=ill, observer=obs)
        else:
            raise ValueError(f"{path}: needs 'lab' or 'spectra' + 'wavelength_nm'")
    return AngularMap(tl, tv, lab, xyz, srgb, spectra, wl, ill, obs, {"source": str(path)})


# ------------------------------------------------------------------------------ fitting
def _mean_de(xyz, white, ref_lab, mask):
    lab = xyz_to_lab(xyz[mask], white=white)
    return float(np.mean(delta_e_2000(lab, ref_lab)))


def fit_exposure(xyz, measured_lab, *, white, mask=None, bounds=(1e-3, 1e3)):
    """Global exposure minimising the mean CIEDE2000 difference to a measured map.

    Parameters
    ----------
    xyz : array_like (..., 3)
        Model XYZ at exposure 1 (scale of ``white``).
    measured_lab : array_like (..., 3)
        Same shape; NaN cells are ignored.
    white : array_like (3,)
        Perfect reflector XYZ the Lab values are relative to.
    mask : array_like of bool (...,), optional
        Cells to use (default all finite).
    bounds : (float, float)
        Search range of the exposure (log-uniform coarse scan, then Brent refinement).

    Returns
    -------
    exposure : float
    mean_delta_e : float
    """
    from scipy.optimize import minimize_scalar

    xyz = np.asarray(xyz, dtype=np.float64)
    ref = np.asarray(measured_lab, dtype=np.float64)
    if xyz.shape != ref.shape:
        raise ValueError(f"measured_lab: shape {ref.shape} does not match xyz {xyz.shape}")
    ok = np.all(np.isfinite(ref), axis=-1) & np.all(np.isfinite(xyz), axis=-1)
    if mask is not None:
        ok &= np.asarray(mask, dtype=bool)
    if not np.any(ok):
        raise ValueError("measured_lab: no finite cells to fit")
    lo, hi = (math.log(_positive(b, "bounds")) for b in bounds)
    if not lo < hi:
        raise ValueError("bounds: need low < high")
    white = np.asarray(white, dtype=np.float64)
    x, r = xyz[ok], ref[ok]

    def cost(le):
        return _mean_de(math.exp(le) * x, white, r, slice(None))

    grid = np.linspace(lo, hi, 33)
    costs = [cost(g) for g in grid]
    k = int(np.argmin(costs))
    a, b = grid[max(k - 1, 0)], grid[min(k + 1, grid.size - 1)]
    res = minimize_scalar(cost, bounds=(a, b), method="bounded", options={"xatol": 1e-5})
    best = (res.x, res.fun) if res.fun <= costs[k] else (grid[k], costs[k])
    return math.exp(best[0]), float(best[1])


@dataclass
class Eq6Fit:
    """Result of :func:`fit_eq6`: exponent, exposure, the mean ΔE reached, the scan."""

    n: float
    exposure: float
    mean_delta_e: float
    scan: list


def fit_eq6(measured: AngularMap, *, thickness, ndf, fit_exposure_too=True, exposure=1.0,
            n_bounds=(0.5, 5000.0), region="all", specular_halfwidth_deg=10.0,
            wavelength_nm=None, film=DEFAULT_FILM, substrate=DEFAULT_SUBSTRATE,
            n_ambient=1.0, theta_m_step_deg=0.5) -> Eq6Fit:
    """Fit eq. 6's cosine-lobe exponent n (and a global exposure) by least mean ΔE00.

    The eq. 6 kernel (:class:`microfacet.forward.brdf.Eq6Kernel`) is built once on the measured
    grid; each trial n is one sparse weighted sum onto the film table's XYZ. n is scanned
    on a log grid over ``n_bounds`` (with the best exposure per n when
    ``fit_exposure_too``), then refined by Brent's method between the scan neighbours.

    Parameters
    ----------
    measured : AngularMap
        The measured map (its Lab; NaN cells ignored). Its illuminant and observer are
        used for the model colours.
    thickness, ndf
        As :func:`simulate_map`.
    fit_exposure_too : bool
        Also fit a global exposure; otherwise ``exposure`` is fixed.
    region : {"all", "diffuse"}
        Fit on all cells or outside the specular region.

    Returns
    -------
    Eq6Fit

    Seed
    ----
    §3.4: n is "a parameter of the cosine lobe model"; §3.5 compares by mean ΔE.
    """
    from scipy.optimize import minimize_scalar

    from . import brdf
    if region not in ("all", "diffuse"):
        raise ValueError(f"region: expected 'all' or 'diffuse', got {region!r}")
    lo, hi = (math.log(_positive(b, "n_bounds")) for b in n_bounds)
    if not lo < hi:
        raise ValueError("n_bounds: need low < high")
    exposure = _positive(exposure, "exposure")
    tl, tv = measured.theta_light_deg, measured.theta_view_deg
    kern = brdf.Eq6Kernel.build(tl[:, None], tv[None, :], thickness=thickness, ndf=ndf,
                                wavelength_nm=wavelength_nm, film=film, substrate=substrate,
                                n_ambient=n_ambient, theta_m_step_deg=theta_m_step_deg)
    tx = kern.film.xyz(illuminant=measured.illuminant, observer=measured.observer)
    white = spectral_weights(kern.film.wavelength_nm, illuminant=measured.illuminant,
                                   observer=measured.observer).sum(axis=0)
    ref = np.asarray(measured.lab, np.float64)
    mask = np.all(np.isfinite(ref), axis=-1)
    if region == "diffuse":
        mask &= ~specular_mask(tl, tv, halfwidth_deg=specular_halfwidth_deg)
    if not np.any(mask):
        raise ValueError("measured: no finite cells in the fitted region")
    scan = []

    def evaluate(ln):
        xyz = kern.xyz(math.exp(ln), table_xyz=tx)
        if fit_exposure_too:
            e, c = fit_exposure(xyz, ref, white=white, mask=mask)
        else:
            e, c = exposure, _mean_de(exposure * xyz[mask], white, ref[mask], slice(None))
        scan.append((math.exp(ln), e, c))
        return c, e

    grid = np.linspace(lo, hi, 25)
    res = [evaluate(g) for g in grid]
    k = int(np.argmin([r[0] for r in res]))
    a, b = grid[max(k - 1, 0)], grid[min(k + 1, grid.size - 1)]
    opt = minimize_scalar(lambda ln: evaluate(ln)[0], bounds=(a, b), method="bounded",
                          options={"xatol": 1e-3})
    best_c, best_e = evaluate(opt.x)
    best_ln = opt.x
    if res[k][0] < best_c:
        best_c, best_e, best_ln = res[k][0], res[k][1], grid[k]
    return Eq6Fit(math.exp(best_ln), float(best_e), float(best_c), scan)


# ------------------------------------------------------------------------------ figure
def plot_maps(path, predicted: AngularMap, *, measured: AngularMap | None = None,
              delta_e=None, stats=None, title=None):
    """PDF (or PNG) figure: the predicted map, and the measured and ΔE00 maps if given.

    Axes: view angle across, light angle down (as the seed's Figs. 5, 10, 20).
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    panels = [("predicted", predicted)]
    if measured is not None:
        panels.append(("measured", measured))
    ncol = len(panels) + (delta_e is not None)
    fig, axes = plt.subplots(1, ncol, figsize=(3.6 * ncol, 3.6), squeeze=False)
    tl, tv = predicted.theta_light_deg, predicted.theta_view_deg
    ext = [tv[0] - 0.5, tv[-1] + 0.5, tl[-1] + 0.5, tl[0] - 0.5]
    for ax, (name, m) in zip(axes[0], panels):
        img = m.srgb if m.srgb is not None else _lab_to_srgb8(m.lab, m.illuminant, m.observer)
        ax.imshow(img, extent=ext, interpolation="nearest")
        ax.set_title(name)
        ax.set_xlabel("view zenith (deg, + = mirror side)")
        ax.set_ylabel("light zenith (deg)")
    if delta_e is not None:
        ax = axes[0][-1]
        im = ax.imshow(delta_e, extent=ext, cmap="magma", interpolation="nearest")
        fig.colorbar(im, ax=ax, fraction=0.046, label="ΔE00")
        t = "ΔE00"
        if stats:
            t += (f": mean {stats['mean']:.2f}, diffuse "
                  f"{stats['mean_excluding_specular']:.2f}")
        ax.set_title(t, fontsize=9)
        ax.set_xlabel("view zenith (deg)")
    if title:
        fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
