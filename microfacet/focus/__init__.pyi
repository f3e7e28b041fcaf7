from . import (
    align,
    fill,
    height,
    measures,
    normals,
    options,
    peaks,
    slices,
    stream,
    uncertainty,
)
from .fill import fill_missing
from .height import FocusResult, height_from_focus
from .measures import focus_measure
from .normals import normals_from_height, tilt_azimuth_deg
from .options import FocusOptions

__all__ = [
    "FocusOptions",
    "FocusResult",
    "align",
    "fill",
    "fill_missing",
    "focus_measure",
    "height",
    "height_from_focus",
    "measures",
    "normals",
    "normals_from_height",
    "options",
    "peaks",
    "slices",
    "stream",
    "tilt_azimuth_deg",
    "uncertainty",
]
