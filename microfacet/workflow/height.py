"""Height from focus into a folder (``microfacet height``): claim the output folder, read and
check the stack, compute the height map, its normals and the all-in-focus image, and write
them in one atomic step.

The folder (format ``microfacet-height/1``) holds ``height_um.npy`` (float32, NaN where
unreliable), ``normals.npy`` (float32 H×W×3, z up), ``reliability_db.npy`` +
``reliability.png``, ``all_in_focus.png``, a ``height.png`` preview and ``height.json``
(inputs, parameters, statistics, timings).
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .. import __version__
from ..core.errors import InputError
from ..core.lazy import load
from ..focus.height import FocusResult, check_focus_memory, height_from_focus
from ..focus.normals import normals_from_height, tilt_azimuth_deg
from ..focus.options import FocusOptions
from ..io.images import write_image
from ..io.outdir import OutputFolder, check_output
from ..io.stack import Stack
from .analyse import StackSource

cv2 = load("cv2")

__all__ = ["HEIGHT_FILES", "HEIGHT_FORMAT", "HeightOutput", "height_to_folder"]

#: ``format`` of ``height.json`` (how :func:`microfacet.io.outdir.output_kind` knows it).
HEIGHT_FORMAT = "microfacet-height/1"
#: The files of a height folder and what they hold (recorded in ``height.json``).
HEIGHT_FILES = {
    "height_um.npy": "float32 HxW height in µm, NaN where unreliable",
    "normals.npy": "float32 HxWx3 unit normals (x right, y up, z up)",
    "all_in_focus.png": "composite of each pixel's sharpest slice",
    "reliability_db.npy": "float32 HxW reliability in dB",
    "reliability.png": "reliability 0..40 dB mapped to 0..255",
    "height.png": "viridis preview of the height (0.5-99.5 percentile), NaN black",
}
#: Bytes per pixel a height folder takes at most (checked against the free space).
BYTES_PER_PIXEL = 32


@dataclass(frozen=True)
class HeightOutput:
    """What :func:`height_to_folder` wrote.

    Attributes
    ----------
    out : Path
        The height folder.
    stack : Path
        The stack folder it was computed from.
    shape : tuple of int
        ``(H, W)`` of the maps.
    n_slices : int
    unreliable_fraction : float
        Share of the pixels without a reliable height (NaN in ``height_um.npy`` unless
        filled).
    timings_s : dict
        Wall times, as in ``height.json``.
    """

    out: Path
    stack: Path
    shape: tuple
    n_slices: int
    unreliable_fraction: float
    timings_s: dict


def height_to_folder(stack, out, *, options: FocusOptions | None = None,
                     smooth_sigma_px: float = 0.0, overwrite: bool = False,
                     progress: Callable[[int, int], None] | None = None) -> HeightOutput:
    """Height from focus of one stack, written to the folder ``out`` in one atomic step.

    The output folder is checked before the stack is read, and the stack (its headers, its
    slices, the memory the height step needs) before any work.

    Parameters
    ----------
    stack : path-like, StackSource or Stack
        A stack folder, or a plain folder of images as a
        :class:`~microfacet.workflow.analyse.StackSource` with its pixel size and z step.
    out : path-like
        The height folder (the rules of :mod:`microfacet.io.outdir`).
    options : FocusOptions, optional
        Options of :func:`~microfacet.focus.height.height_from_focus`.
    smooth_sigma_px : float
        Gaussian smoothing of the slopes for the normals, px (0: none).
    overwrite : bool
        Replace an earlier height folder.
    progress : callable(done, total), optional
        Called after each slice.

    Returns
    -------
    HeightOutput

    Raises
    ------
    InputError
        A bad ``out``, stack or ``smooth_sigma_px``, a stack without slices or with fewer
        than 3, or one too large for the memory.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> from microfacet.io.stack import write_stack
    >>> d = pathlib.Path(tempfile.mkdtemp())
    >>> rng = np.random.default_rng(0)
    >>> tex = rng.random((40, 48)).astype(np.float32)
    >>> imgs = [cv2.GaussianBlur(tex, (0, 0), 0.5 + 0.6 * abs(z - 2.2)) for z in range(6)]
    >>> _ = write_stack(d / "s", [np.round(im * 255).astype(np.uint8) for im in imgs],
    ...                 z_step_um=1.0, pixel_size_um=0.5)
    >>> res = height_to_folder(d / "s", d / "h")
    >>> res.n_slices, sorted(p.name for p in res.out.iterdir())[:3]
    (6, ['all_in_focus.png', 'height.json', 'height.png'])
    """
    t0 = time.perf_counter()
    options = FocusOptions() if options is None else options
    if not smooth_sigma_px >= 0:
        raise InputError(f"must be >= 0, got {smooth_sigma_px}", param="smooth_sigma_px")
    check_output(out, kind="height", inputs=[_path_of(stack)], overwrite=overwrite)
    st = _open_for_height(stack)
    H, W = st.shape
    with OutputFolder(out, kind="height", inputs=[st.path], overwrite=overwrite,
                      expected_bytes=BYTES_PER_PIXEL * H * W) as claim:
        res = height_from_focus(st, options, progress=progress)
        t1 = time.perf_counter()
        normals = normals_from_height(res.height_um, pixel_size_um=st.pixel_size_yx_um,
                                      smooth_sigma_px=smooth_sigma_px)
        tilt, _ = tilt_azimuth_deg(normals)
        t2 = time.perf_counter()
        with claim.writing() as tmp:
            _write_maps(tmp, st, res, normals)
            timings = {**{k: round(v, 4) for k, v in res.timings_s.items()},
                       "height_from_focus": round(t1 - t0, 4), "normals": round(t2 - t1, 4),
                       "total": round(time.perf_counter() - t0, 4)}
            summary = _summary(st, res, tilt, smooth_sigma_px, timings)
            (tmp / "height.json").write_text(json.dumps(summary, indent=2) + "\n",
                                             encoding="utf-8")
    return HeightOutput(Path(out), st.path, (H, W), st.n_slices,
                        float(summary["stats"]["unreliable_fraction"]), timings)


def _path_of(stack):
    return stack.path if isinstance(stack, (Stack, StackSource)) else stack


def _open_for_height(stack) -> Stack:
    """The validated stack, refused when it has no slices (an export only), fewer than 3,
    or would not fit in memory."""
    st = stack if isinstance(stack, Stack) else (
        stack if isinstance(stack, StackSource) else StackSource(stack)).open()
    if not st.has_slices:
        raise InputError(f"{st.path / 'stack.json'}: the stack is a microscope export "
                         f"without slices; height from focus needs 'slices' or 'tiff'")
    if st.n_slices < 3:
        raise InputError(f"{st.path / 'stack.json'}: key 'slices': height from focus needs "
                         f"at least 3 slices, the stack has {st.n_slices}")
    check_focus_memory(st)
    return st


def _write_maps(folder: Path, st: Stack, res: FocusResult, normals) -> None:
    """The arrays and images of :data:`HEIGHT_FILES` (all but height.json)."""
    np.save(folder / "height_um.npy", res.height_um.astype(np.float32))
    np.save(folder / "normals.npy", normals.astype(np.float32))
    np.save(folder / "reliability_db.npy", res.reliability_db.astype(np.float32))
    write_image(folder / "all_in_focus.png", res.all_in_focus,
                bit_depth=16 if st.dtype == np.uint16 else 8)
    rel8 = np.round(np.clip(res.reliability_db, 0, 40) / 40 * 255).astype(np.uint8)
    write_image(folder / "reliability.png", rel8)
    write_image(folder / "height.png", height_preview(res.height_um)[..., ::-1])  # BGR → RGB


def height_preview(h: np.ndarray) -> np.ndarray:
    """Viridis preview of a height map (0.5-99.5 percentile), NaN black; BGR uint8.

    >>> height_preview(np.array([[0.0, np.nan], [1.0, 2.0]], np.float32))[0, 1].tolist()
    [0, 0, 0]
    """
    ok = np.isfinite(h)
    out = np.zeros(h.shape + (3,), np.uint8)
    if ok.any():
        lo, hi = np.percentile(h[ok], [0.5, 99.5])
        v = np.clip((h - lo) / max(hi - lo, 1e-12), 0, 1)
        v8 = np.where(ok, np.round(v * 255), 0).astype(np.uint8)
        out = cv2.applyColorMap(v8, cv2.COLORMAP_VIRIDIS)
        out[~ok] = 0
    return out


def _summary(st: Stack, res: FocusResult, tilt, smooth_sigma_px, timings) -> dict:
    """The content of ``height.json``."""
    h = res.height_um
    ok = np.isfinite(h)
    return {
        "format": HEIGHT_FORMAT,
        "version": __version__,
        "stack": str(st.path),
        "shape": [int(s) for s in st.shape],
        "n_slices": st.n_slices,
        "pixel_size_um": st.pixel_size_um,
        "z_um_range": [float(st.z_um.min()), float(st.z_um.max())],
        "parameters": {**res.params, "smooth_sigma_px": smooth_sigma_px},
        "files": dict(HEIGHT_FILES),
        "stats": {
            "unreliable_fraction": float(1.0 - ok.mean()),
            "height_um_percentiles_1_50_99": (
                [float(v) for v in np.percentile(h[ok], [1, 50, 99])] if ok.any() else None),
            "median_tilt_deg": (float(np.nanmedian(tilt)) if np.isfinite(tilt).any()
                                else None),
        },
        "timings_s": timings,
    }
