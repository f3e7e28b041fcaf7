"""Colour: spectra to CIE XYZ and CIELAB, sRGB images, colour differences, and the
(incidence angle × thickness) colour table the analysis searches.

==================  ==========================================================
module              concern
==================  ==========================================================
``datasets``        CMFs and illuminant spectra (colour-science's tables)
``snapshot``        colour-science's tables and weights stored with the package
``colorimetry``     spectral weights, spectra → XYZ, XYZ ↔ Lab
``adaptation``      Bradford chromatic adaptation (colour-science's operations)
``transfer``        the sRGB transfer functions (decode / encode)
``srgb``            RGB ↔ XYZ, image ↔ Lab, model colours as sRGB
``difference``      CIEDE2000 (fast, float32), CIE94, CIE76, ``delta_e(method=)``
``table``           the colour table: model colour on a (θ, d) grid, with its error
``model``           :class:`FilmColourModel`: the film's colour as the microscope sees it
``arrays``          array checks the modules share (float dtypes kept, channels last)
==================  ==========================================================

Which parts delegate to colour-science and which are kept ours, with the measurements:
docs/colour-benchmarks.md. The names below are importable from ``microfacet.colour`` and
load on first use; ``import microfacet.colour`` imports neither colour-science nor the
submodules.
"""

from ..core.lazy import attach_stub

__getattr__, __dir__, __all__ = attach_stub(__name__, __file__)
