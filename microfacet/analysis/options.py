"""Options of the analysis, and the optics of a scene they resolve to."""

from __future__ import annotations

import math
from dataclasses import dataclass

from ..colour.difference import METHODS
from ..core.errors import InputError
from ..optics.constants import DEFAULT_FILM, DEFAULT_SUBSTRATE, load_set

__all__ = ["MODES", "AnalysisOptions", "SceneOptics", "scene_optics"]

MODES = ("joint", "seed")


@dataclass(frozen=True)
class AnalysisOptions:
    """Options of :func:`~microfacet.analysis.pipeline.analyze_stack` (defaults follow the seed).

    Attributes
    ----------
    mode : {"joint", "seed"}
        ``joint`` (default): facet tilts from the height map, thickness from colour;
        ``seed``: the paper's per-pixel inversion (seed §3.3.3).
    roi_size_px, roi_stride_px : int
        ROI side (seed: 255 px) and stride (default = size).
    saturation_min, value_min : float
        Mask thresholds on the 0-255 HSV scale (seed: saturation 15).
    thickness_range_nm : (float, float)
        Global thickness search range.
    exposure : float or None
        Overrides stack.json's ``exposure``; estimated when both are absent.
    film, substrate, illuminant : str or None
        Override the stack's (or the defaults).
    facet_size_um : float
        Expected facet diameter for the joint mode's segmentation (seed: 1-3 µm).
    tilt_step_deg : float
        Tilt grid step of the per-pixel search (refined below it). 1-2° steps measure as
        accurate at half the time (docs/speed-vs-error.md §3c); whether tilt from colour
        means anything for a film: docs/conditioning.md.
    max_components : int
        Largest number of mixture components tried by BIC.
    operator, window_px, align : focus options (None = the focus module's defaults).
    seed : int
        Random sampling in the ROI fits.
    delta_e_method : {"CIEDE2000", "CIE94", "CIE76"}
        The colour difference every stage minimises or reports (seed: ΔE; CIEDE2000, whose
        cost against the others is in docs/speed-vs-error.md).

    Examples
    --------
    >>> AnalysisOptions(mode="seed").validate()
    >>> try:
    ...     AnalysisOptions(roi_size_px=4).validate()
    ... except InputError as exc:
    ...     print(exc.param)
    roi_size_px
    """

    mode: str = "joint"
    roi_size_px: int = 255
    roi_stride_px: int | None = None
    saturation_min: float = 15.0
    value_min: float = 20.0
    thickness_range_nm: tuple = (0.0, 400.0)
    exposure: float | None = None
    film: str | None = None
    substrate: str | None = None
    illuminant: str | None = None
    facet_size_um: float = 2.0
    tilt_step_deg: float = 0.5
    max_components: int = 5
    operator: str | None = None
    window_px: int | None = None
    align: bool | str = False
    seed: int = 0
    delta_e_method: str = "CIEDE2000"

    def validate(self) -> None:
        """Raise :class:`~microfacet.core.errors.InputError` naming the first bad option."""
        def bad(param, reason):
            raise InputError(reason, param=param)

        if self.mode not in MODES:
            bad("mode", f"must be one of {', '.join(MODES)}, got {self.mode!r}")
        lo, hi = self.thickness_range_nm
        if not (0 <= lo < hi <= 2000):
            bad("thickness_range_nm", f"need 0 <= low < high <= 2000, got {lo:g}:{hi:g}")
        if self.exposure is not None and not (self.exposure > 0 and math.isfinite(self.exposure)):
            bad("exposure", f"must be > 0, got {self.exposure!r}")
        if not self.facet_size_um > 0:
            bad("facet_size_um", f"must be > 0, got {self.facet_size_um!r}")
        if not 0.05 <= self.tilt_step_deg <= 5:
            bad("tilt_step_deg", f"must be in [0.05, 5], got {self.tilt_step_deg!r}")
        if not 1 <= self.max_components <= 10:
            bad("max_components", f"must be in [1, 10], got {self.max_components!r}")
        if not self.roi_size_px >= 8:
            bad("roi_size_px", f"must be >= 8, got {self.roi_size_px!r}")
        if self.roi_stride_px is not None and not 1 <= self.roi_stride_px <= self.roi_size_px:
            bad("roi_stride_px", f"must be in [1, roi_size_px], got {self.roi_stride_px!r}")
        if self.delta_e_method not in METHODS:
            bad("delta_e_method", f"must be one of {', '.join(METHODS)}, got "
                                  f"{self.delta_e_method!r}")
        for param in ("film", "substrate"):
            name = getattr(self, param)
            if name is not None:
                try:
                    load_set(name)
                except ValueError as exc:
                    bad(param, str(exc))


@dataclass(frozen=True)
class SceneOptics:
    """The optics an analysis models: film and substrate sets, illuminant, numerical
    aperture and the largest facet tilt the objective sees, asin(NA)/2 in degrees."""

    film: str
    substrate: str
    illuminant: str
    numerical_aperture: float
    max_tilt_deg: float

    def to_json(self) -> dict:
        return {"film": self.film, "substrate": self.substrate, "illuminant": self.illuminant,
                "numerical_aperture": self.numerical_aperture}


def scene_optics(stack, options: AnalysisOptions) -> SceneOptics:
    """The options' film, substrate and illuminant, else the stack's, else the defaults."""
    film = options.film or stack.film or DEFAULT_FILM
    substrate = options.substrate or stack.substrate or DEFAULT_SUBSTRATE
    for key, name in (("film", film), ("substrate", substrate)):
        try:
            load_set(name)
        except ValueError as exc:
            raise InputError(str(exc), param=key) from None
    na = float(stack.numerical_aperture)
    return SceneOptics(film, substrate, options.illuminant or stack.illuminant or "D65", na,
                       math.degrees(math.asin(na)) / 2.0)
