"""The options of an analysis: one typed tree, one source of defaults.

:class:`AnalysisOptions` holds a section per stage, each a frozen dataclass whose fields carry
their default, unit, valid range and a line of help (:mod:`microfacet.core.options`):

==============  ======================================================================
section         stage (module)
==============  ======================================================================
``focus``       height from focus (:class:`~microfacet.focus.options.FocusOptions`)
``mask``        pixels without colour information (:mod:`.mask`, :mod:`.colour_image`)
``roi``         thickness per region of interest, interference order, exposure (:mod:`.roi`)
``joint``       facets, their planes and thickness (joint mode: :mod:`.segmentation`,
                :mod:`.planes`, :mod:`.facet_thickness`, :mod:`.joint`)
``tilt``        per-pixel tilt from colour (:mod:`.tilt`)
``fits``        the mixtures and whether the data determine them (:mod:`.distributions`,
                :mod:`.identification`)
``optics``      film, substrate, illuminant, exposure, thickness range, colour difference
==============  ======================================================================

Constructing a section validates it (an :class:`~microfacet.core.errors.InputError` names the
option's path, e.g. ``roi.size_px``); each stage takes only its section. The command line's
flags and help are generated from the fields (``cli=True``), and ``summary.json`` records the
whole tree (:meth:`~microfacet.core.options.Options.to_dict`).

Examples
--------
>>> o = AnalysisOptions(mode="seed", roi=RoiOptions(size_px=128))
>>> o.roi.size_px, o.mask.saturation_min
(128, 15.0)
>>> AnalysisOptions.from_dict({"roi": {"size_px": 4}})
Traceback (most recent call last):
...
microfacet.core.errors.InputError: roi.size_px: must be >= 8, got 4
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from ..colour.difference import METHODS
from ..core.errors import InputError
from ..core.options import Options, option
from ..focus.options import FocusOptions
from ..optics.constants import known_sets, unknown_set_reason
from ..optics.defaults import DEFAULT_FILM, DEFAULT_ILLUMINANT, DEFAULT_SUBSTRATE

__all__ = ["AnalysisOptions", "FitOptions", "JointOptions", "MaskOptions", "OpticsOptions",
           "RoiOptions", "Scene", "TiltOptions", "scene_of"]

MODES = ("joint", "seed")


def _thickness_range(value):
    try:
        lo, hi = (float(v) for v in value)
    except (TypeError, ValueError):
        return f"expected (low, high) in nm, got {value!r}"
    if not (0 <= lo < hi <= 2000):
        return f"need 0 <= low < high <= 2000, got {lo:g}:{hi:g}"
    return None


@dataclass(frozen=True)
class MaskOptions(Options):
    """Which pixels carry no colour information (seed §3.3.3 step 2; :mod:`.mask`)."""

    saturation_min: float = option(
        15.0, help="mask pixels of HSV saturation below this, 0-255 scale (seed: 15)",
        low=0, high=255, cli=True, metavar="S")
    value_min: float = option(
        20.0, help="mask pixels of HSV value below this, 0-255 scale", low=0, high=255,
        cli=True, metavar="V")
    shadow_ratio: float = option(
        0.75, help="mask pixels darker than this fraction of their 9x9 neighbourhood's median "
                   "value (partly shadowed step walls; 0 disables)", low=0, high=1)
    steep_ratio: float = option(
        0.3, help="mask pixels whose linear value is below this fraction of the film's median "
                  "(tilted past the acceptance; mask.steep_facet_mask explains the value) "
                  "where they lie within `mask.steep_rim_px` of a pixel darker than "
                  "`mask.steep_core_ratio` of it",
        low=0, high=1)
    steep_core_ratio: float = option(
        0.1, help="pixels whose linear value is below this fraction of the film's median are "
                  "darker than any film colour (the darkest, TiO2 of 29-37 nm on Ti, is "
                  "0.15-0.29 of it by the optical constants; steep facets ~0.05) "
                  "and masked as steep; those between this and `mask.steep_ratio` only "
                  "beside them (a film of a dark colour is not steep; set it to "
                  "`mask.steep_ratio` to mask every pixel below that)", low=0, high=1)
    steep_rim_px: float = option(
        2.5, help="how far the blurred rim of a dark facet, pit or groove reaches from its "
                  "core (pixels between `mask.steep_core_ratio` and `mask.steep_ratio` of the "
                  "film's median this close to the core are masked with it)", unit="px",
        low=0, high=50)
    dark_film_min_px: float = option(
        17.0, help="the narrowest dark area (pixels between `mask.steep_core_ratio` and "
                   "`mask.steep_ratio` of the film's median, no steep core) taken for a film "
                   "of a dark colour; narrower ones are scratches, walls and rims, masked "
                   "(`dark_feature`) but not censored", unit="px", low=1, high=1000)
    grey_film_min_px: float = option(
        17.0, help="the narrowest low-saturation area (below `mask.saturation_min`, neither "
                   "dark nor clipped) taken for a film of a grey colour and analysed, where "
                   "the image also holds film of colour; narrower ones (highlights, rims) stay "
                   "masked. 0 masks every low-saturation pixel, as the seed does",
        unit="px", low=0, high=1000)
    clipped_one_channel: bool = option(
        True, help="analyse pixels with one channel at the clip level, the film's model colour "
                   "clipped alike (the other two channels still carry the colour); off masks "
                   "every clipped pixel. Where the light varies across the image (a flat field "
                   "divided out) the clip level varies too and they are masked")


@dataclass(frozen=True)
class RoiOptions(Options):
    """Thickness per region of interest, the interference order and the exposure
    (:mod:`.roi`)."""

    CLI_PREFIX = "roi-"
    size_px: int = option(255, help="ROI side (seed: 255 px = 55.1 µm)", unit="px", low=8,
                          cli=True, metavar="PX")
    stride_px: int | None = option(None, help="ROI stride (none: the side, no overlap)",
                                   unit="px", kind=int, low=1, cli=True, metavar="PX")
    grid_step_nm: float = option(
        1.0, help="step of the global thickness scan (the minima are >= 20 nm apart; a "
                  "coarser scan is slower, not faster: docs/speed-vs-error.md §3a)",
        unit="nm", low=0.05, high=20)
    sample_px: int = option(256, help="pixels per ROI in the global scan", low=8)
    refine_px: int = option(8000, help="pixels per ROI in the refinement of the best minima",
                            low=8)
    consensus_px: int = option(
        128, help="pixels per ROI in the interference-order consensus and the exposure scan "
                  "(512 did not make the order choice robust and hurt mixed ROIs: "
                  "docs/accuracy.md)", low=8)
    min_pixels: int = option(20, help="ROIs with fewer unmasked pixels are not fitted", low=1)
    consensus_half_width_nm: float = option(
        35.0, help="half-width of the interference-order band chosen for all ROIs together "
                   "(less than half the ~110 nm spacing of the orders; 0 disables)",
        unit="nm", low=0)
    order_margin_de: float = option(
        2.0, help="a ROI leaves the consensus band only for a minimum better by this",
        unit="ΔE", low=0)
    exposure_block_px: int = option(
        4, help="side of the blocks of the second exposure reading: each block's mean colour "
                "at its best thickness over the whole range, so populations in different "
                "orders each keep their own (a block's mean averages away the pixel noise "
                "that would otherwise chase other orders)", unit="px", low=1)

    def __post_init__(self):
        super().__post_init__()
        if self.stride_px is not None and self.stride_px > self.size_px:
            raise InputError(f"must be in [1, `roi.size_px`], got {self.stride_px}",
                             param="stride_px")


@dataclass(frozen=True)
class JointOptions(Options):
    """The joint mode: facets from colour and height, a plane per facet from its reliable
    heights, a thickness per facet from its colour at that tilt (:mod:`.joint`)."""

    facet_size_um: float = option(
        2.0, help="expected facet diameter for the segmentation (seed: 1-3 µm)", unit="µm",
        low=0, low_exclusive=True, cli=True, metavar="UM")
    merge_alpha: float = option(
        0.01, help="significance of the segment-merge tests (a true edge is kept when its "
                   "colour or plane difference would arise by chance with a smaller "
                   "probability)", low=1e-9, high=0.5)
    max_area_factor: float = option(2.0, help="largest segment, in facet areas", low=1)
    merge_rounds: int = option(30, help="segment-merge rounds (mutual best pairs each)", low=1)
    flat_field: str = option(
        "estimate", help="the microscope's flat field (vignetting): `estimate` fits a smooth "
                         "field to the facets' brightness and divides the colours by it where "
                         "the facets then fit better (analysis.flat_field); `off` takes the "
                         "illumination as even (a flat reference, optics.flat_reference, is "
                         "applied either way)", choices=("off", "estimate"))
    min_plane_pixels: int = option(
        8, help="fewest reliable heights for a facet plane (3 determine it; 8 leave 5 degrees "
                "of freedom for the residual that scales its covariance)", low=4)
    plane_edge_px: float = option(
        1.0, help="heights closer than this to a facet boundary are not used by its plane",
        unit="px", low=0)
    unmix_heights: bool = option(
        False, help="undo the focus support's mixing of neighbouring facets' heights before "
                    "the NDF's planes are fitted (analysis.planes.fit_unmixed_planes): against "
                    "the sweep's true facets their slope gain goes from 0.73 to 0.96 "
                    "(median), but the NDF's identification checks cannot yet vouch for what "
                    "it then identifies (2 of 16 scenes off by more than a quarter, "
                    "docs/accuracy.md); off: planes through the heights as measured",
        cli=True)
    interior_px: float = option(
        1.5, help="pixels at least this far from a facet boundary give its mean colour "
                  "(boundaries are partly shadowed)", unit="px", low=0)
    focus_error_correlation: float = option(
        0.7, help="correlation area of the focus stage's height errors per window area "
                  "(window_px²): measured 27-41 px² for the 7 px window on synthetic nd "
                  "stacks", low=0)
    export_sigma_um: float = option(
        1e-4, help="height error assumed for a microscope export that gives none (tiny: the "
                   "planes' covariance then comes from their residuals)", unit="µm",
        low=0, low_exclusive=True)
    order_window_fraction: float = option(
        0.45, help="half-width of a facet's interference-order window, in colour periods "
                   "λ/(2n) at 560 nm (the neighbouring orders' look-alikes stay out)",
        low=0.05, high=0.5)
    order_switch_de: float = option(
        1.0, help="a facet leaves its ROI's interference order when another fits its colour "
                  "better by more than this", unit="ΔE", low=0)
    order_switch_ratio: float = option(
        0.5, help="... and with at most this fraction of the ROI order's ΔE (a facet of two "
                  "regions or of a groove fits neither; without it 1.8 % of the fixture's "
                  "pixels switched to a wrong order)", low=0, high=1)
    facet_brightness_min: float = option(
        0.5, help="a facet's colour is compared with the film's at the brightness factor k in "
                  "[this, 1] that fits it best (analysis.facet_thickness): grooves and rims "
                  "averaged into a facet, stains, the light a tilted facet returns outside "
                  "the objective and vignetting left by the flat field darken a facet, not "
                  "its film's chromaticity; 1: at the image's exposure alone", low=0.05, high=1)
    facet_brightness_penalty_de: float = option(
        4.0, help="... at a cost of this many dE per unit |ln k|, in quadrature with the "
                  "colour's dE (k = 0.8: 0.9 dE; k = 0.5: 2.8 dE)", unit="ΔE", low=0)
    order_cut_strength: float = option(
        1000.0, help="after the order moves, the facets' orders are decided together by a "
                     "minimum cut over the facet graph (analysis.order_cut): the cost of a "
                     "boundary between two neighbours of one colour read in different "
                     "orders, in dE^2 per sqrt(px); 0 keeps each facet's order",
        low=0)
    order_cut_contrast_de: float = option(
        5.0, help="... the colour step between two neighbouring facets at which that cost "
                  "has fallen to exp(-1/2) of it", unit="ΔE", low=0, low_exclusive=True)
    order_cut_keep_de: float = option(
        4.0, help="... added to a facet's runner-up order's dE: a facet leaves the order it "
                  "was read in only where its neighbours' colours ask for it", unit="ΔE",
        low=0)
    thickness_step_nm: float = option(
        0.05, help="final resolution of a facet's thickness (1 nm scan, then ±1 nm at this "
                   "step, then a parabola)", unit="nm", low=0.001, high=1)
    exposure_facets: int = option(
        2000, help="facets (at random) on which the exposure is refined", low=10)
    exposure_thickness_step_nm: float = option(
        0.1, help="resolution of the facets' thickness while the exposure is refined",
        unit="nm", low=0.001, high=1)


@dataclass(frozen=True)
class TiltOptions(Options):
    """The per-pixel tilt search (:mod:`.tilt`; both modes)."""

    CLI_PREFIX = "tilt-"
    step_deg: float = option(
        1.0, help="tilt grid step of the per-pixel search, refined below it (0.5° is no more "
                  "accurate at twice the work: docs/speed-vs-error.md §3c)", unit="°",
        low=0.05, high=5, cli=True, metavar="DEG")
    coarse_stride: int = option(
        4, help="coarse-to-fine search: every this-th grid node first, then those near the "
                "best (1 = every node; the objective's basins are many degrees wide)", low=1)


@dataclass(frozen=True)
class FitOptions(Options):
    """The mixtures (:mod:`.mixtures`, :mod:`.ndf_fit`) and whether the data determine them
    (:mod:`.identification`)."""

    max_components: int = option(
        5, help="largest number of mixture components tried by BIC", low=1, high=10,
        cli=True, metavar="K")
    thickness_sd_floor_nm: float = option(0.1, help="smallest thickness component SD",
                                          unit="nm", low=0, low_exclusive=True)
    thickness_max_sd_nm: float | None = option(
        None, help="largest thickness component SD (none: a third of a facet's interference-"
                   "order window, joint.order_window_fraction of the colours' period: a "
                   "population does not span orders, and facets scattered over a few orders "
                   "are left to the background and the populations' tails instead of one "
                   "wide component that swallows a population)", unit="nm", low=0,
        low_exclusive=True)
    order_moves: str = option(
        "pool", help="`pool`: a thickness component whose facets fit another component's "
                     "interference order within ambiguous_order_de on average is read in "
                     "that order, one population and not two an order apart "
                     "(analysis.distributions.pool_interference_orders); `off` keeps each "
                     "facet's least-dE order", choices=("off", "pool"))
    thickness_min_component_samples: float = option(
        1.0, help="fewest independent regions a thickness component needs (with two, "
                  "populations on one region were lost on the generalization sweep)", low=0)
    thickness_max_samples: int = option(
        20000, help="thickness samples fitted at most (a reproducible subsample above)", low=10)
    ndf_sd_floor_deg: float = option(0.05, help="smallest NDF lobe SD", unit="°", low=0,
                                     low_exclusive=True, high=89)
    ndf_max_samples: int = option(
        50000, help="tilt samples fitted at most (a reproducible subsample above)", low=10)
    ndf_min_component_samples: float = option(2.0, help="fewest facets an NDF lobe needs",
                                              low=0)
    min_ndf_facets: int = option(20, help="fewest facets with a height plane for an "
                                          "identified NDF", low=2)
    max_width_error: float = option(
        0.25, help="largest relative 1-σ error of the lobe width for an identified NDF",
        low=0, low_exclusive=True)
    self_check: bool = option(
        True, help="measure the NDF's slope transfer on the stack itself (injection-recovery, "
                   "joint mode with a height from focus) and refuse an NDF it says the stack "
                   "cannot resolve")
    self_check_range: tuple = option(
        (0.8, 1.25), help="recovered/injected RMS slope outside this range: the NDF is not "
                          "identified", kind=tuple, check=lambda v: None if (
                              len(v) == 2 and 0 < v[0] < 1 < v[1]) else "need 0 < low < 1 < high")
    self_check_max_spread: float = option(
        0.1, help="largest half-range of the self-check's slope gains over its injected widths "
                  "for an identified NDF: a gain that changes more with the width is not one "
                  "transfer of the stack (on the 256^2 sweep's seeds 0-17 the two identified "
                  "NDFs off by more than 25 % had 0.12 and 0.14, eleven of the twelve others "
                  "at most 0.07; docs/accuracy.md)", low=0)
    self_check_sigmas: float = option(
        1.0, help="standard errors of the self-check's transfers (over the facets it measured "
                  "them on) that must lie between them and the edges of self_check_range for "
                  "an identified NDF: a transfer the stack measures too noisily to place "
                  "inside the range does not establish it", low=0)
    self_check_correct: bool = option(
        True, help="scale the NDF's lobes to the RMS slope the self-check vouches for (the "
                   "facet planes' RMS slope below the acceptance, slope noise removed, over "
                   "the self-check's width transfer), where the self-check measured both its "
                   "transfers in [self_check_min_transfer, the top of self_check_range] and "
                   "those planes cover most of the NDF's (analysis.distributions."
                   "SECOND_MOMENT_MIN_COVERAGE), identified or not (the correction's size "
                   "stays in the width's error)")
    self_check_min_transfer: float = option(
        0.5, help="smallest slope gain and width transfer of the self-check that the NDF's "
                  "width is corrected by (a correction of at most 1/this: below it the "
                  "heights keep too little of the slopes for the correction to be a "
                  "measurement)", low=0, low_exclusive=True, high=1)
    max_dome_share: float = option(
        0.3, help="largest mean square slope inside the facets (which planes miss) as a share "
                  "of the planes' own, for an identified NDF (0.3: the planes' RMS slope at "
                  "most 12 % below the per-pixel one); where it cannot be measured (too few "
                  "facets with enough heights) the NDF is not identified either", low=0)
    max_censored_fraction: float = option(
        0.5, help="largest share of the surface past the acceptance for an identified NDF",
        low=0, high=1)
    ambiguous_order_de: float = option(
        1.0, help="a ROI or facet whose runner-up interference order fits within this is "
                  "ambiguous", unit="ΔE", low=0)
    unexplained_mads: float = option(
        5.0, help="facets whose ΔE is above median + this × 1.4826 MAD are not explained by "
                  "the film model (left out of the thickness mixture)", low=0)
    colour_contrast_factor: float = option(
        3.0, help="colour carries tilt when a 10° tilt changes it by more than this × the "
                  "colour error", low=0)
    excess_delta_e: float = option(
        1.0, help="warn when the median ΔE is this far above the image's noise floor",
        unit="ΔE", low=0)
    sample_tilt_warn_fraction: float = option(
        0.5, help="warn when the sample's mean plane is tilted by more than this fraction of "
                  "the NDF's rms lobe width (a tilt m widens a lobe σ to √(σ² + m²))", low=0)

    def __post_init__(self):
        super().__post_init__()
        top = self.thickness_max_sd_nm
        if top is not None and top <= self.thickness_sd_floor_nm:
            raise InputError(f"must be > `fits.thickness_sd_floor_nm` "
                             f"({self.thickness_sd_floor_nm:g}), got {top:g}",
                             param="thickness_max_sd_nm")


@dataclass(frozen=True)
class OpticsOptions(Options):
    """What the film model assumes; None takes the stack's value, then the default."""

    film: str | None = option(
        None, help=f"optical-constant set of the oxide film (stack.json's, else {DEFAULT_FILM})",
        kind=str, check=unknown_set_reason, cli=True)
    substrate: str | None = option(
        None, help=f"optical-constant set of the metal (stack.json's, else {DEFAULT_SUBSTRATE})",
        kind=str, check=unknown_set_reason, cli=True)
    illuminant: str | None = option(
        None, help=f"light the images are white-balanced to (stack.json's, else "
                   f"{DEFAULT_ILLUMINANT})", kind=str, cli=True)
    exposure: float | None = option(
        None, help="scale from the model's linear sRGB to the image's (stack.json's, else "
                   "estimated)", kind=float, low=0, low_exclusive=True, cli=True, metavar="E")
    white_balance: str = option(
        "report", help="the camera's white balance without a reference: `off` takes the "
                    "image as balanced; `report` (the default) also estimates the R and B "
                    "gains from the film's colours into summary.json, warns where they look "
                    "off and carries their uncertainty into the thickness means'; `apply` "
                    "corrects each gain the estimate calls "
                    "determined (experimental: not yet within 2 percent on the sweep, "
                    "docs/accuracy.md); a reference (`white_reference`, `substrate_reference`, "
                    "stack.json's white_balance, white_reference or substrate_reference) is "
                    "always applied",
        choices=("off", "report", "apply"), cli=True)
    white_reference: str | None = option(
        None, help="an image of a white standard taken with the stack's camera settings: its "
                   "R, G, B set the white balance", kind=str, cli=True, metavar="FILE")
    substrate_reference: str | None = option(
        None, help="an image of the bare substrate (the metal without its film, a flat area "
                   "facing the objective) taken with the stack's camera settings and light: "
                   "its R, G, B over the model's colour of that metal set the white balance "
                   "(a white reference wins over it)", kind=str, cli=True, metavar="FILE")
    substrate_oxide_nm: float = option(
        3.0, help="native oxide on the bare substrate of `substrate_reference` (titanium in "
                  "air: a few nm, each moving its colour by about 1 percent; its +-1.5 nm "
                  "enter the gains' uncertainty)", unit="nm", low=0, high=20, cli=True)
    flat_reference: str | None = option(
        None, help="an image of an even, featureless target (a mirror, a white standard or a "
                   "clean blank field) through the stack's optics and light: its smoothed "
                   "brightness is the flat field (vignetting) the colours are divided by, in "
                   "place of the joint mode's estimate", kind=str, cli=True, metavar="FILE")
    thickness_range_nm: tuple = option(
        (0.0, 400.0), help="global thickness search range", unit="nm", kind=tuple,
        check=_thickness_range, cli=True)
    delta_e_method: str = option(
        "CIEDE2000", help="colour difference every stage minimises and reports (seed: ΔE; the "
                          "cost of the others: docs/speed-vs-error.md)", choices=METHODS,
        cli=True)


@dataclass(frozen=True)
class AnalysisOptions(Options):
    """Options of :func:`~microfacet.analysis.pipeline.analyse_stack` (defaults follow the
    seed; the sections are listed in the module notes).

    Examples
    --------
    >>> o = AnalysisOptions(mode="seed").replace(roi={"size_px": 128})
    >>> o.mode, o.roi.size_px
    ('seed', 128)
    >>> AnalysisOptions.from_dict(o.to_dict()) == o
    True
    """

    mode: str = option("joint", help="joint: facet planes + colour; seed: the paper's "
                                     "per-pixel inversion", choices=MODES, cli=True)
    seed: int = option(0, help="random sampling in the ROI and exposure fits", low=0)
    focus: FocusOptions = option(FocusOptions(), help="height from focus")
    mask: MaskOptions = option(MaskOptions(), help="colour mask")
    roi: RoiOptions = option(RoiOptions(), help="thickness per ROI")
    joint: JointOptions = option(JointOptions(), help="joint mode")
    tilt: TiltOptions = option(TiltOptions(), help="per-pixel tilt")
    fits: FitOptions = option(FitOptions(), help="mixtures and identification")
    optics: OpticsOptions = option(OpticsOptions(), help="film model")


@dataclass(frozen=True)
class Scene:
    """What an analysis knows of the scene before it looks at the colours: the optics it
    models (film and substrate sets, illuminant, numerical aperture and the largest facet tilt
    the objective sees, asin(NA)/2 in degrees), the pixel size ``(y, x)`` in µm, whether the
    height comes from focus (not a microscope's export), the exposure (given, or None: to be
    estimated) and where it came from, and the seed of the random samples."""

    film: str
    substrate: str
    illuminant: str
    numerical_aperture: float
    max_tilt_deg: float
    pixel_size_um: tuple
    from_focus: bool
    exposure: float | None
    exposure_source: str
    seed: int = 0

    @property
    def estimate_exposure(self) -> bool:
        return self.exposure is None

    def optics_json(self) -> dict:
        """The optics as ``summary.json`` ``inputs`` records them."""
        return {"film": self.film, "substrate": self.substrate, "illuminant": self.illuminant,
                "numerical_aperture": self.numerical_aperture}


def scene_of(stack, options: AnalysisOptions) -> Scene:
    """The scene of ``stack`` under ``options``: the options' film, substrate, illuminant and
    exposure, else the stack's, else the defaults (the exposure: estimated)."""
    o = options.optics
    film = o.film or stack.film or DEFAULT_FILM
    substrate = o.substrate or stack.substrate or DEFAULT_SUBSTRATE
    for key, name in (("optics.film", film), ("optics.substrate", substrate)):
        if name not in known_sets():
            raise InputError(unknown_set_reason(name), param=key)
    na = float(stack.numerical_aperture)
    exposure = o.exposure if o.exposure is not None else stack.exposure
    source = ("option" if o.exposure is not None else
              "stack.json" if stack.exposure is not None else "estimated")
    return Scene(film, substrate, o.illuminant or stack.illuminant or DEFAULT_ILLUMINANT, na,
                 math.degrees(math.asin(na)) / 2.0, tuple(stack.pixel_size_yx_um),
                 bool(stack.has_slices), exposure, source, options.seed)
