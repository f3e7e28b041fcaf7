"""Compatibility name: colorimetry lives in :mod:`microfacet.colour`.

``from microfacet.color import delta_e_2000`` is part of the project's public API
(shared/spec/api.md) and keeps working.
"""

from .colour.difference import delta_e_76, delta_e_94, delta_e_2000

__all__ = ["delta_e_2000", "delta_e_76", "delta_e_94"]
