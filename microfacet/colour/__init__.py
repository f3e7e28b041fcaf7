"""Colour: spectra to CIE XYZ and CIELAB, sRGB images, colour differences, and the
(incidence angle × thickness) colour table the analysis searches.

==================  ==========================================================
module              concern
==================  ==========================================================
``datasets``        CMFs and illuminant spectra (colour-science's tables)
``colorimetry``     spectral weights, spectra → XYZ, XYZ ↔ Lab
``adaptation``      Bradford chromatic adaptation (colour-science's)
``transfer``        the sRGB transfer functions (decode / encode)
``srgb``            RGB ↔ XYZ, image ↔ Lab, model colours as sRGB
``difference``      CIEDE2000 (fast, float32), CIE94, CIE76, ``delta_e(method=)``
``table``           the colour table: model colour on a (θ, d) grid, with its error
==================  ==========================================================

Which parts delegate to colour-science and which are kept ours, with the measurements:
docs/colour-benchmarks.md. The names below are importable from ``microfacet.colour`` and
load on first use; ``import microfacet.colour`` imports neither colour-science nor the
submodules.
"""

from ..core.lazy import attach

__getattr__, __dir__, __all__ = attach(__name__, submodules=(
    "datasets", "colorimetry", "adaptation", "transfer", "srgb", "difference", "table"),
    submod_attrs={
        "datasets": ["OBSERVERS", "cmfs", "illuminant_key", "illuminant_sd",
                     "known_illuminants", "observer_name"],
        "colorimetry": ["lab_to_xyz", "spectral_weights", "spectrum_to_lab",
                        "spectrum_to_xyz", "white_xyz", "xyz_to_lab"],
        "adaptation": ["BRADFORD", "bradford_matrix"],
        "transfer": ["srgb_decode", "srgb_encode"],
        "srgb": ["SRGB_TO_XYZ", "SRGB_WHITE_XYZ", "XYZ_TO_SRGB", "colours_from_spectra",
                 "image_white_xyz", "lab_to_srgb", "linear_srgb_to_xyz",
                 "model_xyz_to_linear_srgb", "srgb_to_lab", "xyz_to_linear_srgb"],
        "difference": ["METHODS", "delta_e", "delta_e_2000", "delta_e_76", "delta_e_94"],
        "table": ["ColourTable", "SPECTRAL_STEPS_NM", "WAVELENGTH_RANGE_NM",
                  "build_colour_table", "choose_spectral_step", "direct_xyz"],
    })
