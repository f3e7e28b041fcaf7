"""The bottom layer: errors, deferred imports, the two distributions and their densities,
shared result types (the angular map) and stage timing. Imports nothing else of microfacet."""

from .lazy import attach

__getattr__, __dir__, __all__ = attach(__name__, submodules=(
    "angular", "densities", "distributions", "errors", "lazy", "pixels", "timing"), submod_attrs={
    "distributions": ["NDFMixture", "ThicknessMixture"],
    "errors": ["InputError"],
    "angular": ["AngularMap"],
})
