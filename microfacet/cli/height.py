"""``microfacet height STACK --out OUT``: height from focus only.

Writes ``height_um.npy`` (float32, NaN where unreliable), ``normals.npy`` (float32 H×W×3, z up),
``all_in_focus.png``, ``reliability_db.npy`` + ``reliability.png``, a ``height.png`` preview and
``height.json`` (inputs, parameters, statistics, timings). The folder is written under a
temporary name beside OUT and renamed when complete.
"""

from __future__ import annotations

import argparse
import json
import logging
import time
from pathlib import Path

from .. import __version__, focus, io
from ..core.errors import InputError
from ..core.lazy import load
from ..focus.defaults import (
    DEFAULT_FIT_RADIUS,
    DEFAULT_INTERPOLATION,
    DEFAULT_OPERATOR,
    DEFAULT_WINDOW,
    DEFAULT_WINDOW_PX,
    INTERPOLATIONS,
    OPERATORS,
)
from .options import (
    HelpFormatter,
    add_limit_options,
    add_plain_folder_options,
    limits_from_args,
    plain_folder_values,
)
from .progress import Progress

cv2 = load("cv2")
np = load("numpy")

EPILOG = """examples:
  microfacet height my-stack --out my-stack-height
  microfacet height my-stack --out h --operator sml --window-px 9 --fill --overwrite
  microfacet height folder-of-jpegs --pixel-size-um 0.5 --z-step-um 1 --out h --align
"""


def register(subparsers) -> argparse.ArgumentParser:
    p = subparsers.add_parser(
        "height",
        help="height map, normals and all-in-focus image from a focus stack",
        description=(
            "Height from focus: for every pixel the stage height where it is sharpest "
            "(sub-slice least-squares peak fit), a Pertuz-style reliability map in dB, unit "
            "normals from the height and the pixel size, and the all-in-focus composite."),
        epilog=EPILOG, formatter_class=HelpFormatter)

    p.add_argument("stack", metavar="STACK",
                   help="stack folder with stack.json (or its stack.json)")
    p.add_argument("--out", required=True, metavar="OUT",
                   help="output folder (new, empty, or an earlier height folder with "
                        "--overwrite; never an input or a folder holding one)")
    p.add_argument("--operator", choices=OPERATORS, default=DEFAULT_OPERATOR,
                   help="focus measure (default: %(default)s)")
    p.add_argument("--window-px", type=int, default=DEFAULT_WINDOW_PX, metavar="N",
                   help="odd focus window side in pixels (default: %(default)s)")
    p.add_argument("--window", choices=("gaussian", "box"), default=DEFAULT_WINDOW,
                   help="focus window shape (default: %(default)s)")
    p.add_argument("--interpolation", choices=INTERPOLATIONS, default=DEFAULT_INTERPOLATION,
                   help="sub-slice peak estimate (default: %(default)s)")
    p.add_argument("--fit-radius", type=int, default=DEFAULT_FIT_RADIUS, metavar="R",
                   help="slices each side of the peak used by 'lsq' (default: %(default)s)")
    p.add_argument("--min-reliability-db", type=float, default=None, metavar="DB",
                   help="reliability cut in dB (default: per operator, 12 for tenengrad)")
    p.add_argument("--fill", nargs="?", const="smooth", choices=("smooth", "nearest"),
                   default=None, help="fill unreliable pixels (default method: smooth)")
    p.add_argument("--align", nargs="?", const="ecc", choices=("ecc", "phase"), default=None,
                   help="register slices to a reference first (default method: ecc)")
    p.add_argument("--smooth-sigma-px", type=float, default=0.0, metavar="S",
                   help="Gaussian smoothing of the slopes for the normals, px (default: 0)")
    add_plain_folder_options(p)
    add_limit_options(p)
    p.add_argument("--overwrite", action="store_true",
                   help="replace OUT if it is an earlier microfacet height folder")
    p.set_defaults(run=run)
    return p


def _load_stack(args):
    pixel_size_um, z_step_um = plain_folder_values(args)
    if pixel_size_um is not None:
        path = Path(args.stack)
        return io.stack.stack_from_images(path.parent if path.name == "stack.json" else path,
                                          pixel_size_um=pixel_size_um, z_step_um=z_step_um,
                                          limits=limits_from_args(args))
    return io.stack.read_stack(args.stack, limits=limits_from_args(args))


def _height_png(h):
    """Viridis preview of a height map, NaN black; returns BGR uint8."""
    ok = np.isfinite(h)
    out = np.zeros(h.shape + (3,), np.uint8)
    if ok.any():
        lo, hi = np.percentile(h[ok], [0.5, 99.5])
        v = np.clip((h - lo) / max(hi - lo, 1e-12), 0, 1)
        v8 = np.where(ok, np.round(v * 255), 0).astype(np.uint8)
        out = cv2.applyColorMap(v8, cv2.COLORMAP_VIRIDIS)
        out[~ok] = 0
    return out


def run(args) -> int:
    log = logging.getLogger("microfacet.height")
    t0 = time.perf_counter()
    out = Path(args.out)
    io.outdir.check_output(out, kind="height", inputs=[args.stack], overwrite=args.overwrite)
    if args.window_px < 1 or args.window_px % 2 == 0:
        raise InputError(f"--window-px: must be an odd integer >= 1, got {args.window_px}")
    if not args.smooth_sigma_px >= 0:
        raise InputError(f"--smooth-sigma-px: must be >= 0, got {args.smooth_sigma_px}")
    stack = _load_stack(args)            # validates everything before any work
    if not stack.has_slices:
        raise InputError(f"{stack.path / 'stack.json'}: the stack is a microscope export "
                         f"without slices; height from focus needs 'slices' or 'tiff'")
    if stack.n_slices < 3:
        raise InputError(f"{stack.path / 'stack.json'}: key 'slices': height from focus needs "
                         f"at least 3 slices, the stack has {stack.n_slices}")
    focus.height.check_focus_memory(stack)
    claim = io.outdir.OutputFolder(out, kind="height", inputs=[stack.path],
                                   overwrite=args.overwrite,
                         expected_bytes=32 * stack.shape[0] * stack.shape[1])
    with claim:
        with Progress("height", total=stack.n_slices, unit="slices", quiet=args.quiet) as bar:
            res = focus.height.height_from_focus(
                stack, operator=args.operator, window_px=args.window_px, window=args.window,
                interpolation=args.interpolation, fit_radius=args.fit_radius,
                min_reliability_db=args.min_reliability_db, fill=args.fill,
                align=args.align or False, progress=bar.update)
        t1 = time.perf_counter()
        normals = focus.normals.normals_from_height(res.height_um,
                                                    pixel_size_um=stack.pixel_size_yx_um,
                                      smooth_sigma_px=args.smooth_sigma_px)
        tilt, _ = focus.normals.tilt_azimuth_deg(normals)
        t2 = time.perf_counter()

        with claim.writing() as tmp:
            np.save(tmp / "height_um.npy", res.height_um.astype(np.float32))
            np.save(tmp / "normals.npy", normals.astype(np.float32))
            np.save(tmp / "reliability_db.npy", res.reliability_db.astype(np.float32))
            io.images.write_image(tmp / "all_in_focus.png", res.all_in_focus,
                        bit_depth=16 if stack.dtype == np.uint16 else 8)
            rel8 = np.round(np.clip(res.reliability_db, 0, 40) / 40 * 255).astype(np.uint8)
            io.images.write_image(tmp / "reliability.png", rel8)
            io.images.write_image(tmp / "height.png",
                                  _height_png(res.height_um)[..., ::-1])  # BGR → RGB
            h = res.height_um
            ok = np.isfinite(h)
            summary = {
                "format": "microfacet-height/1",
                "version": __version__,
                "stack": str(stack.path),
                "shape": [int(s) for s in stack.shape],
                "n_slices": stack.n_slices,
                "pixel_size_um": stack.pixel_size_um,
                "z_um_range": [float(stack.z_um.min()), float(stack.z_um.max())],
                "parameters": {**res.params, "smooth_sigma_px": args.smooth_sigma_px},
                "files": {
                    "height_um.npy": "float32 HxW height in µm, NaN where unreliable",
                    "normals.npy": "float32 HxWx3 unit normals (x right, y up, z up)",
                    "all_in_focus.png": "composite of each pixel's sharpest slice",
                    "reliability_db.npy": "float32 HxW reliability in dB",
                    "reliability.png": "reliability 0..40 dB mapped to 0..255",
                    "height.png": "viridis preview of the height (0.5-99.5 percentile), NaN black",
                },
                "stats": {
                    "unreliable_fraction": float(1.0 - ok.mean()),
                    "height_um_percentiles_1_50_99": (
                        [float(v) for v in np.percentile(h[ok], [1, 50, 99])]
                        if ok.any() else None),
                    "median_tilt_deg": (float(np.nanmedian(tilt))
                                        if np.isfinite(tilt).any() else None),
                },
                "timings_s": {**{k: round(v, 4) for k, v in res.timings_s.items()},
                              "height_from_focus": round(t1 - t0, 4),
                              "normals": round(t2 - t1, 4),
                              "total": round(time.perf_counter() - t0, 4)},
            }
            (tmp / "height.json").write_text(json.dumps(summary, indent=2) + "\n", encoding="utf-8")
    log.info("wrote %s (%.1f%% unreliable) in %.2f s", out, 100 * (1 - ok.mean()),
             time.perf_counter() - t0)
    return 0
