"""Parameters of synthetic stacks (:class:`SynthParams`) and the imaging variations (the
named presets are in :mod:`microfacet.forward.synth`).

The image model and the scene are described in :mod:`microfacet.forward.synth` and
docs/synthetic-stacks.md. Every *variation* field (below the comment in :class:`SynthParams`)
defaults to "off": with the defaults, a preset renders exactly what it rendered before the
variations existed (same bytes, same truth arrays).

Examples
--------
>>> from microfacet.forward.synth_params import SynthParams
>>> p = SynthParams(seed=3, pit_density_per_mm2=2000.0, jpeg_quality=85)
>>> p.pit_density_per_mm2, p.slice_suffix
(2000.0, '.jpg')
>>> sorted(p.variations_on())
['jpeg_quality', 'pit_density_per_mm2']
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from pathlib import Path

from ..core.defaults import DEFAULT_ILLUMINANT
from ..core.lazy import load
from ..optics.defaults import DEFAULT_FILM, DEFAULT_SUBSTRATE

# numpy-backed, needed only to validate: not imported by `microfacet --help`
constants = load("microfacet.optics.constants")

__all__ = ["SynthParams", "ThicknessComponent", "TiltLobe", "VARIATIONS", "parse_variation"]

#: Most slices a synthetic stack may have.
MAX_SLICES = 10_000


@dataclass(frozen=True)
class TiltLobe:
    """A zero-mean lobe of facet tilts: slopes (tan θ) in x and y are N(0, tan(sd_deg)²).

    The tilt θ then has a Rayleigh-distributed tangent (a Beckmann-like lobe whose slope
    standard deviation per axis is tan(sd_deg)); its mode in slope space is 0°.
    """

    weight: float
    sd_deg: float


@dataclass(frozen=True)
class ThicknessComponent:
    """One population of oxide thickness: N(mean_nm, sd_nm²) with a mixture weight."""

    weight: float
    mean_nm: float
    sd_nm: float


@dataclass(frozen=True)
class SynthParams:
    """Every parameter of a synthetic stack (all lengths in µm unless the name says nm).

    Attributes
    ----------
    height_px, width_px : int
        Image size.
    n_slices : int
        Focal planes.
    pixel_size_um : float
        Lateral pixel size on the sample (the seed's microscope: 347.8 µm / 1600 px ≈ 0.217).
    numerical_aperture : float
        Objective NA; facets tilted past asin(NA)/2 are dark (see ``illumination_fill``).
    facet_size_um : float
        Mean facet diameter (Voronoi cells), 1-3 µm in the seed.
    tilt_lobes : tuple of TiltLobe
        Mixture of zero-mean facet-slope lobes.
    waviness_amplitude_um, waviness_wavelength_um : float
        RMS height and typical wavelength of the macro (roll-dull) waviness.
    thickness : tuple of ThicknessComponent
        Gaussian mixture of region thicknesses.
    region_size_um : float
        Mean diameter of the thickness regions.
    thickness_fine_sd_nm, thickness_fine_scale_um : float
        Smooth thickness variation inside regions (SD and correlation length).
    thickness_facet_sd_nm : float
        Per-facet thickness offset (SD; 0 in most presets): anodic growth can depend on
        the grain underneath. It mimics tilt in colour (10° ≈ 0.3 nm), which is why the
        ``grainy`` preset has it: the hard case where tilt cannot come from colour.
    groove_wall_deg : float
        Slope of the walls of the height steps between facets. Walls steeper than
        asin(NA)/2 reflect outside the objective, so a step of height Δh images as a dark
        groove of projected width Δh / tan(groove_wall_deg) (pixel coverage blended); 0
        disables grooves (vertical, invisible walls). They give the images the texture
        focus needs.
    exposure : float
        Model linear sRGB → image linear sRGB.
    dark_level : float
        Linear signal of facets outside the objective's acceptance (relative to white).
    full_well_e : float or None
        Electrons at signal 1 (shot noise); None for no shot noise.
    read_noise : float
        Read-noise SD in linear signal units.
    bit_depth : {8, 16}
    z_margin_um : float
        Extra focus range below the lowest and above the highest point.
    write_exposure : bool
        Write ``exposure`` into stack.json (else the analyser must estimate it).
    film, substrate : str
        Optical-constant sets (any of :func:`microfacet.optics.known_sets`); stack.json names
        them, so the analysis models the same film.
    illuminant : str
    seed : int
    preset : str
        Name of the preset the parameters came from (``"custom"`` otherwise).

    Imaging variations (defaults: off)
    ----------------------------------
    facet_aspect : float
        Facet cells elongated along ``rolling_direction_deg`` by this length/width ratio
        (cold rolling stretches grains). 1 = isotropic Voronoi cells (default).
    facet_size_spread : float
        Log-SD of the local facet diameter: cell density follows a smooth random field
        (correlation ~5 facets), giving fields of small and large grains side by side
        (duplex or partly recrystallized sheet). 0 = one size (default).
    facet_dome_deg : float
        Rounded instead of planar facets: each facet is a paraboloid cap whose extra slope
        at the cell's mean radius is this angle (grain tops rounded by etching or pickling),
        so the tilt varies inside a facet. 0 = planar (default).
    rolling_direction_deg : float
        Direction of rolling in the image, degrees from +x (columns) toward +y (rows); used
        by ``facet_aspect`` and by scratches.
    terrace_step_um : float
        Sharp-edged relief: whole grains raised by 0, 1 or 2 steps of this height, in
        terraces of ``terrace_size_um`` (grain-boundary steps of rolled and etched sheet).
        Terrace edges are height discontinuities of up to 2 steps: the height-from-focus
        hard case; their walls are dark like grooves when ``groove_wall_deg`` > 0.
        0 = none (default).
    terrace_size_um : float
        Mean diameter of the terraces.
    pit_density_per_mm2 : float
        Etch pits per mm² (pickling, pitting corrosion). A pit is a concave crater in the
        height map: a flat floor (the facet plane lowered, visible with the film's colour)
        of half the pit radius, surrounded by a sharp-edged conical wall of slope
        ``pit_wall_deg``; walls steeper than the acceptance angle image dark. 0 = none.
    pit_radius_um : float
        Mean pit radius at the rim (each pit's radius is log-normal, SD 0.3 in log).
    pit_wall_deg : float
        Slope of the pit walls.
    scratch_density_per_mm2 : float
        Scratch centres per mm² (handling, roll marks). A scratch is a V-shaped trench of
        width ``scratch_width_um`` and wall slope ``scratch_wall_deg`` along a segment of
        length ~``scratch_length_um`` (exponential), in the height map; walls steeper than
        the acceptance angle image as two dark lines. 0 = none (default).
    scratch_length_um, scratch_width_um, scratch_wall_deg : float
        Mean length, width at the surface and wall slope of a scratch.
    scratch_spread_deg : float
        Scratch directions are ``rolling_direction_deg`` ± this (uniform); 90 = random.
    dust_density_per_mm2 : float
        Dust particles per mm²: thin flakes lying on the film, not made of it. They are
        neutral grey (dark soot-like or bright fibre-like), blended into the image with
        anti-aliased elliptical coverage, in focus at the surface height, and **not** in
        the height map (the truth height is the metal surface; ``truth/feature.npy`` marks
        them). 0 = none (default).
    dust_radius_um : float
        Mean particle radius (log-normal, SD 0.4 in log; aspect ratio 0.5-1).
    dust_bright_fraction : float
        Fraction of the particles that are bright (linear reflectance 0.5-0.9); the others
        are dark (0.02-0.08).
    illumination_fill : float
        Tilt-dependent brightness: the illumination cone as a fraction σ of the objective's
        NA (Köhler condenser setting). A facet tilted by θ reflects the cone of directions
        rotated by 2θ; the fraction of it that re-enters the pupil (computed on the sphere,
        uniform pupil irradiance) sets its brightness, a smooth fall from 1 at θ = 0 to 0
        near asin((1 + σ) NA)/2. 0 = axial light: the hard cut at asin(NA)/2 (default).
        The colour stays that of incidence θ.
    vignetting_corner_loss : float
        Smooth radial fall-off of the illumination, ``(1 − v)^((r / r_corner)²)``: the
        fraction of light lost at the image corners (0 = none, default).
    white_balance_gains : tuple of 3 float
        Per-channel gains (R, G, B) on the linear camera image: a white balance off by
        these factors (default (1, 1, 1)).
    drift_px_per_slice : float
        Lateral stage drift: a random walk whose step per slice has this SD (px, each
        axis), sub-pixel shifts (bicubic). Offsets are relative to the truth frame, which
        is the **mean** position of all slices (offsets sum to zero);
        ``truth/params.json`` key ``drift_px`` lists (dy, dx) per slice. 0 = none.
    jpeg_quality : int or None
        Write the slices as JPEG of this quality (1-100; 8-bit only); None = PNG (default).
    stain_density_per_mm2 : float
        Stains per mm²: patches where the film reflects less (residue, contamination, a
        locally altered oxide) but the surface is where it was: **not in the height map**,
        the same height and tilt as around them. Each multiplies the film's linear RGB by a
        factor uniform in [``stain_reflectance_min``, ``stain_reflectance_max``] (dark, the
        film's hue kept), with anti-aliased elliptical coverage like dust;
        ``truth/feature.npy`` marks them (code 4). 0 = none (default).
    stain_radius_um : float
        Mean stain radius (log-normal, SD 0.4 in log; aspect ratio 0.5-1).
    stain_reflectance_min, stain_reflectance_max : float
        Range of the stains' reflectance factors (0-1).
    relief_file : str or None
        A measured height map (any format of
        :func:`microfacet.io.instruments.read_height_map` that gives a pixel size: .npy with
        no pixel size is refused) that **replaces** the facets and the waviness: turned by a
        random multiple of 90°, mirrored or not, and a random window resampled to the
        scene's pixels with every slope preserved (:func:`~microfacet.forward.relief.
        measured_relief`). The truth tilt is that of the resampled map (central
        differences). The Voronoi facets still label ``truth/facet_id.npy`` and carry the
        per-facet thickness offsets; there are no grooves, and terraces and rounded facets
        cannot be combined with it. ``truth/params.json`` records the file's name (never its
        folder) with a SHA-256 prefix, the orientation and the window (key ``relief``).
        None = the synthetic facets (default).
    """

    height_px: int = 256
    width_px: int = 256
    n_slices: int = 24
    pixel_size_um: float = 0.216
    numerical_aperture: float = 0.8
    facet_size_um: float = 2.0
    tilt_lobes: tuple = (TiltLobe(1.0, 4.0),)
    waviness_amplitude_um: float = 0.5
    waviness_wavelength_um: float = 40.0
    thickness: tuple = (ThicknessComponent(1.0, 51.0, 1.0),)
    region_size_um: float = 25.0
    thickness_fine_sd_nm: float = 0.3
    thickness_facet_sd_nm: float = 0.0
    groove_wall_deg: float = 45.0
    thickness_fine_scale_um: float = 3.0
    exposure: float = 1.0
    dark_level: float = 0.02
    full_well_e: float | None = 8000.0
    read_noise: float = 0.002
    bit_depth: int = 8
    z_margin_um: float = 1.0
    write_exposure: bool = False
    film: str = DEFAULT_FILM
    substrate: str = DEFAULT_SUBSTRATE
    illuminant: str = DEFAULT_ILLUMINANT
    seed: int = 0
    preset: str = "custom"
    # -- imaging variations: every default is "off" ------------------------------------
    facet_aspect: float = 1.0
    facet_size_spread: float = 0.0
    facet_dome_deg: float = 0.0
    rolling_direction_deg: float = 0.0
    terrace_step_um: float = 0.0
    terrace_size_um: float = 20.0
    pit_density_per_mm2: float = 0.0
    pit_radius_um: float = 2.0
    pit_wall_deg: float = 60.0
    scratch_density_per_mm2: float = 0.0
    scratch_length_um: float = 40.0
    scratch_width_um: float = 1.0
    scratch_wall_deg: float = 45.0
    scratch_spread_deg: float = 90.0
    dust_density_per_mm2: float = 0.0
    dust_radius_um: float = 1.0
    dust_bright_fraction: float = 0.5
    illumination_fill: float = 0.0
    vignetting_corner_loss: float = 0.0
    white_balance_gains: tuple = (1.0, 1.0, 1.0)
    drift_px_per_slice: float = 0.0
    jpeg_quality: int | None = None
    stain_density_per_mm2: float = 0.0
    stain_radius_um: float = 1.5
    stain_reflectance_min: float = 0.05
    stain_reflectance_max: float = 0.35
    relief_file: str | None = None

    @property
    def max_tilt_deg(self) -> float:
        """Largest facet tilt whose reflection enters the objective: asin(NA)/2."""
        return math.degrees(math.asin(self.numerical_aperture)) / 2.0

    @property
    def slice_suffix(self) -> str:
        """``".png"``, or ``".jpg"`` with ``jpeg_quality``."""
        return ".png" if self.jpeg_quality is None else ".jpg"

    @property
    def default_facets(self) -> bool:
        """True for the original isotropic planar Voronoi facets."""
        return self.facet_aspect == 1.0 and self.facet_size_spread == 0.0

    @property
    def measured(self) -> bool:
        """True when the height is a measured map (``relief_file``), not facets."""
        return self.relief_file is not None

    def variations_on(self) -> dict:
        """The variation fields that differ from their (off) defaults: ``{name: value}``."""
        return {f.name: getattr(self, f.name) for f in dataclasses.fields(self)
                if f.name in IMAGING_VARIATIONS and getattr(self, f.name) != f.default}

    def validate(self) -> None:
        """Raise ValueError naming the first parameter out of range."""
        known = constants.known_sets()
        gains = self.white_balance_gains
        checks = [
            ("height_px", self.height_px >= 16), ("width_px", self.width_px >= 16),
            ("n_slices", 1 <= self.n_slices <= MAX_SLICES),
            ("pixel_size_um", self.pixel_size_um > 0),
            ("numerical_aperture", 0 < self.numerical_aperture < 1),
            ("facet_size_um", self.facet_size_um > 0),
            ("tilt_lobes", len(self.tilt_lobes) > 0
             and all(lb.weight > 0 and 0 <= lb.sd_deg < 60 for lb in self.tilt_lobes)),
            ("thickness", len(self.thickness) > 0
             and all(c.weight > 0 and c.mean_nm >= 0 and c.sd_nm >= 0 for c in self.thickness)),
            ("region_size_um", self.region_size_um > 0),
            ("thickness_facet_sd_nm", self.thickness_facet_sd_nm >= 0),
            ("groove_wall_deg", 0 <= self.groove_wall_deg < 90),
            ("thickness_fine_sd_nm", self.thickness_fine_sd_nm >= 0),
            ("exposure", self.exposure > 0), ("bit_depth", self.bit_depth in (8, 16)),
            ("read_noise", self.read_noise >= 0),
            ("full_well_e", self.full_well_e is None or self.full_well_e > 0),
            ("z_margin_um", self.z_margin_um >= 0),
            ("film", self.film in known), ("substrate", self.substrate in known),
            ("facet_aspect", 1.0 <= self.facet_aspect <= 10.0),
            ("facet_size_spread", 0.0 <= self.facet_size_spread <= 1.0),
            ("facet_dome_deg", 0.0 <= self.facet_dome_deg <= 30.0),
            ("rolling_direction_deg", math.isfinite(self.rolling_direction_deg)),
            ("terrace_step_um", self.terrace_step_um >= 0),
            ("terrace_size_um", self.terrace_size_um > 0),
            ("pit_density_per_mm2", self.pit_density_per_mm2 >= 0),
            ("pit_radius_um", self.pit_radius_um > 0),
            ("pit_wall_deg", 0 < self.pit_wall_deg < 90),
            ("scratch_density_per_mm2", self.scratch_density_per_mm2 >= 0),
            ("scratch_length_um", self.scratch_length_um > 0),
            ("scratch_width_um", self.scratch_width_um > 0),
            ("scratch_wall_deg", 0 < self.scratch_wall_deg < 90),
            ("scratch_spread_deg", 0 <= self.scratch_spread_deg <= 90),
            ("dust_density_per_mm2", self.dust_density_per_mm2 >= 0),
            ("dust_radius_um", self.dust_radius_um > 0),
            ("dust_bright_fraction", 0 <= self.dust_bright_fraction <= 1),
            ("illumination_fill", 0 <= self.illumination_fill <= 1),
            ("vignetting_corner_loss", 0 <= self.vignetting_corner_loss < 1),
            ("white_balance_gains", len(gains) == 3
             and all(math.isfinite(g) and g > 0 for g in gains)),
            ("drift_px_per_slice", 0 <= self.drift_px_per_slice <= 20),
            ("jpeg_quality", self.jpeg_quality is None
             or (isinstance(self.jpeg_quality, int) and 1 <= self.jpeg_quality <= 100
                 and self.bit_depth == 8)),
            ("stain_density_per_mm2", self.stain_density_per_mm2 >= 0),
            ("stain_radius_um", self.stain_radius_um > 0),
            ("stain_reflectance_min", 0 <= self.stain_reflectance_min <= 1),
            ("stain_reflectance_max", self.stain_reflectance_min <= self.stain_reflectance_max
             <= 1),
        ]
        for name, ok in checks:
            if not ok:
                extra = " (JPEG slices are 8-bit)" if name == "jpeg_quality" else ""
                raise ValueError(f"{name}: out of range ({getattr(self, name)!r}){extra}")
        self._validate_relief()

    def _validate_relief(self) -> None:
        if self.relief_file is None:
            return
        if not isinstance(self.relief_file, str) or not self.relief_file.strip():
            raise ValueError(f"relief_file: expected the path of a height map, got "
                             f"{self.relief_file!r}")
        if not Path(self.relief_file).is_file():
            raise ValueError(f"relief_file: {self.relief_file}: file not found")
        for name in ("terrace_step_um", "facet_dome_deg"):
            if getattr(self, name) != 0:
                raise ValueError(f"relief_file: a measured surface cannot be combined with "
                                 f"{name} (set it to 0)")

    def to_json(self) -> dict:
        """Every field, JSON-ready; ``relief_file`` as its name only (no folder of the
        machine that wrote it), so :meth:`from_json` gives a name to resolve again."""
        d = dataclasses.asdict(self)
        d["white_balance_gains"] = list(self.white_balance_gains)
        if self.relief_file is not None:
            d["relief_file"] = Path(self.relief_file).name
        d["max_tilt_deg"] = self.max_tilt_deg
        return d

    @classmethod
    def from_json(cls, data: dict) -> "SynthParams":
        """Parameters from :meth:`to_json` (``truth/params.json`` key ``params``); keys
        absent from older files take their defaults.

        >>> p = SynthParams(seed=4, tilt_lobes=(TiltLobe(0.5, 3.0), TiltLobe(0.5, 9.0)),
        ...                 dust_density_per_mm2=500.0, white_balance_gains=(1.1, 1.0, 0.9))
        >>> SynthParams.from_json(p.to_json()) == p
        True
        """
        names = {f.name for f in dataclasses.fields(cls)}
        kw = {k: v for k, v in data.items() if k in names}
        if "tilt_lobes" in kw:
            kw["tilt_lobes"] = tuple(TiltLobe(**lb) for lb in kw["tilt_lobes"])
        if "thickness" in kw:
            kw["thickness"] = tuple(ThicknessComponent(**c) for c in kw["thickness"])
        if "white_balance_gains" in kw:
            kw["white_balance_gains"] = tuple(float(g) for g in kw["white_balance_gains"])
        return cls(**kw)


#: The imaging-variation fields (all off by default), in declaration order.
_FIELD_NAMES = [f.name for f in dataclasses.fields(SynthParams)]
IMAGING_VARIATIONS: tuple[str, ...] = tuple(_FIELD_NAMES[_FIELD_NAMES.index("facet_aspect"):])

#: The variation fields (settable with ``microfacet synth --variation NAME=VALUE``) and
#: ``film``/``substrate``, with the type of their value.
VARIATIONS: dict[str, type] = {
    "groove_wall_deg": float, "thickness_facet_sd_nm": float,
    "facet_aspect": float, "facet_size_spread": float, "facet_dome_deg": float,
    "rolling_direction_deg": float, "terrace_step_um": float, "terrace_size_um": float,
    "pit_density_per_mm2": float, "pit_radius_um": float, "pit_wall_deg": float,
    "scratch_density_per_mm2": float, "scratch_length_um": float,
    "scratch_width_um": float, "scratch_wall_deg": float, "scratch_spread_deg": float,
    "dust_density_per_mm2": float, "dust_radius_um": float, "dust_bright_fraction": float,
    "illumination_fill": float, "vignetting_corner_loss": float,
    "white_balance_gains": tuple, "drift_px_per_slice": float, "jpeg_quality": int,
    "film": str, "substrate": str, "exposure": float, "full_well_e": float,
    "read_noise": float, "stain_density_per_mm2": float, "stain_radius_um": float,
    "stain_reflectance_min": float, "stain_reflectance_max": float, "relief_file": str,
}


def parse_variation(text: str) -> tuple[str, object]:
    """``"NAME=VALUE"`` → ``(name, value)`` of a :data:`VARIATIONS` field.

    Gains are three comma-separated numbers; ``none`` clears ``jpeg_quality``,
    ``full_well_e`` and ``relief_file``.

    Raises
    ------
    ValueError
        Naming the variation (``variation`` when the text has no ``=`` or an unknown name).

    Examples
    --------
    >>> parse_variation("pit_density_per_mm2=2000")
    ('pit_density_per_mm2', 2000.0)
    >>> parse_variation("white_balance_gains=1.1,1,0.9")
    ('white_balance_gains', (1.1, 1.0, 0.9))
    >>> parse_variation("jpeg_quality=none")
    ('jpeg_quality', None)
    """
    name, sep, value = text.partition("=")
    name, value = name.strip(), value.strip()
    if not sep or name not in VARIATIONS:
        raise ValueError(f"variation: expected NAME=VALUE with NAME one of "
                         f"{', '.join(VARIATIONS)}; got {text!r}")
    kind = VARIATIONS[name]
    if value.lower() == "none" and name in ("jpeg_quality", "full_well_e", "relief_file"):
        return name, None
    try:
        if kind is tuple:
            out = tuple(float(v) for v in value.split(","))
        elif kind is int:
            out = int(value)
        else:
            out = kind(value)
    except ValueError:
        raise ValueError(f"{name}: cannot read {value!r} as {kind.__name__}") from None
    return name, out
