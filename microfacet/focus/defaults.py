"""Options of height from focus and their defaults (no numpy: the command line's help shows
them). The defaults were chosen from the accuracy table and the coverage measurements in
docs/height-from-focus.md (``python pipelines/focus_accuracy.py``,
``python pipelines/focus_coverage.py``); their cost against the alternatives:
docs/speed-vs-error.md and ``python pipelines/bench_focus.py``."""

__all__ = ["COLOURS", "DEFAULT_COARSE_WINDOW_PX", "DEFAULT_COLOUR", "DEFAULT_FIT_RADIUS",
           "DEFAULT_INTERPOLATION", "DEFAULT_MIN_RELIABILITY_DB", "DEFAULT_OPERATOR",
           "DEFAULT_RELIABILITY", "DEFAULT_WINDOW", "DEFAULT_WINDOW_PX", "DETECTION_ALPHA",
           "EARLIER_DEFAULT", "INTERPOLATIONS", "OPERATORS", "PERTUZ_MIN_RELIABILITY_DB",
           "RELIABILITIES", "SIGMA_MODEL", "WINDOWS"]

#: Focus measures (:func:`microfacet.focus.measures.focus_measure`) and their windows.
OPERATORS = ("tenengrad", "sml", "glv")
WINDOWS = ("gaussian", "box")
COLOURS = ("luma", "rgb")
DEFAULT_OPERATOR = "tenengrad"
DEFAULT_WINDOW_PX = 7
DEFAULT_WINDOW = "gaussian"
DEFAULT_COLOUR = "luma"
#: The second, coarser window (evaluated on a grid downsampled by 2). Each pixel takes the
#: window whose height has the smaller uncertainty: the coarse one where texture is weak.
DEFAULT_COARSE_WINDOW_PX = 15
#: Sub-slice peak estimates (:func:`microfacet.focus.height.height_from_focus`):
#: "lorentz" fits a parabola to F^(-1/2) (the focus curve of Gaussian-blurred texture,
#: F ∝ (s² + β²(z − μ)²)^-2), "lsq" a parabola to log F (a Gaussian curve).
INTERPOLATIONS = ("lorentz", "lsq", "gauss3", "none")
DEFAULT_INTERPOLATION = "lorentz"
DEFAULT_FIT_RADIUS = 2
#: Reliability: "sigma" = the precision of the height, −20·log10(σ / z step) dB, on pixels
#: whose focus peak is significant; "pertuz" = Pertuz et al. (2013), the earlier default.
RELIABILITIES = ("sigma", "pertuz")
DEFAULT_RELIABILITY = "sigma"
#: Default cut for "sigma": 4 dB ⇔ σ ≤ 0.63 z step (the same for every operator): the lowest
#: cut whose RMSE and share of heights off by more than one step, on all pixels and at sharp
#: relief, are at most those of the earlier default (``pipelines/focus_coverage.py``, table
#: "Choice of the cut"; docs/height-from-focus.md).
DEFAULT_MIN_RELIABILITY_DB = {"tenengrad": 4.0, "sml": 4.0, "glv": 4.0}
#: The cuts of "pertuz": above the 99.9th percentile of pure-noise (textureless) pixels and
#: below the 1st percentile of textured ones in the synthetic check of tests/focus.
PERTUZ_MIN_RELIABILITY_DB = {"tenengrad": 12.0, "sml": 9.0, "glv": 11.0}
#: Nominal false-peak rate per pixel and window of the detection test (the measured rate on
#: pure noise is 1e-4 to 4e-4: the tails' mean and spread are estimated from few slices).
DETECTION_ALPHA = 1e-5
#: Terms of the height uncertainty, in z steps (docs/height-from-focus.md, calibrated with
#: pipelines/focus_coverage.py): σ² = σ_fit² + (slope·s·σ_w)² + (curv·c·σ_w²)²
#: + (broad·√(w² − (ratio·w_med)²))² + floor², σ_w the window's spread.
SIGMA_MODEL = {"slope": 0.4, "curv": 1.4, "broad": 0.5, "broad_ratio": 1.5, "floor": 0.03,
               "prior_dof": 8.0, "prefer": 1.0}
#: The options that reproduce the default of earlier versions exactly (Gaussian fit, one
#: 7-px window, Pertuz reliability cut at 12 dB): used by the pipelines to compare.
EARLIER_DEFAULT = {"interpolation": "lsq", "coarse_window_px": None, "reliability": "pertuz"}
