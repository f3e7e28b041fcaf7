"""Colour: spectra to CIE XYZ and CIELAB, sRGB images, colour differences, and the
(incidence angle × thickness) colour table the analysis searches.

==================  ==========================================================
module              concern
==================  ==========================================================
``colorimetry``     CMFs, illuminants, spectral weights, spectra → XYZ, XYZ ↔ Lab
``srgb``            sRGB encoding, RGB ↔ XYZ, chromatic adaptation, image ↔ Lab
``difference``      CIEDE2000 (fast, float32), CIE94, CIE76, ``delta_e(method=)``
``table``           the colour table: model colour on a (θ, d) grid, with its error
==================  ==========================================================

The names below are importable from ``microfacet.colour`` and load on first use.
"""

from ..core.lazy import attach

__getattr__, __dir__, __all__ = attach(__name__, submodules=(
    "colorimetry", "srgb", "difference", "table"), submod_attrs={
    "colorimetry": ['OBSERVERS', 'cmfs', 'illuminant_key', 'illuminant_sd', 'known_illuminants', 'lab_to_xyz', 'observer_name', 'spectral_weights', 'spectrum_to_lab', 'spectrum_to_xyz', 'white_xyz', 'xyz_to_lab'],
    "srgb": ['BRADFORD', 'SRGB_TO_XYZ', 'SRGB_WHITE_XYZ', 'XYZ_TO_SRGB', 'bradford_matrix', 'image_white_xyz', 'lab_to_srgb', 'linear_srgb_to_xyz', 'model_xyz_to_linear_srgb', 'srgb_decode', 'srgb_encode', 'srgb_to_lab', 'xyz_to_linear_srgb'],
    "difference": ['METHODS', 'delta_e', 'delta_e_2000', 'delta_e_76', 'delta_e_94'],
    "table": ['ColourTable', 'SPECTRAL_STEPS_NM', 'WAVELENGTH_RANGE_NM', 'build_colour_table', 'choose_spectral_step', 'direct_xyz'],
})
