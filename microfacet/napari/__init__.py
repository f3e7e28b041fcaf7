"""The napari plugin (optional extra ``napari``; manifest ``microfacet/napari.yaml``).

==================  ==========================================================
module              concern
==================  ==========================================================
``reader``          a stack folder → a z-stack layer; a results folder → height,
                    thickness, tilt and facet layers (scale in µm, units and the
                    two mixtures in the layer metadata)
``sample_data``     the bundled ND fixture stack as napari sample data
``widget``          a dock widget: ``analyse_to_folder`` on the open stack in a worker
                    thread, with a progress bar; the results added as layers
==================  ==========================================================

napari, magicgui and Qt are imported on first use (by the widget only); the readers need
neither (``npe2.read`` works without Qt). Nothing else in the package imports this one.
"""

from ..core.lazy import attach_stub

__getattr__, __dir__, __all__ = attach_stub(__name__, __file__)
