"""Files in and out. One module owns each format.

==================  ==========================================================
module              format / concern
==================  ==========================================================
``stack``           focus stacks (``microfacet-stack/1``): :class:`Stack`
``stack_checks``    validation of ``stack.json`` before any work
``images``          image headers, decoding, writing (PNG, JPEG, TIFF, ``.npy``)
``results``         the results folder (``microfacet-results/1``): :class:`Results`
``angular_map``     angular maps (``microfacet-angular/1``)
``spectrum``        measured spectra (CSV)
``jsonfile``        strict JSON reading
``limits``          sizes and memory checked before they are spent
``outdir``, ``lock``  output folders: never an input, one writer, whole or nothing
==================  ==========================================================
"""

from ..core.lazy import attach

__getattr__, __dir__, __all__ = attach(__name__, submodules=(
    "angular_map", "images", "jsonfile", "limits", "lock", "outdir", "results", "spectrum",
    "stack", "stack_checks"), submod_attrs={
    "stack": ["Stack", "read_stack", "stack_from_images", "write_stack", "write_stack_json"],
    "results": ["Results"],
    "outdir": ["OutputFolder", "atomic_output_dir"],
    "limits": ["Limits"],
})
