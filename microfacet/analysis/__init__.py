"""The analysis: a focus stack in, the thickness distribution and the NDF out (seed §3.3.3).

==================  ============================================================
module              stage
==================  ============================================================
``options``         :class:`AnalysisOptions`, the scene's optics
``surface``         height map (from focus or an export), normals, tilt
``colour_image``    CIELAB, the colour mask (``mask``), the colour noise
``roi``             thickness per region of interest, interference order, exposure
``search``          coarse-to-fine least value on a grid, row by row (tilt, thickness)
``tilt``            per-pixel tilt by colour inversion (both modes)
``segmentation``    facets from colour and height edges (joint mode)
``facets``          plane fits, per-facet thickness (joint mode)
``joint``           the joint mode's stage: facets → tilt per pixel
``sampling``        independent samples in a map (correlation area)
``mixtures``        thickness mixture (deconvolved), components by BIC with honest n
``ndf_fit``         NDF lobes (deconvolved, censored Rayleigh EM)
``identification``  the distributions stage, and whether the data determine them
``pipeline``        :func:`analyze_stack`: the stages in order
``output``          :func:`write_results`: the results folder
==================  ============================================================

Nothing here imports the forward models or the report.
"""

from ..core.lazy import attach

__getattr__, __dir__, __all__ = attach(__name__, submodules=(
    "options", "surface", "colour_image", "mask", "roi", "search", "tilt", "segmentation", "facets",
    "joint", "sampling", "mixtures", "ndf_fit", "identification", "pipeline", "output"),
    submod_attrs={
    "options": ["AnalysisOptions"],
    "pipeline": ["AnalysisResult", "analyze_stack"],
    "output": ["save_results", "write_results"],
})
