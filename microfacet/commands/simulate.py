"""``microfacet simulate``: forward angular colour maps."""

from __future__ import annotations

import argparse

from ._common import add_optics_options, example_epilog, optics_kwargs


def register(sub):
    p = sub.add_parser(
        "simulate",
        help="angular colour map of a film (half-vector model, seed Fig. 10)",
        description=(
            "Predict the interference colour over a grid of in-plane light and view zenith "
            "angles with the half-vector thin-film model (seed §2.3-2.4): the facets that "
            "reflect light into the view are seen at half the angle between the two. "
            "Writes angular_lab.npy (L x V x 3), angular_xyz.npy, angular_map.png "
            "(rows: light angle, columns: view angle) and simulate.json."),
        epilog=example_epilog("microfacet simulate --thickness-nm 51 --out sd-blue"),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--thickness-nm", type=float, required=True, help="oxide thickness in nm")
    p.add_argument("--out", required=True, help="output folder (must not exist)")
    p.add_argument("--theta-max-deg", type=float, default=85.0,
                   help="largest light and view zenith angle (default 85)")
    p.add_argument("--theta-step-deg", type=float, default=1.0,
                   help="angle grid step (default 1)")
    p.add_argument("--exposure", type=float, default=1.0,
                   help="reflectance scale for display (default 1)")
    p.add_argument("--overwrite", action="store_true", help="replace an existing --out")
    add_optics_options(p)
    p.set_defaults(run=run)
    return p


def run(args) -> int:
    import json
    import logging
    import time

    import numpy as np

    from .. import __version__
    from ..halfvector import angular_colour_map
    from ..outdir import atomic_output_dir

    log = logging.getLogger("microfacet.simulate")
    opt = optics_kwargs(args)
    if not (0 < args.theta_max_deg < 90):
        raise ValueError("--theta-max-deg: must be in (0, 90)")
    if not (0 < args.theta_step_deg <= args.theta_max_deg):
        raise ValueError("--theta-step-deg: must be > 0 and <= --theta-max-deg")
    t0 = time.perf_counter()
    grid = np.arange(0.0, args.theta_max_deg + 1e-9, args.theta_step_deg)
    m = angular_colour_map(args.thickness_nm, theta_light_deg=grid, theta_view_deg=grid,
                           exposure=args.exposure, **opt)
    with atomic_output_dir(args.out, overwrite=args.overwrite) as tmp:
        np.save(tmp / "angular_lab.npy", m.lab)
        np.save(tmp / "angular_xyz.npy", m.xyz.astype(np.float32))
        np.save(tmp / "theta_light_deg.npy", m.theta_light_deg)
        np.save(tmp / "theta_view_deg.npy", m.theta_view_deg)
        m.save_png(tmp / "angular_map.png", scale=4)
        (tmp / "simulate.json").write_text(json.dumps({
            "format": "microfacet-simulate/1", "model": "half-vector",
            "thickness_nm": m.thickness_nm, "exposure": m.exposure,
            "theta_light_deg": [float(grid[0]), float(grid[-1]), float(args.theta_step_deg)],
            "theta_view_deg": [float(grid[0]), float(grid[-1]), float(args.theta_step_deg)],
            **opt, "version": __version__,
            "timings_s": {"total": time.perf_counter() - t0},
        }, indent=2))
    log.info("wrote %s in %.2f s", args.out, time.perf_counter() - t0)
    if not args.quiet:
        print(f"wrote {args.out}/angular_map.png ({grid.size} x {grid.size} angles)")
    return 0
