"""The analysis: a focus stack in, the thickness distribution and the NDF out (seed §3.3.3).

===================  ===========================================================
module               stage / concern
===================  ===========================================================
``options``          :class:`AnalysisOptions`: one typed tree of the options, a section
                     per stage; :class:`~.options.Scene`
``stages``           :class:`~.stages.Stage`: the stages in order (timer, progress, docs)
``surface``          height map (from focus or an export), normals, tilt
``iso25178``         ISO 25178-2 areal parameters of the height map (Sq, Sa, Sdq, Sdr)
``colour_image``     CIELAB, the colour mask (``mask``), the colour noise
``white_balance``    the camera's gains: from a white reference, or estimated (reported)
``roi``              thickness per region of interest, interference order, exposure
``search``           the one grid minimiser: coarse-to-fine, parabola refinement
``tilt``             per-pixel tilt by colour inversion (both modes)
``segmentation``     facets from colour and height edges (joint mode)
``planes``           a plane per facet from its reliable heights (joint mode)
``facet_thickness``  a thickness per facet from its colour at its tilt (joint mode)
``flat_field``       the microscope's flat field (vignetting) from the facets' brightness
``joint``            the joint mode's stages: facets → tilt per pixel
``order_cut``        the facets' interference orders decided together: a minimum cut
``sampling``         independent samples in a map; the samples a mixture is fitted to
``mixtures``         thickness mixture (deconvolved), components by BIC with honest n
``ndf_fit``          NDF lobes (deconvolved, censored Rayleigh EM)
``distributions``    the distributions stage (both modes)
``self_check``       the NDF's injection-recovery on the stack itself (joint mode)
``consistency``      the summaries against the maps: mixture vs per-pixel map, ROI vs pixels
``identification``   whether the data determine them: structured reasons, warnings
``pipeline``         :func:`analyse_stack`: the stages in order
``output``           :func:`write_results`: the results folder
===================  ===========================================================

The film's model colour is :class:`microfacet.colour.model.FilmColourModel`. Nothing here
imports the forward models or the report.
"""

from ..core.lazy import attach_stub

__getattr__, __dir__, __all__ = attach_stub(__name__, __file__)
