"""Defaults every layer shares, declared once (no numpy: the command line's help shows them).

``DEFAULT_ILLUMINANT = "D65"``
    The light a stack's images are white-balanced to when ``stack.json`` does not say, and
    the light of simulations and reports (the seed renders and compares under D65, §2.6).
``DEFAULT_OBSERVER = "2"``
    The CIE 1931 2° standard observer.

The defaults of the film and substrate sets are in :mod:`microfacet.optics.defaults`; those
of the analysis in :mod:`microfacet.analysis.options`.
"""

__all__ = ["DEFAULT_ILLUMINANT", "DEFAULT_OBSERVER"]

DEFAULT_ILLUMINANT = "D65"
DEFAULT_OBSERVER = "2"
