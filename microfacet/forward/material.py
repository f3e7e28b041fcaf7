"""A measured material as a renderer needs it: the film average on a grid and the NDF lobes.

The thin-film microfacet BRDF of :mod:`microfacet.forward.brdf` separates into the film
average ⟨R⟩(θ_d, λ) — the Airy reflectance averaged over the thickness distribution — and the
achromatic ``D G₂ / (4 cos θ_l cos θ_v)`` of the NDF lobes. A renderer evaluates the BRDF at
millions of (direction, wavelength) samples, so :class:`Material` tabulates ⟨R⟩ once on a
uniform (θ_d, λ) grid and looks it up by bilinear interpolation, exactly as the Mitsuba BSDF
of :mod:`microfacet.render.bsdf` does; it is written to and read from the file of
:mod:`microfacet.io.material_file` (``microfacet export-brdf``).

The grid (0.25° in θ_d, 1 nm over 360-825 nm, ~0.7 MB) was chosen by measured error against
the exact Airy reflectance (``python -m pipelines run accuracy-material-table``; the numbers
are in docs/rendering.md): 0.5° × 5 nm errs 10-20 times more. Wavelengths outside the grid
take the nearest end's value: Mitsuba samples 360-830 nm and the default film's optical
constants end at 826.6 nm, where the CIE 1931 observer weighs less than 2e-5 of its peak.

Examples
--------
>>> from microfacet.core.distributions import NDFMixture
>>> m = Material.build(thickness=51.0, ndf=NDFMixture([(1.0, 8.0)]), theta_step_deg=1.0,
...                    wavelength_step_nm=5.0)
>>> m.film_average.shape, m.film_average.dtype
((90, 94), dtype('float32'))
>>> f = m.brdf([0, 0, 1], [0.1, 0, 1], wavelength_nm=[550.0])
>>> f.shape
(1,)
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .. import __version__
from ..core.distributions import NDFMixture, ThicknessMixture
from ..core.errors import InputError, one_line
from ..io.material_file import read_material_file, write_material_file
from ..io.results import Results
from ..optics.constants import DEFAULT_FILM, DEFAULT_SUBSTRATE, load_set
from .brdf import FilmAverage, microfacet_geometry

__all__ = ["Material", "THETA_STEP_DEG", "WAVELENGTH_RANGE_NM", "WAVELENGTH_STEP_NM"]

#: Default grid: θ_d step (degrees), wavelength range and step (nm); see the module notes.
THETA_STEP_DEG = 0.25
WAVELENGTH_RANGE_NM = (360.0, 825.0)
WAVELENGTH_STEP_NM = 1.0
#: The BRDF's formulas, written into every exported file.
BRDF_TEXT = ("f_r = R(theta_d, lambda) * D(h) * G2(l, v) / (4 cos theta_l cos theta_v); "
             "D = sum_i w_i exp(-tan^2 theta_h / a_i^2) / (pi a_i^2 cos^4 theta_h), "
             "a_i = sqrt(2) tan(sd_deg_i); G2 = 1 / (1 + L(l) + L(v)), L = sum_i w_i L_i, "
             "L_i = (erf(x) - 1) / 2 + exp(-x^2) / (2 x sqrt(pi)), x = 1 / (a_i tan theta); "
             "R bilinear in (theta_d_deg, wavelength_nm), clamped at the grid ends")


def uniform_grid(lo: float, hi: float, step: float) -> np.ndarray:
    """``lo, lo + step, …`` up to ``hi`` (inclusive within 1e-9 of a step)."""
    n = int(math.floor((hi - lo) / step + 1e-9)) + 1
    return lo + step * np.arange(n, dtype=np.float64)


def _covered_range(names, lo: float, hi: float, step: float) -> tuple[float, float]:
    """The part of ``[lo, hi]`` that every optical-constant set in ``names`` covers, on the
    ``step`` grid from ``lo`` (sets given as constant indices cover everything)."""
    for name in names:
        if isinstance(name, str):
            a, b = load_set(name).range_nm
            lo = lo + step * math.ceil(max(0.0, a - lo) / step - 1e-9)
            hi = min(hi, b)
    if not hi - lo >= step:
        raise InputError(f"the optical constants {', '.join(map(str, names))} do not cover "
                         "the visible range", param="film")
    return lo, hi


@dataclass(frozen=True)
class Material:
    """A fitted thin-film microfacet material, tabulated for rendering.

    Attributes
    ----------
    ndf : NDFMixture
        The facet-normal lobes.
    film_average : ndarray (T, N) float32
        ⟨R⟩ at ``theta_d_deg`` × ``wavelength_nm``.
    theta_d_deg : ndarray (T,)
        Uniform from 0°, below 90°.
    wavelength_nm : ndarray (N,)
        Uniform.
    thickness : ThicknessMixture or float
        The thickness distribution (or a single thickness, nm) the table averages over.
    film, substrate : str
        Optical-constant set names.
    n_ambient : float
    metadata : dict
        Provenance (results folder, microfacet version, whether the NDF was identified).
    """

    ndf: NDFMixture
    film_average: np.ndarray
    theta_d_deg: np.ndarray
    wavelength_nm: np.ndarray
    thickness: object
    film: str = DEFAULT_FILM
    substrate: str = DEFAULT_SUBSTRATE
    n_ambient: float = 1.0
    metadata: dict = field(default_factory=dict)

    # ------------------------------------------------------------------ construction
    @classmethod
    def build(cls, *, thickness, ndf, film=DEFAULT_FILM, substrate=DEFAULT_SUBSTRATE,
              n_ambient=1.0, theta_step_deg=THETA_STEP_DEG,
              wavelength_range_nm=WAVELENGTH_RANGE_NM, wavelength_step_nm=WAVELENGTH_STEP_NM,
              metadata=None) -> "Material":
        """Tabulate ⟨R⟩ of ``thickness`` over the (θ_d, λ) grid.

        Parameters
        ----------
        thickness : float or ThicknessMixture
            nm.
        ndf : NDFMixture
        film, substrate : str
        theta_step_deg, wavelength_step_nm : float
            Grid steps; the wavelength grid is clipped inwards to the optical constants'
            range.
        wavelength_range_nm : (float, float)

        Returns
        -------
        Material
        """
        if not isinstance(ndf, NDFMixture):
            raise InputError(f"expected an NDFMixture, got {type(ndf).__name__}", param="ndf")
        for name, v in (("theta_step_deg", theta_step_deg),
                        ("wavelength_step_nm", wavelength_step_nm)):
            if not (isinstance(v, (int, float)) and 0.01 <= v <= 10):
                raise InputError(f"must be within 0.01-10, got {v!r}", param=name)
        lo, hi = (float(x) for x in wavelength_range_nm)
        lo, hi = _covered_range((film, substrate), lo, hi, float(wavelength_step_nm))
        wl = uniform_grid(lo, hi, float(wavelength_step_nm))
        th = uniform_grid(0.0, 89.999, float(theta_step_deg))
        # A mixture component by component: each on its own quadrature nodes (a narrow
        # component does not force its step onto the whole support; 16x faster on the
        # fixture's, the same integral to 1e-6).
        parts = ([(w, ThicknessMixture([(1.0, mu, sd)])) for w, mu, sd in thickness.components]
                 if isinstance(thickness, ThicknessMixture) else [(1.0, thickness)])
        table = np.zeros((th.size, wl.size))
        for w, part in parts:
            table += w * FilmAverage.build(th, part, wavelength_nm=wl, film=film,
                                           substrate=substrate, n_ambient=n_ambient).spectra
        return cls(ndf, table.astype(np.float32), th, wl, thickness, str(film),
                   str(substrate), float(n_ambient), dict(metadata or {}))

    @classmethod
    def from_results(cls, results, **grid) -> "Material":
        """The material of an analysis results folder (its thickness mixture, NDF and optics).

        Parameters
        ----------
        results : path-like or Results
        **grid
            ``theta_step_deg``, ``wavelength_range_nm``, ``wavelength_step_nm``.

        Raises
        ------
        InputError
            Naming ``summary.json`` and the missing key (``ndf.mixture``,
            ``thickness.mixture``).
        """
        r = results if isinstance(results, Results) else Results(results)
        shown = one_line(r.path / "summary.json")
        thickness, ndf = r.thickness_mixture(), r.ndf_mixture()
        for key, value in (("thickness.mixture", thickness), ("ndf.mixture", ndf)):
            if value is None:
                raise InputError(f"{shown}: no key '{key}': the analysis fitted no "
                                 f"{key.split('.')[0]} distribution to render")
        optics = r.optics()
        meta = {"source": {"results": str(r.path.resolve()),
                           "created": r.get("created"),
                           "ndf_identified": bool(r.get("ndf", "identified")),
                           "ndf_reason": r.get("ndf", "reason") or ""}}
        return cls.build(thickness=thickness, ndf=ndf, film=optics.get("film", DEFAULT_FILM),
                         substrate=optics.get("substrate", DEFAULT_SUBSTRATE), metadata=meta,
                         **grid)

    # ------------------------------------------------------------------------- file
    def write(self, path) -> Path:
        """Write the material file (:mod:`microfacet.io.material_file`); returns its path."""
        if isinstance(self.thickness, ThicknessMixture):
            thickness = self.thickness.to_json()
        else:
            thickness = {"thickness_nm": float(self.thickness)}
        meta = {**self.metadata, "brdf": BRDF_TEXT, "ndf": self.ndf.to_json(),
                "thickness": thickness, "film": self.film, "substrate": self.substrate,
                "n_ambient": self.n_ambient, "microfacet_version": __version__}
        write_material_file(path, {"film_average": self.film_average,
                                   "theta_d_deg": self.theta_d_deg,
                                   "wavelength_nm": self.wavelength_nm}, meta)
        return Path(path)

    @classmethod
    def read(cls, path) -> "Material":
        """A material file read back (checked; errors name the file and key)."""
        arrays, meta = read_material_file(path)
        shown = one_line(path)
        try:
            ndf = NDFMixture.from_json(meta["ndf"])
            t = meta["thickness"]
            thickness = (float(t["thickness_nm"]) if "thickness_nm" in t
                         else ThicknessMixture.from_json(t))
            film, substrate = str(meta["film"]), str(meta["substrate"])
            n_ambient = float(meta.get("n_ambient", 1.0))
        except KeyError as exc:
            raise InputError(f"{shown}: metadata.json: no key {exc}") from None
        except (ValueError, TypeError, AttributeError) as exc:
            raise InputError(f"{shown}: metadata.json: {one_line(exc)}") from None
        extra = {k: v for k, v in meta.items()
                 if k not in ("format", "brdf", "ndf", "thickness", "film", "substrate",
                              "n_ambient", "microfacet_version")}
        return cls(ndf, arrays["film_average"], arrays["theta_d_deg"], arrays["wavelength_nm"],
                   thickness, film, substrate, n_ambient, extra)

    # ------------------------------------------------------------------- evaluation
    def film_reflectance(self, theta_d_deg, wavelength_nm):
        """⟨R⟩ by bilinear interpolation, clamped at the grid ends (as the renderer does).

        Parameters
        ----------
        theta_d_deg, wavelength_nm : array_like
            Broadcast together (S).

        Returns
        -------
        ndarray (S,) float64; NaN where an input is NaN.
        """
        t, w = np.broadcast_arrays(np.asarray(theta_d_deg, np.float64),
                                   np.asarray(wavelength_nm, np.float64))
        i, fi = _cell(t, self.theta_d_deg)
        j, fj = _cell(w, self.wavelength_nm)
        a = self.film_average.astype(np.float64)
        r0 = a[i, j] * (1 - fj) + a[i, j + 1] * fj
        r1 = a[i + 1, j] * (1 - fj) + a[i + 1, j + 1] * fj
        out = r0 * (1 - fi) + r1 * fi
        return np.where(np.isfinite(t) & np.isfinite(w), out, np.nan)

    def brdf(self, light, view, *, wavelength_nm):
        """f_r(l, v; λ) in 1/sr through the table (cf. :func:`~.brdf.microfacet_brdf`).

        Parameters
        ----------
        light, view : array_like (..., 3)
            Directions away from the surface, z = macroscopic normal; they broadcast (S).
        wavelength_nm : array_like (N,)

        Returns
        -------
        ndarray, shape S + (N,)
        """
        geom, theta_d = microfacet_geometry(light, view, self.ndf)
        wl = np.atleast_1d(np.asarray(wavelength_nm, np.float64))
        return self.film_reflectance(theta_d[..., None], wl) * geom[..., None]


def _cell(x, grid):
    """Lower node index and fraction of ``x`` on a uniform ``grid``, clamped to its ends."""
    step = grid[1] - grid[0]
    u = np.clip((np.where(np.isfinite(x), x, grid[0]) - grid[0]) / step, 0.0, grid.size - 1)
    i = np.minimum(np.floor(u).astype(np.intp), grid.size - 2)
    return i, u - i
