"""The options of height from focus: one typed section, the one place their defaults are
written (no numpy: the command line's help shows them).

:class:`FocusOptions` is the ``focus`` section of the analysis' options tree
(:class:`~microfacet.analysis.options.AnalysisOptions`) and the options of
:func:`~microfacet.focus.height.height_from_focus` and ``microfacet height``. Each field
carries its default, valid values and help (:mod:`microfacet.core.options`); constructing a
section validates it and an :class:`~microfacet.core.errors.InputError` names the field.

The defaults were chosen from the accuracy table and the coverage measurements in
docs/height-from-focus.md (``python -m pipelines run accuracy-focus``,
``python -m pipelines run accuracy-focus-coverage``); their cost against the alternatives:
docs/speed-vs-error.md and ``python -m pipelines run speed-focus``.

What stays a module constant, and why: the valid values (``OPERATORS``, ``WINDOWS``, ...:
what the code implements, not a setting) and :data:`RELIABILITY_CUTS_DB`, the measured cut of
each reliability measure and operator that ``min_reliability_db=None`` stands for (a table
per operator, not one value). The constants of the uncertainty model (``SIGMA_MODEL``,
``DETECTION_ALPHA``) live in :mod:`microfacet.focus.uncertainty`: they are calibrations of
the model, not choices a user makes.

Examples
--------
>>> o = FocusOptions(operator="sml", window_px=9)
>>> o.window_px, o.interpolation, o.reliability_cut_db
(9, 'lorentz', 4.0)
>>> FocusOptions(reliability="pertuz").reliability_cut_db
12.0
>>> from microfacet.core.errors import InputError
>>> try:
...     FocusOptions(window_px=4)
... except InputError as exc:
...     print(exc)
window_px: must be an odd integer >= 1, got 4
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from numbers import Integral, Real

from ..core.options import Options, option

__all__ = ["EARLIER_DEFAULT", "FocusOptions", "OPERATORS"]

#: Focus measures (:func:`microfacet.focus.measures.focus_measure`); a new one also needs its
#: cuts in :data:`RELIABILITY_CUTS_DB`.
OPERATORS = ("tenengrad", "sml", "glv")
#: Window shapes of a focus measure.
WINDOWS = ("gaussian", "box")
#: What a focus measure sees of an RGB slice.
COLOURS = ("luma", "rgb")
#: Sub-slice peak estimates (:mod:`microfacet.focus.peaks`).
INTERPOLATIONS = ("lorentz", "lsq", "gauss3", "none")
#: Meanings of ``reliability_db``.
RELIABILITIES = ("sigma", "pertuz")
#: Ways to fill the unreliable pixels (:func:`microfacet.focus.fill.fill_missing`).
FILLS = ("smooth", "nearest")
#: Registration methods of the slices (:mod:`microfacet.focus.align`).
ALIGN_METHODS = ("ecc", "phase")

#: The cut ``min_reliability_db=None`` stands for, per reliability measure and operator (dB).
#:
#: * ``"sigma"``: 4 dB ⇔ σ ≤ 0.63 z step, the same for every operator: the lowest cut whose
#:   RMSE and share of heights off by more than one step, on all pixels and at sharp relief,
#:   are at most those of the earlier default (``python -m pipelines run
#:   accuracy-focus-coverage``, table "Choice of the cut"; docs/height-from-focus.md).
#: * ``"pertuz"``: above the 99.9th percentile of pure-noise (textureless) pixels and below
#:   the 1st percentile of textured ones in the synthetic check of tests/focus.
RELIABILITY_CUTS_DB = {
    "sigma": {"tenengrad": 4.0, "sml": 4.0, "glv": 4.0},
    "pertuz": {"tenengrad": 12.0, "sml": 9.0, "glv": 11.0},
}


def odd_window_reason(value) -> str | None:
    """Why ``value`` is not a window side (an odd integer >= 1), or None.

    >>> odd_window_reason(7) is None, odd_window_reason(8)
    (True, 'must be an odd integer >= 1, got 8')
    """
    if _integer(value) is not None or value < 1 or value % 2 == 0:
        return f"must be an odd integer >= 1, got {value!r}"
    return None


def _integer(value) -> str | None:
    """Python and numpy integers, not bools."""
    if isinstance(value, bool) or not isinstance(value, Integral):
        return f"must be an integer, got {value!r}"
    return None


def _fit_radius(value) -> str | None:
    if _integer(value) is not None or not 1 <= value <= 10:
        return f"must be an integer in 1..10, got {value!r}"
    return None


def _index(value) -> str | None:
    if _integer(value) is not None or value < 0:
        return f"must be an integer >= 0, got {value!r}"
    return None


def _optional_window(value) -> str | None:
    """0 (off) or an odd window side."""
    if _integer(value) is None and value == 0 or odd_window_reason(value) is None:
        return None
    return f"must be 0 (none) or an odd integer >= 1, got {value!r}"


def _cut_db(value) -> str | None:
    """A number of dB; ``-inf`` keeps every pixel, NaN would keep none silently."""
    if isinstance(value, bool) or not isinstance(value, Real) or math.isnan(value):
        return f"must be a number (dB; -inf keeps every pixel), got {value!r}"
    return None


@dataclass(frozen=True)
class FocusOptions(Options):
    """Options of height from focus (:func:`~microfacet.focus.height.height_from_focus`).

    Attributes
    ----------
    operator : {"tenengrad", "sml", "glv"}
        Focus measure (:func:`~microfacet.focus.measures.focus_measure`). Tenengrad with a
        Gaussian 7-px window and the Lorentz fit has the lowest RMSE on the Cou & Guennebaud
        stacks (0.098 / 0.101 / 0.118 slices; docs/height-from-focus.md).
    window_px : int
        Odd side of the main focus window, px (the Gaussian's σ = window_px/√12). 5 px raises
        the RMSE to 0.119-0.134, 9-11 px gain nothing (lsq rows of the accuracy table).
    window : {"gaussian", "box"}
        Window shape: a Gaussian beats a box of the same spread (0.102 vs 0.109 on stack 1).
    interpolation : {"lorentz", "lsq", "gauss3", "none"}
        Sub-slice peak estimate: ``"lorentz"`` fits a parabola to F^(-1/2) (the focus curve
        of Gaussian-blurred texture, F ∝ (s² + β²(z − μ)²)^-2), ``"lsq"`` a parabola to
        log F (a Gaussian curve; the earlier default), ``"gauss3"`` the classic 3-point
        Gaussian (biased: 0.218 vs 0.144 slices with SML box 5), ``"none"`` the arg-max slice.
    fit_radius : int
        Slices on each side of the sharpest one used by ``"lorentz"`` and ``"lsq"`` (2: r = 3
        measures the same, 0.104 vs 0.102); ``"gauss3"`` and ``"none"`` use 1.
    min_reliability_db : float or None
        Pixels below this reliability are NaN in ``height_um`` (``-inf`` keeps all). None:
        the measured cut of the reliability measure and operator
        (:data:`RELIABILITY_CUTS_DB`: 4 dB, σ ≤ 0.63 z step, for ``"sigma"``).
    fill : {None, "smooth", "nearest"}
        Fill the unreliable pixels (:func:`~microfacet.focus.fill.fill_missing`); None
        leaves them NaN.
    align : {None, "ecc", "phase"}
        Register every slice to a reference slice before measuring focus (a second pass over
        the stack; :mod:`microfacet.focus.align`). None: the slices are taken as registered.
    reference : int or None
        File-order index of the alignment reference; None: the slice whose field of view
        the most other slices cover.
    colour : {"luma", "rgb"}
        Measure the luma of RGB slices, or sum the measures of the three channels: better
        where the colour texture is more than about twice the grey one, at three times the
        noise floor (``focus_coverage.py``, colour table).
    coarse_window_px : int
        A second, larger window, evaluated on a grid downsampled by 2 when ≥ 11 px; each
        pixel takes the window whose height has the smaller uncertainty, the coarse one where
        texture is weak (coverage at luma contrast 0.012: 74 % against 34 % with 7 px alone,
        for at most 0.001 slice of Cou RMSE). 0: the main window only; ignored unless larger
        than ``window_px``.
    fine_window_px : int
        A smaller window for sharp relief (coverage of the relief zone 86-91 % instead of
        76-82 % with 3 px), off (0) by default: it raises the Cou RMSE to 0.116 / 0.126 /
        0.147. Ignored unless smaller than ``window_px``.
    evidence_window_px : int
        A small window measured beside the others but not combined with them: its height
        (``FocusResult.evidence_height_um``) comes from the focus evidence within about a
        pixel, never from texture several pixels away, which is what a facet's plane needs
        (a 7-15 px window lends a textureless facet the height of its neighbours' edges and
        flattens it: docs/accuracy.md). 0: off (the planes use the combined height).
    reliability : {"sigma", "pertuz"}
        What ``reliability_db`` means: ``"sigma"``, the precision of the height,
        −20·log10(σ / z step) dB, on pixels whose focus peak is significant; ``"pertuz"``,
        the ratio of Pertuz et al. (2013), the earlier default.
    slope_sigma_px : float
        σ (px) of the NaN-aware smoothing of the height's slopes before the analysis takes
        normals (1 px: pixel noise of a height from focus); an instrument's height map is
        used as measured (:func:`~microfacet.analysis.surface.surface_normals`).
    """

    CLI_PREFIX = ""

    operator: str = option(
        "tenengrad", help="focus measure (tenengrad: lowest RMSE on the Cou & Guennebaud "
                          "stacks)", choices=OPERATORS, cli=True)
    window_px: int = option(
        7, help="odd side of the main focus window (5 px: higher RMSE, 9-11 px: no gain)",
        unit="px", check=odd_window_reason, cli=True, metavar="N")
    window: str = option(
        "gaussian", help="focus window shape (a Gaussian beats a box of the same spread)",
        choices=WINDOWS, cli=True)
    interpolation: str = option(
        "lorentz", help="sub-slice peak estimate: parabola in F^-1/2 (lorentz), in log F "
                        "(lsq, the earlier default), 3-point Gaussian, or the arg-max slice",
        choices=INTERPOLATIONS, cli=True)
    fit_radius: int = option(
        2, help="slices on each side of the peak fitted by lorentz and lsq (gauss3 and none "
                "use 1)", check=_fit_radius, cli=True, metavar="R")
    min_reliability_db: float | None = option(
        None, help="reliability cut, dB (-inf keeps every pixel; default 4 dB, σ <= 0.63 z "
                   "step, or the Pertuz cut of the operator)", unit="dB", kind=float,
        check=_cut_db, cli=True, metavar="DB")
    fill: str | None = option(
        None, help="fill the unreliable pixels (method smooth when none is given)", kind=str,
        choices=FILLS, cli=True, cli_kwargs=dict(nargs="?", const="smooth"))
    align: str | None = option(
        None, help="register the slices to a reference slice first (method ecc when none is "
                   "given)", kind=str, choices=ALIGN_METHODS, cli=True,
        cli_kwargs=dict(nargs="?", const="ecc"))
    reference: int | None = option(
        None, help="file index of the alignment reference (none: the slice the others cover "
                   "most)", kind=int, check=_index)
    colour: str = option(
        "luma", help="measure the luma, or sum the measures of the R, G, B channels (rgb: for "
                     "colour texture stronger than about twice the grey one)", choices=COLOURS)
    coarse_window_px: int = option(
        15, help="a second, coarser window taken where texture is weak (0: none)", unit="px",
        check=_optional_window)
    fine_window_px: int = option(
        0, help="a finer window for sharp relief (0: none; 3 px covers more of it at a "
                "higher RMSE on smooth stacks)", unit="px", check=_optional_window)
    evidence_window_px: int = option(
        3, help="a small window whose heights the facet planes use: each from the focus "
                "evidence within about a pixel (0: the planes use the combined height)",
        unit="px", check=_optional_window)
    reliability: str = option(
        "sigma", help="reliability measure: the height's precision (sigma) or Pertuz et al. "
                      "(2013)", choices=RELIABILITIES)
    slope_sigma_px: float = option(
        1.0, help="σ of the smoothing of a focus height map's slopes before its normals (an "
                  "instrument's height map is used as measured, unsmoothed)", unit="px", low=0)

    @property
    def reliability_cut_db(self) -> float:
        """The reliability cut in use: ``min_reliability_db``, or the measured one."""
        if self.min_reliability_db is not None:
            return float(self.min_reliability_db)
        return RELIABILITY_CUTS_DB[self.reliability][self.operator]

    @property
    def fit_radius_used(self) -> int:
        """Slices on each side of the peak the fit uses: ``fit_radius`` for ``"lorentz"`` and
        ``"lsq"``, 1 for ``"gauss3"`` and ``"none"``."""
        return int(self.fit_radius) if self.interpolation in ("lsq", "lorentz") else 1


#: The options that reproduce the default of earlier versions exactly (Gaussian fit, one
#: 7-px window, Pertuz reliability cut at 12 dB): the pipelines compare against it.
EARLIER_DEFAULT = FocusOptions(interpolation="lsq", coarse_window_px=0, reliability="pertuz")
