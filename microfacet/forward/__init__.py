"""Forward models: the colour of the film for any light and view direction, from the
thickness distribution and the NDF; and synthetic focus stacks with ground truth.

==================  ==========================================================
module              concern
==================  ==========================================================
``halfvector``      half-vector geometry and spectra (seed §2.3, eq. 5)
``brdf``            microfacet thin-film BRDF (Walter et al. 2007 with the NDF)
``eq6``             the seed's eq. 6
``angular``         angular colour maps of any model; the display exposure rule
``compare``         ΔE00 against a measured map; fitting exposure and eq. 6's n
``scene``           synthetic surfaces, thickness fields and sharp images
``synth``           synthetic focus stacks (presets, noise, defocus, truth)
==================  ==========================================================
"""

from ..core.lazy import attach

__getattr__, __dir__, __all__ = attach(__name__, submodules=(
    "halfvector", "brdf", "eq6", "angular", "compare", "scene", "synth"), submod_attrs={
    "angular": ["simulate_map", "display_exposure"],
    "synth": ["SynthParams", "generate_stack", "preset"],
})
