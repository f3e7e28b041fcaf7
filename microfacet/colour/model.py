"""The film's model colour as the microscope sees it: one object for every comparison of the
analysis with an image.

A facet of oxide thickness d tilted by θ under coaxial light shows the thin-film reflectance
R(λ; θ, d) (seed eqs. 2-4) integrated under the illuminant (the :class:`~.table.ColourTable`),
scaled by the camera's exposure and expressed in CIELAB relative to the illuminant's white;
it is compared with a pixel by a colour difference (seed §3.3.3: ΔE, CIEDE2000 by default).
:class:`FilmColourModel` holds the table, the exposure and the colour-difference formula
together, so that no stage builds Lab from the table by hand.

References
----------
.. [1] N. Nagata, M. Kamei, K. Takahashi, K. Tobitani, T. Akagi, S. Yamamura, "Simulation
   Technology for Titanium Oxide Layer Interference Color", Technical Report (the seed paper),
   §2.4, §3.3.3.
.. [2] G. Sharma, W. Wu, E. N. Dalal, "The CIEDE2000 color-difference formula",
   Color Res. Appl. 30 (2005) 21-30, doi:10.1002/col.20070.

Examples
--------
>>> from microfacet.colour.table import build_colour_table
>>> table = build_colour_table(thickness_range_nm=(30, 80), theta_range_deg=(0, 20))
>>> model = FilmColourModel(table, exposure=0.9)
>>> lab = model.lab(0.0, 51.0)
>>> float(model.delta_e(lab, 0.0, 51.0))
0.0
>>> round(model.period_nm, 1)     # λ/(2n) at 560 nm: the colours repeat about this often
114.6
"""

from __future__ import annotations

import dataclasses
import functools
from dataclasses import dataclass, field

import numpy as np

from ..optics.constants import optical_constants
from ..optics.thinfilm import reflectance_period_nm
from .colorimetry import xyz_to_lab
from .difference import METHODS, delta_e

__all__ = ["FilmColourModel"]

#: Wavelength at which the film's index sets the colour period and the refraction angle
#: (the middle of the visible range, where the CMFs weigh most).
COLOUR_PERIOD_WAVELENGTH_NM = 560.0


@dataclass(frozen=True)
class FilmColourModel:
    """Model CIELAB of the film at (tilt, thickness), and its difference from image colours.

    Parameters
    ----------
    table : ColourTable
        The tabulated film colour over the scene's (θ, d) range.
    exposure : float
        Scale from the model's XYZ (perfect reflector Y = 1) to the image's.
    delta_e_method : {"CIEDE2000", "CIE94", "CIE76"}
        The colour difference every comparison uses.

    Attributes
    ----------
    white : ndarray of float32, shape (3,)
        The white the Lab values are relative to (the table's).
    """

    table: object
    exposure: float = 1.0
    delta_e_method: str = "CIEDE2000"
    white: np.ndarray = field(init=False, repr=False, compare=False)

    def __post_init__(self):
        if self.delta_e_method not in METHODS:
            raise ValueError(f"delta_e_method: must be one of {', '.join(METHODS)}, got "
                             f"{self.delta_e_method!r}")
        if not (np.isfinite(self.exposure) and self.exposure > 0):
            raise ValueError(f"exposure: must be > 0, got {self.exposure!r}")
        object.__setattr__(self, "white", self.table.white_xyz.astype(np.float32))

    def with_exposure(self, exposure: float) -> "FilmColourModel":
        """The same model at another exposure."""
        return dataclasses.replace(self, exposure=float(exposure))

    # -- colours ----------------------------------------------------------------------
    def xyz(self, theta_deg, thickness_nm) -> np.ndarray:
        """The table's XYZ at exposure 1 (float64, NaN outside the table); cache these to
        evaluate :meth:`lab_from_xyz` at several exposures."""
        return self.table.xyz_at(theta_deg, thickness_nm)

    def lab_from_xyz(self, xyz) -> np.ndarray:
        """CIELAB (float32) of XYZ from :meth:`xyz` at this model's exposure."""
        return xyz_to_lab((xyz * self.exposure).astype(np.float32), white=self.white)

    def lab(self, theta_deg, thickness_nm) -> np.ndarray:
        """Model CIELAB (float32, shape broadcast(θ, d) + (3,)) at tilt ``theta_deg``
        (degrees) and thickness ``thickness_nm`` (nm)."""
        return self.lab_from_xyz(self.xyz(theta_deg, thickness_nm))

    def difference(self, lab_a, lab_b) -> np.ndarray:
        """The model's colour difference between two Lab arrays (they broadcast)."""
        return delta_e(lab_a, lab_b, method=self.delta_e_method)

    def delta_e(self, lab, theta_deg, thickness_nm) -> np.ndarray:
        """Colour difference between image colours ``lab`` and the model at (θ, d)."""
        return self.difference(self.lab(theta_deg, thickness_nm), lab)

    # -- the film -----------------------------------------------------------------------
    @property
    def theta_range_deg(self) -> tuple[float, float]:
        return float(self.table.theta_deg[0]), float(self.table.theta_deg[-1])

    @property
    def thickness_range_nm(self) -> tuple[float, float]:
        return float(self.table.thickness_nm[0]), float(self.table.thickness_nm[-1])

    @functools.cached_property
    def film_index(self) -> float:
        """Real refractive index of the film at :data:`COLOUR_PERIOD_WAVELENGTH_NM`."""
        n = optical_constants(self.table.film, np.array([COLOUR_PERIOD_WAVELENGTH_NM]))
        return float(np.real(np.ravel(n)[0]))

    @property
    def period_nm(self) -> float:
        """The thickness over which the film's colour repeats (paler): λ/(2n) at normal
        incidence and 560 nm (:func:`~microfacet.optics.thinfilm.reflectance_period_nm`)."""
        return float(reflectance_period_nm(COLOUR_PERIOD_WAVELENGTH_NM, 0.0, self.film_index))

    def thickness_per_tilt(self, theta_deg, thickness_nm) -> np.ndarray:
        """∂d/∂θ (nm per radian) of equal colour: a tilt θ shortens the film's optical path
        like a thickness change, d·tan θ₁·cos θ / (n cos θ₁) per radian, with θ₁ the
        refraction angle in the film (Snell: sin θ₁ = sin θ / n)."""
        th = np.radians(np.asarray(theta_deg, dtype=np.float64))
        sin1 = np.sin(th) / self.film_index
        cos1 = np.sqrt(1.0 - sin1 ** 2)
        return np.asarray(thickness_nm) * (sin1 / cos1) * np.cos(th) / (self.film_index * cos1)
