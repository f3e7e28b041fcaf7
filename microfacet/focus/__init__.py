"""Height from focus: focus measures, the streaming peak search, slice alignment, normals.

==================  ==========================================================
module              concern
==================  ==========================================================
``options``         :class:`FocusOptions`: the options of height from focus, their defaults
``measures``        how sharp each pixel is in one slice (Tenengrad, SML, GLV)
``height``          the one-pass height map, reliability, all-in-focus image
``stream``          the running peak of every pixel's focus curve
``peaks``           sub-slice peak fit, its variance, the Pertuz reliability
``uncertainty``     height, its uncertainty and the decision per focus window
``fill``            filling the unreliable pixels of a height map
``slices``          the slices it reads: a stack, or images with their heights
``align``           registration of slices that drift or change magnification
``normals``         normals and tilt from a height map (µm-aware, NaN-aware)
==================  ==========================================================
"""

from ..core.lazy import attach_stub

__getattr__, __dir__, __all__ = attach_stub(__name__, __file__)
