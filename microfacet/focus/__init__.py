"""Height from focus: focus measures, the streaming peak search, slice alignment, normals.

==================  ==========================================================
module              concern
==================  ==========================================================
``options``         :class:`FocusOptions`: the options of height from focus, their defaults
``measures``        how sharp each pixel is in one slice (Tenengrad, SML, GLV)
``height``          the one-pass height map, reliability, all-in-focus image
``slices``          the slices it reads: a stack, or images with their heights
``align``           registration of slices that drift or change magnification
``normals``         normals and tilt from a height map (µm-aware, NaN-aware)
==================  ==========================================================
"""

from ..core.lazy import attach

__getattr__, __dir__, __all__ = attach(__name__, submodules=(
    "options", "measures", "height", "align", "normals"), submod_attrs={
    "height": ["FocusResult", "fill_missing", "height_from_focus"],
    "measures": ["focus_measure"],
    "options": ["FocusOptions"],
    "normals": ["normals_from_height", "tilt_azimuth_deg"],
})
