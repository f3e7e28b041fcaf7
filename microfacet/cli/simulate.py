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

from .. import workflow
from ..core.errors import InputError
from .options import (
    HelpFormatter,
    add_optics_options,
    add_option_fields,
    example_epilog,
    optics_options,
    options_from_args,
)

_EXAMPLES = (
    "microfacet simulate --thickness-nm 51 --out sd-blue",
    "microfacet simulate --results nd-analysis --model microfacet --out nd-sim",
    'microfacet simulate --thickness-mixture "0.3:112:3,0.45:130:3,0.25:149:3" \\',
    '    --ndf-lobes "0.6:3,0.4:9" --model eq6 --lobe-exponent 80 --out nd-eq6',
    "microfacet simulate --results nd-analysis --model eq6 --compare measured.npz \\",
    "    --fit-exponent --fit-exposure --out nd-fit",
)
_DESCRIPTION = (
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
    "Optics given as options win over the results folder's. "
    "See docs/forward-simulation.md.")
#: The options of :class:`~microfacet.workflow.simulate.SimulateOptions` per help group.
_MODEL = ("model", "lobe_exponent")
_GRID = ("theta_max_deg", "theta_step_deg", "exposure", "spectral_step_nm")
_COMPARE = ("specular_halfwidth_deg", "fit_exponent", "fit_exposure")


def register(sub):
    p = sub.add_parser(
        "simulate",
        help="angular colour / spectral maps (half-vector, seed eq. 6, microfacet BRDF)",
        description=_DESCRIPTION, epilog=example_epilog(*_EXAMPLES),
        formatter_class=HelpFormatter,
    )
    src = p.add_argument_group("what to simulate")
    src.add_argument("--thickness-nm", type=float, default=None, metavar="NM",
                     help="one oxide thickness in nm (alone: the half-vector map)")
    src.add_argument("--results", default=None, metavar="DIR",
                     help="analysis results folder: fitted mixtures and optics from "
                          "DIR/summary.json")
    src.add_argument("--thickness-mixture", default=None, metavar="W:MEAN:SD,...",
                     help="thickness mixture, weight:mean_nm:sd_nm per component")
    src.add_argument("--ndf-lobes", default=None, metavar="W:SD,...",
                     help="NDF lobes, weight:sd_deg per zero-mean Gaussian-slope lobe")
    add_option_fields(src, workflow.SimulateOptions, only=_MODEL)
    p.add_argument("--out", required=True, metavar="OUT", help="output folder (must not exist)")
    add_option_fields(p, workflow.SimulateOptions, only=_GRID)
    cmp_ = p.add_argument_group("comparison with a measured map")
    cmp_.add_argument("--compare", default=None, metavar="MEASURED.npz",
                      help="measured angular map (microfacet-angular/1 .npz)")
    add_option_fields(cmp_, workflow.SimulateOptions, only=_COMPARE)
    p.add_argument("--overwrite", action="store_true", help="replace an existing OUT")
    add_optics_options(p)
    p.set_defaults(run=run)
    return p


def parse_thickness_mixture(text) -> list:
    """``"w:mean:sd,..."`` → ``[(w, mean_nm, sd_nm), ...]`` (an InputError names
    ``--thickness-mixture``)."""
    return _parse_components(text, 3, "thickness_mixture", "weight:mean_nm:sd_nm")


def parse_ndf_lobes(text) -> list:
    """``"w:sd_deg,..."`` → ``[(w, sd_deg), ...]`` (an InputError names ``--ndf-lobes``)."""
    return _parse_components(text, 2, "ndf_lobes", "weight:sd_deg")


def _parse_components(text, n, param, form):
    comps = []
    for part in str(text).split(","):
        if not part.strip():
            continue
        try:
            vals = tuple(float(v) for v in part.split(":"))
        except ValueError:
            vals = ()
        if len(vals) != n:
            raise InputError(f"{part.strip()!r} is not {form}", param=param)
        comps.append(vals)
    if not comps:
        raise InputError("no components", param=param)
    return comps


def run(args) -> int:
    """Parse the options, simulate (:func:`~microfacet.workflow.simulate.simulate_to_folder`)
    and print where the map was written (and the mean ΔE00 of a comparison)."""
    options = options_from_args(args, workflow.SimulateOptions, optics=optics_options(args))
    done = workflow.simulate_to_folder(
        args.out, results=args.results, thickness_nm=args.thickness_nm,
        thickness_mixture=(None if args.thickness_mixture is None
                           else parse_thickness_mixture(args.thickness_mixture)),
        ndf_lobes=None if args.ndf_lobes is None else parse_ndf_lobes(args.ndf_lobes),
        compare=args.compare, options=options, overwrite=args.overwrite)
    if not args.quiet:
        msg = (f"wrote {args.out}/angular_map.png ({done.shape[0]} x {done.shape[1]} angles, "
               f"{done.model})")
        if done.compare is not None:
            msg += (f"; mean dE00 {done.compare['mean']:.2f}, outside the specular band "
                    f"{done.compare['mean_excluding_specular']:.2f}")
        print(msg)
    return 0
