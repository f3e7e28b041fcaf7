from . import constants, defaults, spectrumfit, thinfilm
from .constants import (
    OpticalConstantSet,
    known_sets,
    load_set,
    optical_constants,
    resolve_index,
)
from .defaults import DEFAULT_FILM, DEFAULT_SUBSTRATE
from .spectrumfit import SpectrumFit, fit_thickness
from .thinfilm import reflectance

__all__ = [
    "DEFAULT_FILM",
    "DEFAULT_SUBSTRATE",
    "OpticalConstantSet",
    "SpectrumFit",
    "constants",
    "defaults",
    "fit_thickness",
    "known_sets",
    "load_set",
    "optical_constants",
    "reflectance",
    "resolve_index",
    "spectrumfit",
    "thinfilm",
]
