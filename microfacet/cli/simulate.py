"""``microfacet simulate``: forward angular colour / spectral reflectance maps.

Two paths:

* ``--thickness-nm D`` alone: the half-vector map of one film (seed Fig. 10), written
  exactly as before (``angular_lab.npy``, ``angular_xyz.npy``, ``theta_*.npy``,
  ``angular_map.png``, ``simulate.json``).
* from distributions — ``--results OUT`` (an ``analyze`` results folder) or explicit
  ``--thickness-mixture`` / ``--ndf-lobes`` — with ``--model microfacet|eq6|half-vector``:
  adds ``spectra.npy``, ``wavelength_nm.npy``, ``angular_map.npz`` (the
  ``microfacet-angular/1`` format of :mod:`microfacet.forward.angular`) and ``figure.pdf``;
  ``--compare MEASURED.npz`` adds ``delta_e.npy`` and the two mean ΔE00 values, and
  ``--fit-exponent`` / ``--fit-exposure`` fit eq. 6's n and a global exposure first.
"""

from __future__ import annotations

import json
import logging
import math
import time
from pathlib import Path

from .. import __version__, colour, core, forward, io, report
from ..core.errors import InputError
from ..core.lazy import load
from .options import HelpFormatter, add_optics_options, example_epilog, optics_kwargs

np = load("numpy")

_EXAMPLES = (
    "microfacet simulate --thickness-nm 51 --out sd-blue",
    "microfacet simulate --results nd-analysis --model microfacet --out nd-sim",
    'microfacet simulate --thickness-mixture "0.3:112:3,0.45:130:3,0.25:149:3" \\',
    '    --ndf-lobes "0.6:3,0.4:9" --model eq6 --lobe-exponent 80 --out nd-eq6',
    "microfacet simulate --results nd-analysis --model eq6 --compare measured.npz \\",
    "    --fit-exponent --fit-exposure --out nd-fit",
)


def register(sub):
    p = sub.add_parser(
        "simulate",
        help="angular colour / spectral maps (half-vector, seed eq. 6, microfacet BRDF)",
        description=(
            "Predict the interference colour over a grid of in-plane light and view zenith "
            "angles (view positive on the mirror side; rows = light, columns = view). "
            "With --thickness-nm alone: the half-vector thin-film model (seed §2.3-2.4) of "
            "one film, writing angular_lab.npy (L x V x 3), angular_xyz.npy, "
            "angular_map.png and simulate.json. With a thickness mixture and NDF lobes "
            "(from --results or given explicitly): --model microfacet (Walter et al. 2007 "
            "BRDF with the measured NDF, Smith masking and the thickness-averaged "
            "thin-film Fresnel term; reflectance factor pi*f_r), eq6 (seed eq. 6, "
            "cosine-lobe exponent --lobe-exponent) or half-vector; also writes "
            "spectra.npy (L x V x N), wavelength_nm.npy, angular_map.npz and figure.pdf. "
            "--compare MEASURED.npz (microfacet-angular/1: theta_light_deg, "
            "theta_view_deg, and lab or spectra + wavelength_nm) simulates on the measured "
            "grid and adds delta_e.npy and the mean CIEDE2000 over all cells and outside "
            "the specular band |view - light| <= --specular-halfwidth-deg. "
            "See docs/forward-simulation.md."),
        epilog=example_epilog(*_EXAMPLES),
        formatter_class=HelpFormatter,
    )
    src = p.add_argument_group("what to simulate")
    src.add_argument("--thickness-nm", type=float, default=None, metavar="NM",
                     help="one oxide thickness in nm (alone: the half-vector map)")
    src.add_argument("--results", default=None, metavar="DIR",
                     help="analysis results folder: fitted mixtures from DIR/summary.json")
    src.add_argument("--thickness-mixture", default=None, metavar="W:MEAN:SD,...",
                     help="thickness mixture, weight:mean_nm:sd_nm per component")
    src.add_argument("--ndf-lobes", default=None, metavar="W:SD,...",
                     help="NDF lobes, weight:sd_deg per zero-mean Gaussian-slope lobe")
    src.add_argument("--model", default=None, choices=["microfacet", "eq6", "half-vector"],
                     help="forward model (default microfacet when an NDF is known)")
    src.add_argument("--lobe-exponent", type=float, default=None, metavar="N",
                     help="eq. 6 cosine-lobe exponent n (default 100, or the fit)")
    p.add_argument("--out", required=True, metavar="OUT", help="output folder (must not exist)")
    p.add_argument("--theta-max-deg", type=float, default=85.0, metavar="DEG",
                   help="largest light and view zenith angle (default 85)")
    p.add_argument("--theta-step-deg", type=float, default=1.0, metavar="DEG",
                   help="angle grid step (default 1)")
    p.add_argument("--exposure", type=float, default=None, metavar="E",
                   help="reflectance scale for display (default: auto, the 98th percentile "
                        "of Y at 0.9 of white; 1 for --thickness-nm)")
    p.add_argument("--spectral-step-nm", type=float, default=5.0, metavar="NM",
                   help="spectral step over 380-780 nm of the spectra (default 5)")
    cmp_ = p.add_argument_group("comparison with a measured map")
    cmp_.add_argument("--compare", default=None, metavar="MEASURED.npz",
                      help="measured angular map (microfacet-angular/1 .npz)")
    cmp_.add_argument("--specular-halfwidth-deg", type=float, default=10.0, metavar="DEG",
                      help="specular band |view - light| <= this is excluded from the "
                           "diffuse mean (default 10)")
    cmp_.add_argument("--fit-exponent", action="store_true",
                      help="fit the eq. 6 exponent n by least mean dE00 (needs --compare)")
    cmp_.add_argument("--fit-exposure", action="store_true",
                      help="fit a global exposure by least mean dE00 (needs --compare)")
    p.add_argument("--overwrite", action="store_true", help="replace an existing OUT")
    add_optics_options(p)
    p.set_defaults(run=run)
    return p


#: Finest angle step and spectral step accepted (finer grids change no colour measurably:
#: docs/speed-vs-error.md), largest exposure, cosine-lobe exponent, thickness and mixture SD.
MIN_THETA_STEP_DEG = 0.05
SPECTRAL_STEP_RANGE_NM = (0.5, 20.0)
EXPOSURE_RANGE = (1e-6, 1e6)
MAX_LOBE_EXPONENT = 1e6
MAX_THICKNESS_NM = 5000.0
MAX_THICKNESS_SD_NM = 1000.0


def run(args) -> int:
    inputs = [x for x in (args.results, args.compare) if x]
    io.outdir.check_output(args.out, kind="simulate", inputs=inputs, overwrite=args.overwrite)
    return _simulate(args)


def _grid(args):
    if not (0 < args.theta_max_deg < 90):
        raise ValueError("--theta-max-deg: must be in (0, 90)")
    if not (MIN_THETA_STEP_DEG <= args.theta_step_deg <= args.theta_max_deg):
        raise ValueError(f"--theta-step-deg: must be >= {MIN_THETA_STEP_DEG:g} and <= "
                         f"--theta-max-deg, got {args.theta_step_deg:g}")
    return np.arange(0.0, args.theta_max_deg + 1e-9, args.theta_step_deg)


def _check_grid_memory(model, n_light, n_view, n_wl, what):
    need = forward.angular.simulate_memory_bytes(model=model, n_light=n_light, n_view=n_view,
                                                 n_wavelengths=n_wl)
    io.limits.check_memory(need, f"{n_light} x {n_view} angles x {n_wl} wavelengths ({what})")


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


def _check_thickness_nm(value):
    if value is not None and not (math.isfinite(value) and 0 <= value <= MAX_THICKNESS_NM):
        raise InputError(f"must be in [0, {MAX_THICKNESS_NM:g}] nm, got {value:g}",
                         param="thickness_nm")


def parse_thickness_mixture(text, *, option="--thickness-mixture"):
    """``"w:mean:sd,..."`` → :class:`~microfacet.core.distributions.ThicknessMixture`
    (ValueError naming ``option``)."""
    return core.distributions.ThicknessMixture(
        _parse_components(text, 3, option, "weight:mean_nm:sd_nm"))


def parse_ndf_lobes(text, *, option="--ndf-lobes"):
    """``"w:sd_deg,..."`` → :class:`~microfacet.core.distributions.NDFMixture`
    (ValueError naming ``option``)."""
    return core.distributions.NDFMixture(_parse_components(text, 2, option, "weight:sd_deg"))


def _parse_components(text, n, option, form):
    comps = []
    for part in str(text).split(","):
        if not part.strip():
            continue
        try:
            vals = tuple(float(v) for v in part.split(":"))
        except ValueError:
            raise ValueError(f"{option}: {part.strip()!r} is not {form}") from None
        if len(vals) != n:
            raise ValueError(f"{option}: {part.strip()!r} is not {form}")
        comps.append(vals)
    try:
        if not comps:
            raise ValueError("no components")
        if n == 2 and any(not (0 < c[1] < 90) for c in comps):
            raise ValueError("sd_deg must be in (0, 90)")
        if n == 3 and any(not 0 <= c[1] <= MAX_THICKNESS_NM for c in comps):
            raise ValueError(f"mean_nm must be in [0, {MAX_THICKNESS_NM:g}]")
        if n == 3 and any(c[2] > MAX_THICKNESS_SD_NM for c in comps):
            raise ValueError(f"sd_nm must be <= {MAX_THICKNESS_SD_NM:g}")
        if any(not all(map(_finite, c)) or c[0] <= 0 or c[-1] <= 0 for c in comps):
            raise ValueError("weights and sds must be finite and > 0")
    except ValueError as exc:
        raise ValueError(f"{option}: {exc}") from None
    return comps


def _finite(x):
    return math.isfinite(x)


def _read_results(folder):
    """The fitted mixtures and optics of an analysis results folder (``--results``)."""
    try:
        res = io.results.Results(folder)
        out = {"thickness": res.thickness_mixture(), "ndf": res.ndf_mixture()}
    except InputError as exc:
        raise InputError(exc.reason, param="results") from None
    if out["thickness"] is None:
        raise InputError(f"{Path(folder) / 'summary.json'} has no thickness.mixture",
                         param="results")
    for key in ("film", "substrate", "illuminant"):
        if isinstance(res.summary.get(key), str):
            out[key] = res.summary[key]
    # summary["exposure"] is the microscope camera's scale, not a gonio map's: not used.
    return out


def _simulate(args) -> int:
    log = logging.getLogger("microfacet.simulate")
    t0 = time.perf_counter()
    res = _read_results(args.results) if args.results is not None else {}
    if args.thickness_mixture is not None:
        thickness = parse_thickness_mixture(args.thickness_mixture)
    elif args.thickness_nm is not None:
        _check_thickness_nm(args.thickness_nm)
        thickness = float(args.thickness_nm)
    elif "thickness" in res:
        thickness = res["thickness"]
    else:
        raise ValueError("--thickness-mixture: give --results, --thickness-mixture or "
                         "--thickness-nm")
    ndf = parse_ndf_lobes(args.ndf_lobes) if args.ndf_lobes is not None else res.get("ndf")
    model = args.model or ("microfacet" if ndf is not None else "half-vector")
    if model != "half-vector" and ndf is None:
        raise ValueError(f"--ndf-lobes: model {model} needs NDF lobes (or --results with "
                         "ndf.mixture)")
    if args.fit_exponent and model != "eq6":
        raise ValueError("--fit-exponent: only with --model eq6")
    if (args.fit_exponent or args.fit_exposure) and args.compare is None:
        raise ValueError("--compare: --fit-exponent / --fit-exposure need a measured map")
    # Optics: explicit options win over the results folder, then the defaults.
    if args.film is None and "film" in res:
        args.film = res["film"]
    if args.substrate is None and "substrate" in res:
        args.substrate = res["substrate"]
    if args.illuminant == "D65" and "illuminant" in res:
        args.illuminant = res["illuminant"]
    opt = optics_kwargs(args)
    auto_exposure = args.exposure is None and not args.fit_exposure
    exposure = 1.0 if args.exposure is None else args.exposure
    if not (np.isfinite(exposure) and EXPOSURE_RANGE[0] <= exposure <= EXPOSURE_RANGE[1]):
        raise ValueError(f"--exposure: must be in [{EXPOSURE_RANGE[0]:g}, "
                         f"{EXPOSURE_RANGE[1]:g}], got {exposure:g}")
    n = 100.0 if args.lobe_exponent is None else float(args.lobe_exponent)
    if not (np.isfinite(n) and 0 <= n <= MAX_LOBE_EXPONENT):
        raise ValueError(f"--lobe-exponent: must be in [0, {MAX_LOBE_EXPONENT:g}]")
    step = args.spectral_step_nm
    lo_step, hi_step = SPECTRAL_STEP_RANGE_NM
    if not (np.isfinite(step) and lo_step <= step <= hi_step):
        raise ValueError(f"--spectral-step-nm: must be in [{lo_step:g}, {hi_step:g}]")
    wl = np.linspace(380.0, 780.0, int(round(400.0 / step)) + 1)

    measured = None
    if args.compare is not None:
        measured = io.angular_map.load_map(args.compare)
        tl, tv = measured.theta_light_deg, measured.theta_view_deg
        opt["illuminant"], opt["observer"] = measured.illuminant, measured.observer
    else:
        tl = tv = _grid(args)
    if not (0 < args.specular_halfwidth_deg < 90):
        raise ValueError("--specular-halfwidth-deg: must be in (0, 90)")
    _check_grid_memory(model, tl.size, tv.size, wl.size,
                       f"--theta-step-deg {args.theta_step_deg:g}, --spectral-step-nm {step:g}")
    try:
        forward.brdf.thickness_nodes(thickness)
    except ValueError as exc:
        raise InputError(str(exc).partition(": ")[2],
                         param="thickness_mixture" if args.thickness_mixture else "results"
                         ) from None

    fit = {}
    if args.fit_exponent:
        r = forward.compare.fit_eq6(measured, thickness=thickness, ndf=ndf,
                                    fit_exposure_too=args.fit_exposure,
                    exposure=exposure, wavelength_nm=wl, film=opt["film"],
                    substrate=opt["substrate"])
        n, fit["n"], fit["mean_delta_e"] = r.n, r.n, r.mean_delta_e
        if args.fit_exposure:
            exposure = fit["exposure"] = r.exposure
    kw = dict(model=model, thickness=thickness, ndf=ndf, n=n, theta_light_deg=tl,
              theta_view_deg=tv, wavelength_nm=wl, film=opt["film"],
              substrate=opt["substrate"], illuminant=opt["illuminant"],
              observer=opt["observer"])
    if args.fit_exposure and not args.fit_exponent:
        m1 = forward.angular.simulate_map(exposure=1.0, **kw)
        white = colour.colorimetry.spectral_weights(wl, illuminant=opt["illuminant"],
                                       observer=opt["observer"]).sum(axis=0)
        exposure, fit["mean_delta_e"] = forward.compare.fit_exposure(m1.xyz, measured.lab,
                                                                     white=white)
        fit["exposure"] = exposure
    if auto_exposure and not args.fit_exponent:
        # the display rule every map picture uses (forward.angular.display_exposure)
        m = forward.angular.simulate_map(exposure=1.0, **kw)
        exposure = fit["auto_exposure"] = forward.angular.display_exposure(m)
        m = forward.angular.with_exposure(m, exposure)
    else:
        m = forward.angular.simulate_map(exposure=exposure, **kw)
    _check_outcome(m.xyz, model)
    de = stats = None
    if measured is not None:
        de = forward.compare.delta_e_map(m, measured)
        stats = forward.compare.mean_delta_e(de, tl, tv,
                                             specular_halfwidth_deg=args.specular_halfwidth_deg)

    meta = {
        "format": "microfacet-simulate/2", "model": model, "exposure": float(exposure),
        "thickness": (thickness.to_json() if hasattr(thickness, "to_json")
                      else {"thickness_nm": thickness}),
        "ndf": ndf.to_json() if ndf is not None else None,
        "theta_light_deg": [float(tl[0]), float(tl[-1]), int(tl.size)],
        "theta_view_deg": [float(tv[0]), float(tv[-1]), int(tv.size)],
        "wavelength_nm": [float(wl[0]), float(wl[-1]), int(wl.size)],
        "results": str(args.results) if args.results else None,
        **opt, "version": __version__,
    }
    if model == "eq6":
        meta["lobe_exponent"] = float(n)
    if fit:
        meta["fit"] = fit
    if stats is not None:
        meta["compare"] = {"measured": str(args.compare), **stats}
    inputs = [x for x in (args.results, args.compare) if x]
    with io.outdir.atomic_output_dir(args.out, kind="simulate", overwrite=args.overwrite,
                           inputs=inputs) as tmp:
        np.save(tmp / "spectra.npy", m.spectra.astype(np.float32))
        np.save(tmp / "wavelength_nm.npy", wl)
        np.save(tmp / "angular_lab.npy", m.lab)
        np.save(tmp / "angular_xyz.npy", m.xyz.astype(np.float32))
        np.save(tmp / "theta_light_deg.npy", tl)
        np.save(tmp / "theta_view_deg.npy", tv)
        io.angular_map.save_map(tmp / "angular_map.npz", m)
        io.angular_map.save_png(tmp / "angular_map.png", m, scale=4)
        title = f"{model}" + (f", n = {n:.3g}" if model == "eq6" else "") + \
            f", exposure {exposure:.3g}"
        report.figures.plot_maps(tmp / "figure.pdf", m, measured=measured, delta_e=de, stats=stats,
                  title=title)
        if de is not None:
            np.save(tmp / "delta_e.npy", de.astype(np.float32))
        meta["timings_s"] = {**m.meta["timings_s"], "total": time.perf_counter() - t0}
        (tmp / "simulate.json").write_text(json.dumps(meta, indent=2))
    log.info("wrote %s in %.2f s", args.out, time.perf_counter() - t0)
    if not args.quiet:
        msg = f"wrote {args.out}/angular_map.png ({tl.size} x {tv.size} angles, {model})"
        if stats is not None:
            msg += (f"; mean dE00 {stats['mean']:.2f}, outside the specular band "
                    f"{stats['mean_excluding_specular']:.2f}")
        print(msg)
    return 0
