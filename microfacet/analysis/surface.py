"""The surface stages: the height map (from focus, or a microscope's export) and its
normals and tilt (seed §3.3.3 step 1)."""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass

import numpy as np

from ..core.errors import InputError
from ..focus.fill import fill_missing
from ..focus.height import FocusResult, height_from_focus
from ..focus.normals import normals_from_height, tilt_azimuth_deg
from ..focus.options import FocusOptions

__all__ = ["Surface", "measure_height", "surface_normals"]

log = logging.getLogger(__name__)


def _export_as_focus(stack) -> FocusResult:
    """A :class:`~microfacet.focus.height.FocusResult` from a microscope export (``height_um``
    + ``image`` in stack.json): the height map as given (non-finite = unreliable), the export
    image as the all-in-focus composite, no focus measure (reliability NaN)."""
    t0 = time.perf_counter()
    h = stack.read_export_height()
    img = stack.read_export_image()
    shape = h.shape
    return FocusResult(
        height_um=h, height_fit_um=h.copy(), reliability_db=np.full(shape, np.nan, np.float32),
        reliable=np.isfinite(h), best_index=np.zeros(shape, np.int32),
        focus_max=np.full(shape, np.nan, np.float32), all_in_focus=img,
        z_um=np.zeros(0), params={"source": "microscope export"},
        timings_s={"total": round(time.perf_counter() - t0, 4)})


def measure_height(stack, options: FocusOptions) -> FocusResult:
    """Height from focus of the stack's slices (:func:`~microfacet.focus.height.
    height_from_focus` with the ``focus`` section of the options), or the export's own
    height map.

    Raises
    ------
    InputError
        A stack of slices with fewer than 3 of them (naming stack.json and 'slices').
    """
    if not stack.has_slices:
        return _export_as_focus(stack)
    if stack.n_slices < 3:
        raise InputError(f"{stack.path / 'stack.json'}: key 'slices': height from focus needs "
                         f"at least 3 slices, the stack has {stack.n_slices}")
    return height_from_focus(stack, options)


@dataclass
class Surface:
    """The measured surface.

    Attributes
    ----------
    focus : FocusResult
        Height (NaN where unreliable), the unmasked fit, reliability, composite image.
    normals : ndarray (H, W, 3)
        From the height map with its holes filled (slopes smoothed by ``smooth_sigma_px``).
    tilt_deg : ndarray (H, W)
        Tilt of those normals, degrees.
    no_focus : bool
        True when no pixel has a reliable height: the surface is taken as flat.
    """

    focus: FocusResult
    normals: np.ndarray
    tilt_deg: np.ndarray
    no_focus: bool


def surface_normals(focus: FocusResult, *, pixel_size_um, smooth_sigma_px: float = 0.0,
                    where="") -> Surface:
    """Normals and tilt from the height map, its unreliable pixels filled smoothly, its
    slopes smoothed by ``smooth_sigma_px`` (the focus options' ``slope_sigma_px`` for a
    height from focus; 0 for an instrument's map, whose slopes are then its central
    differences).

    With no reliable pixel at all (identical or featureless slices) the fitted height is
    rounding noise: the surface is taken as flat (tilt 0) and a warning is logged; the
    facet planes then get no weight and tilts come from colour alone
    (``summary.json`` ``height.unreliable_fraction`` = 1).
    """
    no_focus = not focus.reliable.any()
    if no_focus:
        log.warning("%s: no pixel has a reliable height (the slices carry no focus "
                    "information); the surface is taken as flat and facet tilts come from "
                    "colour alone", where)
        filled = np.zeros(focus.height_um.shape, np.float32)
    elif np.isnan(focus.height_um).any():
        filled = fill_missing(focus.height_um, method="smooth")
    else:
        filled = focus.height_um
    normals = normals_from_height(filled, pixel_size_um=pixel_size_um,
                                  smooth_sigma_px=smooth_sigma_px)
    tilt, _ = tilt_azimuth_deg(normals)
    return Surface(focus, normals, tilt, no_focus)
