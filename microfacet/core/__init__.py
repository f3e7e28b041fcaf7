"""The bottom layer: errors, deferred imports, the two distributions and their densities,
shared result types (the angular map) and stage timing. Imports nothing else of microfacet."""

from .lazy import attach_stub

__getattr__, __dir__, __all__ = attach_stub(__name__, __file__)
