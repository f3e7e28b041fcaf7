"""``microfacet fit-spectrum SPECTRUM``: oxide thickness from a measured spectrum."""

from __future__ import annotations

import json

from .. import io, optics
from ..core.errors import InputError
from .options import HelpFormatter, add_optics_options, example_epilog, optics_kwargs, pair_type


def register(sub):
    p = sub.add_parser(
        "fit-spectrum",
        help="oxide thickness from a measured spectral reflectance (seed §2.5)",
        description=(
            "Fit the oxide thickness whose thin-film reflectance best matches a measured "
            "spectrum (least squares over a global thickness grid, then refinement). Prints "
            "what was assumed in reading the file, the thickness, the RMS residual and the "
            "runner-up minimum: interference colours repeat with order, so a second minimum "
            "with a similar residual means the answer is ambiguous. The file may be any "
            "spectrometer's text export: comma, semicolon, tab or whitespace delimited, with "
            "or without a header (names such as Wavelength (nm), lambda, R, %R, "
            "Reflectance (%)), wavelengths in nm or µm, reflectance as a fraction or in "
            "percent (see docs/fit-spectrum.md). The spectrum's absolute level is fitted "
            "(one scale) unless --fix-scale."),
        epilog=example_epilog(
            "microfacet fit-spectrum fixtures/spectra/tio2-80nm-spectrometer.csv",
            "microfacet fit-spectrum export.txt --columns 'Wavelength,%R' --angle-deg 8",
            "microfacet fit-spectrum calibrated.csv --fix-scale --json"),
        formatter_class=HelpFormatter,
    )
    p.add_argument("spectrum", metavar="SPECTRUM",
                   help="spectrum as delimited text (wavelength and reflectance columns)")
    p.add_argument("--columns", default=None, metavar="WL,R",
                   help="the wavelength and reflectance columns, by header name or 1-based "
                        "number (default: found from the header, else columns 1 and 2)")
    p.add_argument("--angle-deg", type=float, default=0.0, metavar="DEG",
                   help="angle of incidence on the film in degrees (default 0)")
    p.add_argument("--thickness-range-nm", type=pair_type(":", float, "LOW:HIGH in nm"),
                   default=(0.0, 1000.0), metavar="LOW:HIGH",
                   help="thickness search range in nm (default 0:1000)")
    scale = p.add_mutually_exclusive_group()
    scale.add_argument("--fix-scale", action="store_true",
                       help="trust the spectrum's absolute level instead of fitting one "
                            "multiplicative scale (only for a calibrated reflectance; warns "
                            "when the data look scaled)")
    scale.add_argument("--fit-scale", action="store_true",
                       help="fit one multiplicative scale of the spectrum (the default)")
    p.add_argument("--json", action="store_true", help="print the result as JSON")
    add_optics_options(p)
    p.set_defaults(run=run)
    return p


def run(args) -> int:
    opt = optics_kwargs(args)
    spectrum = io.spectrum.read_spectrum(args.spectrum, columns=args.columns)
    fit_scale = not args.fix_scale
    try:
        fit = optics.spectrumfit.fit_thickness(
            spectrum.wavelength_nm, spectrum.reflectance, angle_deg=args.angle_deg,
            film=opt["film"], substrate=opt["substrate"], fit_scale=fit_scale,
            thickness_range_nm=tuple(args.thickness_range_nm))
    except InputError as exc:
        if exc.param in ("angle_deg", "thickness_range_nm"):
            raise  # an option: the command line names its flag
        raise InputError(f"{args.spectrum}: {exc}") from None  # the data in the file
    result = {
        "thickness_nm": round(fit.thickness_nm, 3),
        "residual_rms": fit.residual_rms,
        "runner_up_thickness_nm": round(fit.runner_up_thickness_nm, 3),
        "runner_up_residual_rms": fit.runner_up_residual_rms,
        "scale": fit.scale,
        "scale_fitted": fit.scale_fitted,
        "angle_deg": fit.angle_deg,
        "film": opt["film"],
        "substrate": opt["substrate"],
        "columns": list(spectrum.columns),
        "n_samples": int(spectrum.wavelength_nm.size),
        "notes": list(spectrum.notes),
    }
    if args.json:
        print(json.dumps(result, indent=2))
    else:
        for note in spectrum.notes:
            print(f"read          {note}")
        print(f"thickness_nm  {fit.thickness_nm:.2f}   (RMS residual {fit.residual_rms:.4g})")
        print(f"runner-up     {fit.runner_up_thickness_nm:.2f}   "
              f"(RMS residual {fit.runner_up_residual_rms:.4g})")
        print(f"scale         {fit.scale:.4f}   "
              f"({'fitted' if fit.scale_fitted else 'fixed by --fix-scale'})")
    return 0
