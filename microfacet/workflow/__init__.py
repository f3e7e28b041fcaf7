"""Workflows: what a command does, as library functions the command line only parses for and
prints from. Each writes one output folder atomically (:mod:`microfacet.io.outdir`).

==================  ==========================================================
module              workflow
==================  ==========================================================
``analyse``         :func:`analyse_to_folder`: one stack → results folder + report
``batch``           :func:`run_batch`: many stacks, local processes or a Dask cluster,
                    resumable, ``batch_summary.csv``
``batch_summary``   the rows and folder names of ``batch_summary.csv``
``height``          :func:`height_to_folder`: one stack → height-from-focus folder
``simulate``        :func:`simulate_to_folder`: distributions → angular colour maps
``material``        :func:`export_material`: a results folder → one material file
``render``          :func:`render_to_folder`: the material photographed in Mitsuba 3
``executors``       local worker processes and Dask clusters
==================  ==========================================================
"""

from ..core.lazy import attach

__getattr__, __dir__, __all__ = attach(__name__, submodules=(
    "analyse", "batch", "batch_summary", "executors", "height", "material", "render",
    "simulate"),
    submod_attrs={
    "analyse": ["analyse_to_folder", "open_stack"],
    "batch": ["BatchInterrupted", "BatchResult", "run_batch"],
    "height": ["HeightOutput", "height_to_folder"],
    "material": ["ExportOutput", "export_material"],
    "render": ["RenderOptions", "RenderOutput", "render_to_folder"],
    "simulate": ["FilmOptics", "SimulateOptions", "SimulateOutput", "simulate_to_folder"],
})
