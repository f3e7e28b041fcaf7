from . import (
    angular,
    defaults,
    densities,
    distributions,
    errors,
    lazy,
    options,
    pixels,
    threads,
    timing,
)
from .angular import AngularMap
from .distributions import NDFMixture, ThicknessMixture
from .errors import InputError

__all__ = [
    "AngularMap",
    "InputError",
    "NDFMixture",
    "ThicknessMixture",
    "angular",
    "defaults",
    "densities",
    "distributions",
    "errors",
    "lazy",
    "options",
    "pixels",
    "threads",
    "timing",
]
