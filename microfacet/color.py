"""Compatibility name: colour differences live in :mod:`microfacet.colour.difference`.

``from microfacet.color import delta_e_2000`` is part of the API outside scripts rely on
(docs/api.md) and keeps working; importing this module warns that the name has moved.
"""

import warnings

from .colour.difference import delta_e_76, delta_e_94, delta_e_2000

__all__ = ["delta_e_2000", "delta_e_76", "delta_e_94"]

warnings.warn("microfacet.color is a compatibility name (docs/api.md): import delta_e from "
              "microfacet or microfacet.colour.difference", DeprecationWarning, stacklevel=2)
