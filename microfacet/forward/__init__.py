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
``material``        the measured material tabulated for renderers (film average × lobes)
``scene``           synthetic surfaces, thickness fields and sharp images
``relief``          relief beyond planar facets: shaped cells, domes, terraces, pits, dust
``imaging``         the microscope's pupil, vignetting, white balance and drift
``synth_params``    :class:`SynthParams` and the imaging variations
``synth``           synthetic focus stacks (presets, noise, defocus, truth)
==================  ==========================================================
"""

from ..core.lazy import attach_stub

__getattr__, __dir__, __all__ = attach_stub(__name__, __file__)
