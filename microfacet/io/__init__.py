"""Files in and out. One module owns each format.

==================  ==========================================================
module              format / concern
==================  ==========================================================
``stack``           focus stacks (``microfacet-stack/1``): :class:`Stack`
``stack_checks``    validation of ``stack.json`` before any work; images of a plain folder
``stack_write``     writing ``stack.json`` (validated first) and stacks of images
``images``          image headers, decoding, writing (PNG with pHYs, JPEG, TIFF, ``.npy``)
``tiff_meta``       physical size in TIFF metadata (OME, ImageJ, resolution tags)
``instruments``     instrument height maps (``.x3p``, float TIFF, ``.npy``; through
                    SurfaceTopography ``.al3d``, ``.plu``, ``.sur``, ``.vk4``, ``.datx``, ...)
``x3p``             ISO 25178-72 ``.x3p`` height maps, read and written
``results``         the results folder (``microfacet-results/1``): :class:`Results`
``angular_map``     angular maps (``microfacet-angular/1``)
``spectrum``        measured spectra (spectrometer text exports)
``jsonfile``        strict JSON reading
``limits``          sizes and memory checked before they are spent
``outdir``, ``lock``  output folders: never an input, one writer, whole or nothing
==================  ==========================================================
"""

from ..core.lazy import attach

__getattr__, __dir__, __all__ = attach(__name__, submodules=(
    "angular_map", "images", "instruments", "jsonfile", "limits", "lock", "outdir", "results",
    "spectrum", "stack", "stack_checks", "stack_write", "tiff_meta", "x3p"), submod_attrs={
    "stack": ["Stack", "find_images", "read_stack", "stack_from_images", "write_stack",
              "write_stack_json"],
    "instruments": ["HeightMap", "read_height_map"],
    "x3p": ["read_x3p", "write_x3p"],
    "spectrum": ["Spectrum", "read_spectrum"],
    "results": ["Results"],
    "outdir": ["OutputFolder", "atomic_output_dir"],
    "limits": ["Limits"],
})
