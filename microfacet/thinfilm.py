"""Compatibility name: the thin-film model lives in :mod:`microfacet.optics.thinfilm`.

``from microfacet.thinfilm import reflectance`` is part of the API outside scripts rely on
(docs/api.md) and keeps working; importing this module warns that the name has moved.
"""

import warnings

from .optics.thinfilm import (
    FresnelProducts,
    fresnel_reflectance,
    normal_wavevector,
    reflectance,
    reflectance_period_nm,
)

__all__ = ["FresnelProducts", "fresnel_reflectance", "normal_wavevector", "reflectance",
           "reflectance_period_nm"]

warnings.warn("microfacet.thinfilm is a compatibility name (docs/api.md): import reflectance "
              "from microfacet or microfacet.optics.thinfilm", DeprecationWarning, stacklevel=2)
