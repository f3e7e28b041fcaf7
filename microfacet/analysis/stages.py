"""The stages of one analysis, in order: one enum drives the timer (``summary.json``
``timings_s``), the progress bar of the command line and the stage table of
docs/architecture.md (:func:`stage_table`).

The weights are the stages' relative cost: their ``timings_s`` on a 1-megapixel × 40-slice
``nd`` synthetic stack (joint mode, 2 cores; docs/benchmarks.md), so that the progress bar's
estimate follows the measured cost of the stages rather than their count.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

__all__ = ["Stage", "stage_table"]


@dataclass(frozen=True)
class StageInfo:
    key: str
    label: str
    weight: float
    function: str
    produces: str


class Stage(enum.Enum):
    """A stage of ``microfacet analyze``: ``key`` (its ``timings_s`` key), ``label`` (what the
    progress bar shows), ``weight`` (relative cost), the function and what it produces."""

    HEIGHT = StageInfo("height_from_focus", "height from focus", 2.3,
                       "analysis.surface.measure_height",
                       "`FocusResult`: height, its σ, reliability, all-in-focus image")
    NORMALS = StageInfo("normals", "normals", 0.1, "analysis.surface.surface_normals",
                        "`Surface`: normals, tilt of the height map")
    COLOUR = StageInfo("colour_and_mask", "colour", 1.4, "analysis.colour_image.measure_colour",
                       "`ColourImage`: CIELAB, mask, colour noise")
    COLOUR_TABLE = StageInfo("colour_table", "colour table", 0.6,
                             "colour.table.build_colour_table",
                             "`ColourTable` over (tilt, thickness) → `FilmColourModel`")
    ROI = StageInfo("thickness_roi", "thickness per ROI", 1.6, "analysis.roi.thickness_per_roi",
                    "`RoiFit`: thickness per ROI, interference order, exposure")
    SEGMENTATION = StageInfo("segmentation", "facets", 2.1, "analysis.joint.facet_labels",
                             "facet labels from colour and height edges (joint mode)")
    FACET_FITS = StageInfo("facet_fits", "facet fits", 1.6,
                           "analysis.joint.facets_at_exposure_readings",
                           "`JointResult`: planes, exposure, thickness and colour error per "
                           "facet; the flat field (vignetting) their brightness asks for "
                           "(`analysis.flat_field`), the colours divided by it and the facets "
                           "refitted where they then fit better; a thickness component whose "
                           "facets fit another component's interference order alike read in "
                           "that order (`analysis.distributions.pool_interference_orders`, "
                           "`analysis.joint.facets_in_other_order`); then each facet's order "
                           "decided with its neighbours' by a minimum cut "
                           "(`analysis.order_cut`) (joint mode)")
    TILT = StageInfo("tilt_per_pixel", "tilt per pixel", 2.3,
                     "analysis.joint.joint_pixel_tilts / analysis.tilt.seed_tilts",
                     "`PixelEstimates`: thickness, tilt, σ, ΔE per pixel")
    MIXTURES = StageInfo("mixtures", "distributions", 0.9,
                         "analysis.distributions.fit_joint_distributions / "
                         "fit_seed_distributions",
                         "`Distributions`: thickness mixture and NDF, each judged identified "
                         "or not; each thickness mean's 1σ with the white balance's part "
                         "(`analysis.joint.gain_thickness_shifts`)")
    SELF_CHECK = StageInfo("self_check", "self-check", 0.5,
                           "analysis.self_check.self_check_ndf / "
                           "analysis.distributions.correct_ndf_width",
                           "`SelfCheck`: recovered/injected RMS slope of known facet slopes "
                           "rendered in the scene's own conditions (on a thread of its own "
                           "from the facets' planes on, beside the stages before this one; its "
                           "time here is the wait for it); the NDF's judgement, and "
                           "its lobes refitted to the slopes over the width transfer where the "
                           "self-check passes (joint mode)")
    WRITE = StageInfo("write", "write", 0.3, "analysis.output.save_results",
                      "the results folder (`io.results`, `io.summary.Summary`)")
    REPORT = StageInfo("report", "report", 3.3, "report.write_report", "report.pdf and its PNGs")

    @property
    def key(self) -> str:
        return self.value.key

    @property
    def label(self) -> str:
        return self.value.label

    @property
    def weight(self) -> float:
        return self.value.weight


#: The stages the seed mode skips.
JOINT_ONLY = (Stage.SEGMENTATION, Stage.FACET_FITS, Stage.SELF_CHECK)


def stage_table() -> str:
    """The Markdown table of the stages (docs/architecture.md holds it; a test compares).

    >>> stage_table().splitlines()[2].startswith("| `height_from_focus` |")
    True
    """
    rows = ["| stage (timing key) | function | produces |", "|---|---|---|"]
    rows += [f"| `{s.key}` | `{s.value.function}` | {s.value.produces} |" for s in Stage]
    return "\n".join(rows)
