"""Optics: optical constants of the film and substrate, the thin-film (Airy) reflectance, and
the thickness from a measured spectrum.

==================  ==========================================================
module              concern
==================  ==========================================================
``constants``       bundled n + ik sets (refractiveindex.info, CC0)
``defaults``        the default film and substrate sets (``DEFAULT_FILM``, ...)
``thinfilm``        ambient / film / substrate reflectance, s, p, unpolarised
``spectrumfit``     oxide thickness of least squares to a spectrum (seed §2.5)
==================  ==========================================================
"""

from ..core.lazy import attach_stub

__getattr__, __dir__, __all__ = attach_stub(__name__, __file__)
