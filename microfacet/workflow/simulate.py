"""Forward angular maps into a folder (``microfacet simulate``): the distributions — one
thickness, a thickness mixture and NDF lobes given explicitly, or an analysis results folder's
fits — through a forward model (:func:`microfacet.forward.angular.simulate_map`), optionally
compared with and fitted to a measured map, written as a simulation folder
(:mod:`microfacet.io.simulation`) in one atomic step.

What to simulate, in order of precedence: ``thickness_mixture``, else ``thickness_nm``, else
the results folder's thickness mixture; ``ndf_lobes``, else the results folder's NDF. The
optics (:class:`FilmOptics`): each one given explicitly wins (the default illuminant given
explicitly included), else the results folder's ``inputs``, else the defaults; a measured map
fixes the illuminant and observer its colours were computed under.

Examples
--------
>>> import tempfile, pathlib
>>> out = pathlib.Path(tempfile.mkdtemp()) / "sim"
>>> done = simulate_to_folder(out, thickness_nm=51.0,
...                           options=SimulateOptions(theta_max_deg=30, theta_step_deg=10))
>>> done.model, done.shape, sorted(p.name for p in out.iterdir())[:3]
('half-vector', (4, 4), ['angular_lab.npy', 'angular_map.npz', 'angular_map.png'])
"""

from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .. import __version__
from ..colour.colorimetry import spectral_weights
from ..core.angular import AngularMap
from ..core.defaults import DEFAULT_ILLUMINANT, DEFAULT_OBSERVER
from ..core.distributions import NDFMixture, ThicknessMixture
from ..core.errors import InputError
from ..core.options import Options, option
from ..forward import angular, compare
from ..forward.brdf import thickness_nodes
from ..io.angular_map import load_map
from ..io.limits import check_memory
from ..io.outdir import OutputFolder, check_output
from ..io.results import Results
from ..io.simulation import Simulation, write_simulation
from ..optics.constants import unknown_set_reason
from ..optics.defaults import DEFAULT_FILM, DEFAULT_SUBSTRATE
from ..report.figures import plot_maps

__all__ = ["FilmOptics", "SimulateOptions", "SimulateOutput", "simulate_to_folder"]

MODELS = ("microfacet", "eq6", "half-vector")
#: Finest angle step accepted (finer grids change no colour measurably:
#: docs/speed-vs-error.md), the spectral step range, the exposure range, the largest
#: cosine-lobe exponent, thickness and thickness SD.
MIN_THETA_STEP_DEG = 0.05
SPECTRAL_STEP_RANGE_NM = (0.5, 20.0)
EXPOSURE_RANGE = (1e-6, 1e6)
MAX_LOBE_EXPONENT = 1e6
MAX_THICKNESS_NM = 5000.0
MAX_THICKNESS_SD_NM = 1000.0
#: eq. 6's cosine-lobe exponent n when none is given or fitted.
DEFAULT_LOBE_EXPONENT = 100.0
#: The visible range the spectra cover, nm.
SPECTRAL_RANGE_NM = (380.0, 780.0)


def _within(low, high, *, closed=True):
    """A check: the value must be in [low, high] (``closed``) or (low, high)."""
    shown = f"[{low:g}, {high:g}]" if closed else f"({low:g}, {high:g})"

    def check(value):
        if value is None:
            return None
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            return f"must be a number in {shown}, got {value!r}"
        ok = low <= value <= high if closed else low < value < high
        return None if math.isfinite(value) and ok else f"must be in {shown}, got {value:g}"
    return check


@dataclass(frozen=True)
class FilmOptics(Options):
    """The film, the substrate, the light and the observer a forward model assumes
    (``simulate``, ``fit-spectrum``). None: the results folder's where there is one, else the
    default (:meth:`resolved`)."""

    film: str | None = option(
        None, help=f"optical-constant set of the oxide film (default {DEFAULT_FILM})",
        kind=str, check=unknown_set_reason, cli=True)
    substrate: str | None = option(
        None, help=f"optical-constant set of the metal (default {DEFAULT_SUBSTRATE})",
        kind=str, check=unknown_set_reason, cli=True)
    illuminant: str | None = option(
        None, help=f"illuminant name (default {DEFAULT_ILLUMINANT})", kind=str, cli=True)
    observer: str = option(DEFAULT_OBSERVER, help="CIE standard observer in degrees",
                           choices=("2", "10"), cli=True)

    def resolved(self, recorded: dict | None = None) -> dict:
        """``{film, substrate, illuminant, observer}``: each given value, else the one in
        ``recorded`` (a results folder's), else the default.

        >>> FilmOptics(illuminant="D65").resolved({"illuminant": "D50", "film": "X"})
        {'film': 'X', 'substrate': 'Ti_JohnsonChristy1974', 'illuminant': 'D65', 'observer': '2'}
        """
        rec = recorded or {}
        return {"film": self.film or rec.get("film") or DEFAULT_FILM,
                "substrate": self.substrate or rec.get("substrate") or DEFAULT_SUBSTRATE,
                "illuminant": self.illuminant or rec.get("illuminant") or DEFAULT_ILLUMINANT,
                "observer": self.observer}


@dataclass(frozen=True)
class SimulateOptions(Options):
    """How :func:`simulate_to_folder` simulates: the model, the grids, the exposure, the fits
    to a measured map, and the optics."""

    model: str | None = option(None, help="forward model (default microfacet when an NDF is "
                                          "known, else half-vector)", kind=str, choices=MODELS,
                               cli=True)
    lobe_exponent: float | None = option(
        None, help=f"eq. 6 cosine-lobe exponent n (default {DEFAULT_LOBE_EXPONENT:g}, or the "
                   f"fit)", kind=float, check=_within(0, MAX_LOBE_EXPONENT), cli=True,
        metavar="N")
    theta_max_deg: float = option(85.0, help="largest light and view zenith angle", unit="°",
                                  check=_within(0, 90, closed=False), cli=True, metavar="DEG")
    theta_step_deg: float = option(1.0, help="angle grid step", unit="°",
                                   low=MIN_THETA_STEP_DEG, cli=True, metavar="DEG")
    exposure: float | None = option(
        None, help="reflectance scale (default: for display, the 98th percentile of Y at 0.9 "
                   "of white; 1 for a single thickness)", kind=float,
        check=_within(*EXPOSURE_RANGE), cli=True, metavar="E")
    spectral_step_nm: float = option(
        5.0, help="spectral step of the spectra over 380-780 nm", unit="nm",
        check=_within(*SPECTRAL_STEP_RANGE_NM), cli=True, metavar="NM")
    specular_halfwidth_deg: float = option(
        10.0, help="specular band |view - light| <= this is left out of the diffuse mean ΔE00",
        unit="°", check=_within(0, 90, closed=False), cli=True, metavar="DEG")
    fit_exponent: bool = option(False, help="fit the eq. 6 exponent n by least mean ΔE00 "
                                            "(needs a measured map)", cli=True)
    fit_exposure: bool = option(False, help="fit a global exposure by least mean ΔE00 (needs "
                                            "a measured map)", cli=True)
    optics: FilmOptics = option(FilmOptics(), help="film, substrate, light, observer")

    def __post_init__(self):
        super().__post_init__()
        if self.theta_step_deg > self.theta_max_deg:
            raise InputError(f"must be >= {MIN_THETA_STEP_DEG:g} and <= `theta_max_deg`, got "
                             f"{self.theta_step_deg:g}", param="theta_step_deg")
        if self.fit_exponent and self.model != "eq6":
            raise InputError("only with `model` eq6", param="fit_exponent")


@dataclass(frozen=True)
class SimulateOutput:
    """What :func:`simulate_to_folder` wrote.

    Attributes
    ----------
    out : Path
        The simulation folder.
    model : str
    exposure : float
        The exposure of the written map (given, fitted or the display rule's).
    shape : tuple of int
        ``(L, V)``: light × view angles.
    compare : dict or None
        Mean ΔE00 to the measured map over all cells (``mean``) and outside the specular band
        (``mean_excluding_specular``).
    fit : dict
        What was fitted (``n``, ``exposure``, ``auto_exposure``, ``mean_delta_e``).
    meta : dict
        ``simulate.json``.
    """

    out: Path
    model: str
    exposure: float
    shape: tuple
    compare: dict | None
    fit: dict
    meta: dict


@dataclass
class _Plan:
    """Everything a simulation needs, validated before any work."""

    thickness: object
    thickness_param: str
    ndf: NDFMixture | None
    model: str
    optics: dict
    theta_light_deg: np.ndarray
    theta_view_deg: np.ndarray
    wavelength_nm: np.ndarray
    measured: AngularMap | None
    options: SimulateOptions
    results: str | None
    compare: str | None


def simulate_to_folder(out, *, results=None, thickness_nm: float | None = None,
                       thickness_mixture=None, ndf_lobes=None, compare=None,
                       options: SimulateOptions | None = None,
                       overwrite: bool = False) -> SimulateOutput:
    """Simulate an angular colour map and write it as the simulation folder ``out``.

    Parameters
    ----------
    out : path-like
        The simulation folder (the rules of :mod:`microfacet.io.outdir`).
    results : path-like, optional
        An analysis results folder: its fitted mixtures and optics where not given here.
    thickness_nm : float, optional
        One oxide thickness (with no NDF: the half-vector map of one film).
    thickness_mixture : ThicknessMixture or sequence of (weight, mean_nm, sd_nm), optional
    ndf_lobes : NDFMixture or sequence of (weight, sd_deg), optional
    compare : path-like, optional
        A measured map (``microfacet-angular/1``): simulated on its grid, under its
        illuminant and observer, and compared (``delta_e.npy``).
    options : SimulateOptions, optional
    overwrite : bool
        Replace an earlier simulation folder.

    Returns
    -------
    SimulateOutput

    Raises
    ------
    InputError
        Naming the parameter at fault (``thickness_mixture``, ``results``, ``compare``,
        ``out``, an option), before any work.
    """
    started = time.perf_counter()
    options = SimulateOptions() if options is None else options
    inputs = [Path(x) for x in (results, compare) if x is not None]
    check_output(out, kind="simulate", inputs=inputs, overwrite=overwrite)
    plan = _plan(results, thickness_nm, thickness_mixture, ndf_lobes, compare, options)
    with OutputFolder(out, kind="simulate", inputs=inputs, overwrite=overwrite,
                      expected_bytes=_size_bytes(plan)) as claim:
        m, fit = _simulate(plan)
        de, stats = _compare(plan, m)
        meta = _meta(plan, m, fit, stats)
        with claim.writing() as tmp:
            write_simulation(tmp, Simulation(m, meta, de), started=started,
                             extra=lambda folder: _figure(folder, plan, m, de, stats))
    logging.getLogger(__name__).info("wrote %s in %.2f s", out, time.perf_counter() - started)
    return SimulateOutput(Path(out), plan.model, float(m.meta["exposure"]), m.shape, stats,
                          fit, meta)


# ------------------------------------------------------------------------- the plan
def _plan(results, thickness_nm, thickness_mixture, ndf_lobes, compare, options) -> _Plan:
    """Read and check the inputs (results folder, distributions, measured map) and the
    options that depend on them."""
    recorded = _read_results(results) if results is not None else {}
    thickness, param = _thickness(thickness_nm, thickness_mixture, recorded)
    ndf = (_mixture(ndf_lobes, NDFMixture, "ndf_lobes") if ndf_lobes is not None
           else recorded.get("ndf"))
    model = options.model or ("microfacet" if ndf is not None else "half-vector")
    if model != "half-vector" and ndf is None:
        raise InputError(f"model {model} needs NDF lobes (or `results` with ndf.mixture)",
                         param="ndf_lobes")
    if (options.fit_exponent or options.fit_exposure) and compare is None:
        raise InputError("`fit_exponent` / `fit_exposure` need a measured map", param="compare")
    optics = options.optics.resolved(recorded.get("optics"))
    measured = None if compare is None else load_map(compare)
    if measured is not None:
        _follow_measured(optics, options.optics, measured)
        tl, tv = measured.theta_light_deg, measured.theta_view_deg
    else:
        tl = tv = np.arange(0.0, options.theta_max_deg + 1e-9, options.theta_step_deg)
    lo, hi = SPECTRAL_RANGE_NM
    wl = np.linspace(lo, hi, int(round((hi - lo) / options.spectral_step_nm)) + 1)
    plan = _Plan(thickness, param, ndf, model, optics, tl, tv, wl, measured, options,
                 None if results is None else str(results),
                 None if compare is None else str(compare))
    _check_work(plan)
    return plan


def _read_results(folder) -> dict:
    """The fitted mixtures and the optics of an analysis results folder (``results``)."""
    try:
        res = Results(folder)
        recorded = {"thickness": res.thickness_mixture(), "ndf": res.ndf_mixture(),
                    "optics": res.optics(), "summary": res.path / "summary.json"}
    except InputError as exc:
        raise InputError(exc.raw_reason, param="results") from None
    reasons = {f"inputs.{key}": unknown_set_reason(recorded["optics"].get(key))
               for key in ("film", "substrate")}
    for key, n in (("thickness", 3), ("ndf", 2)):
        if recorded[key] is not None:
            reasons[f"{key}.mixture"] = _component_reason(recorded[key].components, n)
    for key, reason in reasons.items():
        if reason is not None:
            raise InputError(f"{recorded['summary']}: key '{key}': {reason}", param="results")
    # summary["exposure"] is the microscope camera's scale, not a gonio map's: not used.
    return recorded


def _thickness(thickness_nm, thickness_mixture, recorded) -> tuple:
    """The thickness to simulate and the parameter it came from."""
    if thickness_mixture is not None:
        return _mixture(thickness_mixture, ThicknessMixture, "thickness_mixture"), \
            "thickness_mixture"
    if thickness_nm is not None:
        value = float(thickness_nm)
        if not (math.isfinite(value) and 0 <= value <= MAX_THICKNESS_NM):
            raise InputError(f"must be in [0, {MAX_THICKNESS_NM:g}] nm, got {value:g}",
                             param="thickness_nm")
        return value, "thickness_nm"
    if recorded.get("thickness") is not None:
        return recorded["thickness"], "results"
    if "summary" in recorded:
        raise InputError(f"{recorded['summary']} has no thickness.mixture", param="results")
    raise InputError("give `results`, `thickness_mixture` or `thickness_nm`",
                     param="thickness_mixture")


def _mixture(value, cls, param):
    """``value`` (a mixture or its components) as a ``cls``, within the bounds a forward
    model takes; an InputError names ``param``."""
    comps = value.components if isinstance(value, cls) else value
    try:
        comps = [tuple(float(v) for v in c) for c in comps]
    except (TypeError, ValueError):
        raise InputError(f"expected components of numbers, got {value!r}"[:200],
                         param=param) from None
    reason = _component_reason(comps, 2 if cls is NDFMixture else 3)
    if reason is not None:
        raise InputError(reason, param=param)
    if isinstance(value, cls):
        return value
    try:
        return cls(comps)
    except ValueError as exc:
        raise InputError(str(exc), param=param) from None


def _component_reason(comps, n: int) -> str | None:
    """Why the mixture components ``comps`` (tuples of ``n`` numbers: weight, mean_nm, sd_nm
    or weight, sd_deg) cannot be simulated, or None."""
    if not comps:
        return "no components"
    if any(len(c) != n for c in comps):
        return f"every component needs {n} numbers"
    if n == 2 and any(not (0 < c[1] < 90) for c in comps):
        return "sd_deg must be in (0, 90)"
    if n == 3 and any(not 0 <= c[1] <= MAX_THICKNESS_NM for c in comps):
        return f"mean_nm must be in [0, {MAX_THICKNESS_NM:g}]"
    if n == 3 and any(c[2] > MAX_THICKNESS_SD_NM for c in comps):
        return f"sd_nm must be <= {MAX_THICKNESS_SD_NM:g}"
    if any(not all(map(math.isfinite, c)) or c[0] <= 0 or c[-1] <= 0 for c in comps):
        return "weights and sds must be finite and > 0"
    return None


def _follow_measured(optics: dict, given: FilmOptics, measured: AngularMap) -> None:
    """The measured map's colours are under its illuminant and observer: simulate under
    them too (a different illuminant given explicitly is overridden, with a warning)."""
    if given.illuminant is not None and given.illuminant != measured.illuminant:
        logging.getLogger(__name__).warning(
            "illuminant %s ignored: the measured map %s is under %s", given.illuminant,
            measured.meta.get("source"), measured.illuminant)
    optics["illuminant"], optics["observer"] = measured.illuminant, measured.observer


def _check_work(plan: _Plan) -> None:
    """Refuse a grid that needs more memory than is free, or a mixture that needs too many
    quadrature nodes, before any work."""
    o = plan.options
    need = angular.simulate_memory_bytes(model=plan.model, n_light=plan.theta_light_deg.size,
                                         n_view=plan.theta_view_deg.size,
                                         n_wavelengths=plan.wavelength_nm.size)
    check_memory(need, f"{plan.theta_light_deg.size} x {plan.theta_view_deg.size} angles x "
                       f"{plan.wavelength_nm.size} wavelengths (`theta_step_deg` "
                       f"{o.theta_step_deg:g}, `spectral_step_nm` {o.spectral_step_nm:g})")
    try:
        thickness_nodes(plan.thickness)
    except ValueError as exc:
        raise InputError(str(exc).partition(": ")[2], param=plan.thickness_param) from None


def _size_bytes(plan: _Plan) -> int:
    """About what the folder takes on disk: the float32 spectra twice (``spectra.npy`` and the
    map file), the colours, the figure."""
    cells = plan.theta_light_deg.size * plan.theta_view_deg.size
    return int(cells * (8 * plan.wavelength_nm.size + 64) + (4 << 20))


# ------------------------------------------------------------------------- the work
def _simulate(plan: _Plan) -> tuple[AngularMap, dict]:
    """The map at the given, fitted or display exposure, and what was fitted."""
    o, fit = plan.options, {}
    exposure = 1.0 if o.exposure is None else o.exposure
    n = DEFAULT_LOBE_EXPONENT if o.lobe_exponent is None else float(o.lobe_exponent)
    if o.fit_exponent:
        r = compare.fit_eq6(plan.measured, thickness=plan.thickness, ndf=plan.ndf,
                            fit_exposure_too=o.fit_exposure, exposure=exposure,
                            wavelength_nm=plan.wavelength_nm, film=plan.optics["film"],
                            substrate=plan.optics["substrate"])
        n, fit["n"], fit["mean_delta_e"] = r.n, r.n, r.mean_delta_e
        if o.fit_exposure:
            exposure = fit["exposure"] = r.exposure
    kw = dict(model=plan.model, thickness=plan.thickness, ndf=plan.ndf, n=n,
              theta_light_deg=plan.theta_light_deg, theta_view_deg=plan.theta_view_deg,
              wavelength_nm=plan.wavelength_nm, **plan.optics)
    if o.fit_exposure and not o.fit_exponent:
        m1 = angular.simulate_map(exposure=1.0, **kw)
        white = spectral_weights(plan.wavelength_nm, illuminant=plan.optics["illuminant"],
                                 observer=plan.optics["observer"]).sum(axis=0)
        exposure, fit["mean_delta_e"] = compare.fit_exposure(m1.xyz, plan.measured.lab,
                                                             white=white)
        fit["exposure"] = exposure
    if o.exposure is None and not o.fit_exposure and not o.fit_exponent:
        # the display rule every map picture uses (forward.angular.display_exposure)
        m = angular.simulate_map(exposure=1.0, **kw)
        exposure = fit["auto_exposure"] = angular.display_exposure(m)
        m = angular.with_exposure(m, exposure)
    else:
        m = angular.simulate_map(exposure=exposure, **kw)
    _check_outcome(m.xyz, plan.model)
    m.meta["exposure"], m.meta["n"] = float(exposure), float(n)
    return m, fit


def _check_outcome(xyz, model):
    """Refuse an exposure or lobe exponent that makes every colour infinite or zero."""
    finite = np.isfinite(xyz)
    if not finite.any():
        raise InputError("every predicted colour is infinite; use a smaller exposure",
                         param="exposure")
    if not np.any(xyz[finite] > 0):
        param = "lobe_exponent" if model == "eq6" else "exposure"
        raise InputError("every predicted colour is black (zero); the value is far outside "
                         "what the model can show", param=param)


def _compare(plan: _Plan, m: AngularMap):
    """ΔE00 per cell to the measured map and its two means (None, None without one)."""
    if plan.measured is None:
        return None, None
    de = compare.delta_e_map(m, plan.measured)
    stats = compare.mean_delta_e(de, plan.theta_light_deg, plan.theta_view_deg,
                                 specular_halfwidth_deg=plan.options.specular_halfwidth_deg)
    return de, stats


def _meta(plan: _Plan, m: AngularMap, fit: dict, stats: dict | None) -> dict:
    """``simulate.json`` (io.simulation adds ``format`` and the total time)."""
    def span(a):
        return [float(a[0]), float(a[-1]), int(a.size)]

    th = plan.thickness
    meta = {"model": plan.model, "exposure": m.meta["exposure"],
            "thickness": th.to_json() if hasattr(th, "to_json") else {"thickness_nm": th},
            "ndf": plan.ndf.to_json() if plan.ndf is not None else None,
            "theta_light_deg": span(plan.theta_light_deg),
            "theta_view_deg": span(plan.theta_view_deg),
            "wavelength_nm": span(plan.wavelength_nm),
            "results": str(plan.results) if plan.results else None,
            **plan.optics, "version": __version__}
    if plan.model == "eq6":
        meta["lobe_exponent"] = m.meta["n"]
    if fit:
        meta["fit"] = fit
    if stats is not None:
        meta["compare"] = {"measured": str(plan.compare), **stats}
    meta["timings_s"] = dict(m.meta.get("timings_s", {}))
    return meta


def _figure(folder: Path, plan: _Plan, m: AngularMap, de, stats) -> None:
    title = (f"{plan.model}" + (f", n = {m.meta['n']:.3g}" if plan.model == "eq6" else "")
             + f", exposure {m.meta['exposure']:.3g}")
    plot_maps(folder / "figure.pdf", m, measured=plan.measured, delta_e=de, stats=stats,
              title=title)
