"""The angular map: colours (and spectra) over a grid of in-plane light × view zenith angles.

Rows are light zenith angles θ_light (L), columns view zenith angles θ_view (V), view
positive on the mirror side (θ_view = θ_light is the specular direction). Made by the forward
models (:func:`microfacet.forward.angular.simulate_map`), stored by
:mod:`microfacet.io.angular_map`, drawn by the report.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .defaults import DEFAULT_ILLUMINANT, DEFAULT_OBSERVER

__all__ = ["AngularMap"]


@dataclass
class AngularMap:
    """Colours (and optionally spectra) over a (θ_light, θ_view) grid.

    Attributes
    ----------
    theta_light_deg : ndarray (L,)
    theta_view_deg : ndarray (V,)
    lab : ndarray (L, V, 3) float32
    xyz : ndarray (L, V, 3) or None
        Perfect reflector Y = 1 (exposure applied).
    srgb : ndarray (L, V, 3) uint8 or None
        Display image (rows = light angle, columns = view angle).
    spectra : ndarray (L, V, N) or None
        Reflectance (factor), exposure applied.
    wavelength_nm : ndarray (N,) or None
    illuminant, observer : str
    meta : dict
        Model name, parameters, exposure.
    """

    theta_light_deg: np.ndarray
    theta_view_deg: np.ndarray
    lab: np.ndarray
    xyz: np.ndarray | None = None
    srgb: np.ndarray | None = None
    spectra: np.ndarray | None = None
    wavelength_nm: np.ndarray | None = None
    illuminant: str = DEFAULT_ILLUMINANT
    observer: str = DEFAULT_OBSERVER
    meta: dict = field(default_factory=dict)

    @property
    def shape(self):
        return (self.theta_light_deg.size, self.theta_view_deg.size)
