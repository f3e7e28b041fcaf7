"""Compatibility name: the thin-film model lives in :mod:`microfacet.optics.thinfilm`.

``from microfacet.thinfilm import reflectance`` is part of the project's public API
(shared/spec/api.md) and keeps working.
"""

from .optics.thinfilm import (
                              FresnelProducts,
                              fresnel_reflectance,
                              normal_wavevector,
                              reflectance,
                              reflectance_period_nm,
)

__all__ = ["FresnelProducts", "fresnel_reflectance", "normal_wavevector", "reflectance",
           "reflectance_period_nm"]
