"""Optics: optical constants of the film and substrate, the thin-film (Airy) reflectance, and
the thickness from a measured spectrum.

==================  ==========================================================
module              concern
==================  ==========================================================
``constants``       bundled n + ik sets (refractiveindex.info, CC0), the defaults
``thinfilm``        ambient / film / substrate reflectance, s, p, unpolarised
``spectrumfit``     oxide thickness of least squares to a spectrum (seed §2.5)
==================  ==========================================================
"""

from ..core.lazy import attach

__getattr__, __dir__, __all__ = attach(__name__, submodules=(
    "constants", "thinfilm", "spectrumfit"), submod_attrs={
    "constants": ["DEFAULT_FILM", "DEFAULT_SUBSTRATE", "OpticalConstantSet", "known_sets",
                  "load_set", "optical_constants", "resolve_index"],
    "thinfilm": ["reflectance"],
    "spectrumfit": ["SpectrumFit", "fit_thickness"],
})
