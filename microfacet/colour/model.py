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
from .srgb import image_white_xyz, linear_srgb_to_xyz, model_xyz_to_linear_srgb

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
    clip_rgb : tuple of 3 float, optional
        The linear sRGB level of each channel at which the camera clipped the image the
        model is compared with (1 for an image as recorded; ``1/g`` where the analysis divided
        it by a gain ``g``). Where the film's colour at this exposure exceeds it, the model
        shows the clipped colour the camera records (:meth:`lab_from_xyz`). None: no
        clipped pixel is compared (the clip at 0 of colours outside the sRGB gamut holds
        always).

    Attributes
    ----------
    white : ndarray of float32, shape (3,)
        The white the Lab values are relative to (the table's).
    """

    table: object
    exposure: float = 1.0
    delta_e_method: str = "CIEDE2000"
    clip_rgb: tuple | None = None
    white: np.ndarray = field(init=False, repr=False, compare=False)

    def __post_init__(self):
        if self.delta_e_method not in METHODS:
            raise ValueError(f"delta_e_method: must be one of {', '.join(METHODS)}, got "
                             f"{self.delta_e_method!r}")
        if not (np.isfinite(self.exposure) and self.exposure > 0):
            raise ValueError(f"exposure: must be > 0, got {self.exposure!r}")
        if self.clip_rgb is not None:
            c = tuple(float(v) for v in self.clip_rgb)
            if len(c) != 3 or not all(np.isfinite(v) and v > 0 for v in c):
                raise ValueError(f"clip_rgb: must be three levels > 0, got {self.clip_rgb!r}")
            object.__setattr__(self, "clip_rgb", c)
        object.__setattr__(self, "white", self.table.white_xyz.astype(np.float32))

    def with_exposure(self, exposure: float) -> "FilmColourModel":
        """The same model at another exposure."""
        return dataclasses.replace(self, exposure=float(exposure))

    def with_clip(self, clip_rgb) -> "FilmColourModel":
        """The same model compared with an image clipped at ``clip_rgb`` (None: not)."""
        c = None if clip_rgb is None else tuple(float(v) for v in clip_rgb)
        return self if c == self.clip_rgb else dataclasses.replace(self, clip_rgb=c)

    # -- colours ----------------------------------------------------------------------
    def xyz(self, theta_deg, thickness_nm) -> np.ndarray:
        """The table's XYZ at exposure 1 (float64, NaN outside the table); cache these to
        evaluate :meth:`lab_from_xyz` at several exposures."""
        return self.table.xyz_at(theta_deg, thickness_nm)

    def lab_from_xyz(self, xyz) -> np.ndarray:
        """CIELAB (float32) of XYZ from :meth:`xyz` at this model's exposure, as an sRGB
        camera records it: a linear sRGB channel below 0 (a film colour outside the sRGB
        gamut: TiO2 of about 150-180 nm on Ti is a cyan of negative red, 3-4.5 ΔE00 from
        what any sRGB image holds) is recorded at 0, and with ``clip_rgb`` a channel above
        its level at that level (an over-exposed film of one clipped channel is compared
        with pixels clipped alike); the other channels as they are. Colours inside the
        gamut are the table's XYZ in CIELAB relative to its white, exactly.

        >>> from microfacet.colour.table import build_colour_table
        >>> m = FilmColourModel(build_colour_table(thickness_range_nm=(40, 180),
        ...                                        theta_range_deg=(0, 5)), exposure=2.5)
        >>> xyz = m.xyz(0.0, 50.0)
        >>> rgb = model_xyz_to_linear_srgb(xyz * 2.5, white=m.table.white_xyz)
        >>> int((rgb > 1.0).sum()), bool(m.with_clip((1, 1, 1)).delta_e(m.lab(0.0, 50.0),
        ...                                                               0.0, 50.0) > 1.0)
        (1, True)
        >>> round(float(m.with_clip((1, 1, 1)).with_exposure(99.0).lab(0.0, 50.0)[0]), 1)
        100.0
        >>> raw = xyz_to_lab(m.xyz(0.0, 172.0) * 2.5, white=m.table.white_xyz)   # cyan
        >>> round(float(m.difference(m.lab(0.0, 172.0), raw)), 1)
        3.3
        """
        x = (np.asarray(xyz) * self.exposure).astype(np.float32)
        lab = xyz_to_lab(x, white=self.white)
        rgb = x @ self._xyz_to_rgb
        hi = np.float32(np.inf) if self.clip_rgb is None else np.float32(self.clip_rgb)
        with np.errstate(invalid="ignore"):       # NaN outside the table stays NaN
            out = ((rgb < 0.0) | (rgb > hi)).any(axis=-1)
        if out.any():
            t = self.table
            rec = np.clip(rgb[out], 0.0, hi)
            lab[out] = xyz_to_lab(
                linear_srgb_to_xyz(rec, illuminant=t.illuminant, observer=t.observer),
                white=image_white_xyz(illuminant=t.illuminant, observer=t.observer))
        return lab

    def lab_scaled(self, lab, xyz, factor) -> np.ndarray:
        """:meth:`lab_from_xyz` of ``xyz × factor`` (``factor`` > 0) from ``lab``, the Lab of
        ``xyz`` (its :meth:`lab_from_xyz`), without a second cube root where that is exact.

        Scaling XYZ by k scales the CIE function f(t) = t^(1/3) by k^(1/3) while t stays
        above its linear segment, so L* + 16, a* and b* scale by k^(1/3); a colour outside
        the sRGB gamut is recorded at 0 in that channel, which scales alike. Elsewhere — a
        scaled f at or below 6/29 (t ≤ 216/24389: within 0.9 % of black), or a clip level
        (``clip_rgb``), which does not scale — it is :meth:`lab_from_xyz` of ``xyz × factor``.
        The brightness-factor searches of :mod:`microfacet.analysis.facet_thickness` compare
        each colour at eight factors: one cube root instead of eight (docs/benchmarks.md).

        >>> from microfacet.colour.table import build_colour_table
        >>> m = FilmColourModel(build_colour_table(thickness_range_nm=(0, 300),
        ...                                        theta_range_deg=(0, 20)), exposure=0.9)
        >>> xyz = m.xyz(np.array([0.0, 10.0, 20.0]), np.array([5.0, 150.0, 290.0]))
        >>> lab = m.lab_from_xyz(xyz)
        >>> for k in (0.5, 0.8, 1.0, 1e-3):
        ...     assert np.allclose(m.lab_scaled(lab, xyz, k), m.lab_from_xyz(xyz * k), atol=2e-4)
        """
        k = float(factor)
        if k == 1.0:
            return lab
        if self.clip_rgb is not None:
            return self.lab_from_xyz(np.asarray(xyz) * k)
        c = np.float32(np.cbrt(k))
        fy = (lab[..., 0] + np.float32(16.0)) / np.float32(116.0)
        low = np.minimum(np.minimum(fy + lab[..., 1] / np.float32(500.0),
                                    fy - lab[..., 2] / np.float32(200.0)), fy) * c
        out = np.empty_like(lab)
        out[..., 0] = (lab[..., 0] + np.float32(16.0)) * c - np.float32(16.0)
        out[..., 1:] = lab[..., 1:] * c
        exact = low <= np.float32(6.0 / 29.0)          # NaN compares False and stays NaN
        if exact.any():
            out[exact] = self.lab_from_xyz(np.asarray(xyz)[exact] * k)
        return out

    @functools.cached_property
    def _xyz_to_rgb(self) -> np.ndarray:
        """(3, 3) float32: ``xyz @ this`` is the linear sRGB of the table's XYZ
        (:func:`~.srgb.model_xyz_to_linear_srgb`, linear in XYZ)."""
        t = self.table
        return model_xyz_to_linear_srgb(np.eye(3), white=t.white_xyz, illuminant=t.illuminant,
                                        observer=t.observer).astype(np.float32)

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
