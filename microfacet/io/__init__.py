"""Files in and out. One module owns each format.

==================  ==========================================================
module              format / concern
==================  ==========================================================
``stack``           focus stacks (``microfacet-stack/1``): :class:`Stack`
``stack_checks``    validation of ``stack.json`` before any work; images of a plain folder
``stack_schema``    the keys of ``stack.json`` as data: types, ranges, defaults
``stack_write``     writing ``stack.json`` (validated first) and stacks of images
``images``          image headers, decoding, writing (PNG with pHYs, JPEG, TIFF, ``.npy``)
``tiff_meta``       physical size in TIFF metadata (OME, ImageJ, resolution tags)
``vendor``          vendors' z-stack files (Zeiss ``.czi``, Nikon ``.nd2``, Leica ``.lif``;
                    extra ``microscopes``)
``instruments``     instrument height maps (``.x3p``, float TIFF, ``.npy``; through
                    SurfaceTopography ``.al3d``, ``.plu``, ``.sur``, ``.vk4``, ``.datx``, ...)
``x3p``             ISO 25178-72 ``.x3p`` height maps, read and written
``results``         the results folder (``microfacet-results/1``): :class:`Results`
``summary``         its ``summary.json`` as a typed, versioned :class:`Summary`
``height_folder``   the height folder of ``microfacet height`` (``microfacet-height/1``)
``angular_map``     angular maps (``microfacet-angular/1``)
``material_file``   the exported BRDF (``microfacet-brdf/1``): film average table + lobes
``spectrum``        measured spectra (spectrometer text exports)
``jsonfile``        strict JSON reading
``limits``          sizes and memory checked before they are spent
``outdir``, ``lock``  output folders: never an input, one writer, whole or nothing
==================  ==========================================================
"""

from ..core.lazy import attach_stub

__getattr__, __dir__, __all__ = attach_stub(__name__, __file__)
