"""Options of height from focus and their defaults (no numpy: the command line's help shows
them). The defaults were chosen from the accuracy table in docs/height-from-focus.md
(``python pipelines/focus_accuracy.py``); their cost against the alternatives:
docs/speed-vs-error.md."""

__all__ = ["DEFAULT_FIT_RADIUS", "DEFAULT_INTERPOLATION", "DEFAULT_MIN_RELIABILITY_DB",
           "DEFAULT_OPERATOR", "DEFAULT_WINDOW", "DEFAULT_WINDOW_PX", "INTERPOLATIONS",
           "OPERATORS", "WINDOWS"]

#: Focus measures (:func:`microfacet.focus.measures.focus_measure`) and their windows.
OPERATORS = ("tenengrad", "sml", "glv")
WINDOWS = ("gaussian", "box")
DEFAULT_OPERATOR = "tenengrad"
DEFAULT_WINDOW_PX = 7
DEFAULT_WINDOW = "gaussian"
#: Sub-slice peak estimates (:func:`microfacet.focus.height.height_from_focus`).
INTERPOLATIONS = ("lsq", "gauss3", "none")
DEFAULT_INTERPOLATION = "lsq"
DEFAULT_FIT_RADIUS = 2
#: Default reliability cut in dB per operator: above the 99.9th percentile of pure-noise
#: (textureless) pixels and below the 1st percentile of textured ones in the synthetic check
#: of tests/focus; see docs/height-from-focus.md.
DEFAULT_MIN_RELIABILITY_DB = {"tenengrad": 12.0, "sml": 9.0, "glv": 11.0}
