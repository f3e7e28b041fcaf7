"""The analysis: a focus stack in, the thickness distribution and the NDF out (seed §3.3.3).

==================  ============================================================
module              stage
==================  ============================================================
``options``         :class:`AnalysisOptions`, the scene's optics
``surface``         height map (from focus or an export), normals, tilt
``colour_image``    CIELAB, the colour mask (``mask``), the colour noise
``roi``             thickness per region of interest, interference order, exposure
``tilt``            per-pixel tilt by colour inversion (seed mode)
``facets``          facets, plane fits, per-facet thickness (joint mode)
``mixtures``        thickness mixture, components by BIC with honest sample sizes
``ndf_fit``         NDF lobes (Rayleigh EM); ``fit_distributions`` (the stage)
``pipeline``        :func:`analyze_stack`: the stages in order
``output``          :func:`write_results`: the results folder
==================  ============================================================

Nothing here imports the forward models or the report.
"""

from ..core.lazy import attach

__getattr__, __dir__, __all__ = attach(__name__, submodules=(
    "options", "surface", "colour_image", "mask", "roi", "tilt", "facets", "mixtures",
    "ndf_fit", "pipeline", "output"), submod_attrs={
    "options": ["AnalysisOptions"],
    "pipeline": ["AnalysisResult", "analyze_stack"],
    "output": ["save_results", "write_results"],
})
