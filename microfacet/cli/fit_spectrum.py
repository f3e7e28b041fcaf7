"""``microfacet fit-spectrum SPECTRUM.csv``: oxide thickness from a measured spectrum."""

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
            "the thickness, the RMS residual and the runner-up minimum: interference colours "
            "repeat with order, so a second minimum with a similar residual means the "
            "answer is ambiguous."),
        epilog=example_epilog("microfacet fit-spectrum sample2.csv --angle-deg 8",
                              "(CSV columns: wavelength_nm,reflectance; reflectance as a "
                              "fraction or in percent)"),
        formatter_class=HelpFormatter,
    )
    p.add_argument("spectrum", metavar="SPECTRUM.csv", help="wavelength_nm,reflectance CSV")
    p.add_argument("--angle-deg", type=float, default=0.0, metavar="DEG",
                   help="angle of incidence on the film in degrees (default 0)")
    p.add_argument("--thickness-range-nm", type=pair_type(":", float, "LOW:HIGH in nm"),
                   default=(0.0, 1000.0), metavar="LOW:HIGH",
                   help="thickness search range in nm (default 0:1000)")
    p.add_argument("--fit-scale", action="store_true",
                   help="also fit a multiplicative scale of the measured spectrum")
    p.add_argument("--json", action="store_true", help="print the result as JSON")
    add_optics_options(p)
    p.set_defaults(run=run)
    return p


def run(args) -> int:
    opt = optics_kwargs(args)
    wl, R = io.spectrum.read_spectrum_csv(args.spectrum)
    try:
        fit = optics.spectrumfit.fit_thickness(
            wl, R, angle_deg=args.angle_deg, film=opt["film"], substrate=opt["substrate"],
            fit_scale=args.fit_scale, thickness_range_nm=tuple(args.thickness_range_nm))
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
        "angle_deg": fit.angle_deg,
        "film": opt["film"],
        "substrate": opt["substrate"],
    }
    if args.json:
        print(json.dumps(result, indent=2))
    else:
        print(f"thickness_nm  {fit.thickness_nm:.2f}   (RMS residual {fit.residual_rms:.4g})")
        print(f"runner-up     {fit.runner_up_thickness_nm:.2f}   "
              f"(RMS residual {fit.runner_up_residual_rms:.4g})")
        if args.fit_scale:
            print(f"scale         {fit.scale:.4f}")
    return 0
