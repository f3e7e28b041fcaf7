from . import (
    adaptation,
    arrays,
    colorimetry,
    datasets,
    difference,
    model,
    srgb,
    table,
    transfer,
)
from .adaptation import bradford_matrix
from .colorimetry import (
    lab_to_xyz,
    spectral_weights,
    spectrum_to_lab,
    spectrum_to_xyz,
    white_xyz,
    xyz_to_lab,
)
from .datasets import cmfs, illuminant_sd, known_illuminants
from .difference import METHODS, delta_e, delta_e_76, delta_e_94, delta_e_2000
from .model import FilmColourModel
from .srgb import (
    SRGB_TO_XYZ,
    SRGB_WHITE_XYZ,
    XYZ_TO_SRGB,
    colours_from_spectra,
    lab_to_srgb,
    linear_srgb_to_xyz,
    model_xyz_to_linear_srgb,
    srgb_to_lab,
    xyz_to_linear_srgb,
)
from .table import ColourTable, build_colour_table, choose_spectral_step, direct_xyz
from .transfer import srgb_decode, srgb_encode

__all__ = [
    "ColourTable",
    "FilmColourModel",
    "METHODS",
    "SRGB_TO_XYZ",
    "SRGB_WHITE_XYZ",
    "XYZ_TO_SRGB",
    "adaptation",
    "arrays",
    "bradford_matrix",
    "build_colour_table",
    "choose_spectral_step",
    "cmfs",
    "colorimetry",
    "colours_from_spectra",
    "datasets",
    "delta_e",
    "delta_e_2000",
    "delta_e_76",
    "delta_e_94",
    "difference",
    "direct_xyz",
    "illuminant_sd",
    "known_illuminants",
    "lab_to_srgb",
    "lab_to_xyz",
    "linear_srgb_to_xyz",
    "model",
    "model_xyz_to_linear_srgb",
    "spectral_weights",
    "spectrum_to_lab",
    "spectrum_to_xyz",
    "srgb",
    "srgb_decode",
    "srgb_encode",
    "srgb_to_lab",
    "table",
    "transfer",
    "white_xyz",
    "xyz_to_lab",
    "xyz_to_linear_srgb",
]
