"""Height from focus into a folder (``microfacet height``): claim the output folder, read and
check the stack, compute the height map, its normals and the all-in-focus image, and write
them in one atomic step.

The folder (format ``microfacet-height/1``) holds ``height_um.npy`` (float32, NaN where
unreliable), ``normals.npy`` (float32 H×W×3, z up), ``reliability_db.npy`` +
``reliability.png``, ``all_in_focus.png``, a ``height.png`` preview and ``height.json``
(inputs, parameters, statistics, timings).
"""

from __future__ import annotations

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
from ..io.height_folder import HeightMaps, write_height_folder
from ..io.outdir import OutputFolder, check_output
from ..io.stack import Stack, StackSource

cv2 = load("cv2")

__all__ = ["HeightOutput", "height_to_folder"]

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
        :class:`~microfacet.io.stack.StackSource` with its pixel size and z step.
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
            timings = {**{k: round(v, 4) for k, v in res.timings_s.items()},
                       "height_from_focus": round(t1 - t0, 4), "normals": round(t2 - t1, 4),
                       "total": round(time.perf_counter() - t0, 4)}
            summary = _summary(st, res, tilt, smooth_sigma_px, timings)
            write_height_folder(tmp, HeightMaps(res.height_um, normals, res.reliability_db,
                                                res.all_in_focus,
                                                16 if st.dtype == np.uint16 else 8), summary)
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


def _summary(st: Stack, res: FocusResult, tilt, smooth_sigma_px, timings) -> dict:
    """The content of ``height.json``."""
    h = res.height_um
    ok = np.isfinite(h)
    return {
        "version": __version__,
        "stack": str(st.path),
        "shape": [int(s) for s in st.shape],
        "n_slices": st.n_slices,
        "pixel_size_um": st.pixel_size_um,
        "z_um_range": [float(st.z_um.min()), float(st.z_um.max())],
        "parameters": {**res.params, "smooth_sigma_px": smooth_sigma_px},
        "stats": {
            "unreliable_fraction": float(1.0 - ok.mean()),
            "height_um_percentiles_1_50_99": (
                [float(v) for v in np.percentile(h[ok], [1, 50, 99])] if ok.any() else None),
            "median_tilt_deg": (float(np.nanmedian(tilt)) if np.isfinite(tilt).any()
                                else None),
        },
        "timings_s": timings,
    }
