"""Height from focus: focus measures, the streaming peak search, slice alignment, normals.

==================  ==========================================================
module              concern
==================  ==========================================================
``measures``        how sharp each pixel is in one slice (Tenengrad, SML, GLV)
``height``          the one-pass height map, reliability, all-in-focus image
``align``           registration of slices that drift or change magnification
``normals``         normals and tilt from a height map (µm-aware, NaN-aware)
==================  ==========================================================
"""

from ..core.lazy import attach

__getattr__, __dir__, __all__ = attach(__name__, submodules=(
    "measures", "height", "align", "normals"), submod_attrs={
    "height": ["FocusResult", "fill_missing", "height_from_focus"],
    "measures": ["focus_measure"],
    "normals": ["normals_from_height", "tilt_azimuth_deg"],
})
