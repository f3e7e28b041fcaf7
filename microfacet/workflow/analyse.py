"""One stack end to end: claim the results folder, analyse, write the results and the report
into it in one atomic step (``microfacet analyze`` and each batch worker)."""

from __future__ import annotations

import threading

from ..analysis.options import AnalysisOptions
from ..analysis.output import results_size_bytes, save_results
from ..analysis.pipeline import check_stack_for_analysis, run_stages
from ..analysis.stages import Stage
from ..core.threads import return_free_memory
from ..io.outdir import OutputFolder, check_output
from ..io.stack import Stack, StackSource
from ..report.writer import preload, write_report

__all__ = ["analyse_to_folder", "open_stack"]


def open_stack(stack, *, limits=None, pixel_size_um=None, z_step_um=None):
    """The validated :class:`~microfacet.io.stack.Stack` of a stack folder, or of a plain
    folder of images with ``pixel_size_um`` and ``z_step_um`` (natural file order, nothing
    written).

    Examples
    --------
    >>> import numpy as np, tempfile, pathlib
    >>> from microfacet.io.images import write_image
    >>> d = pathlib.Path(tempfile.mkdtemp())
    >>> for i in (1, 2, 10):
    ...     write_image(d / f"img_{i}.png", np.full((4, 5), 20 * i, np.uint8))
    >>> st = open_stack(d, pixel_size_um=0.5, z_step_um=2.0)
    >>> st.n_slices, [float(z) for z in st.z_um]
    (3, [0.0, 2.0, 4.0])
    """
    return StackSource(stack, pixel_size_um, z_step_um, limits).open()


def _path_of(stack):
    return stack.path if isinstance(stack, (Stack, StackSource)) else stack


def analyse_to_folder(stack, out, *, options: AnalysisOptions | None = None, overwrite=False,
                      report=True, progress=None):
    """One stack end to end: claim ``out``, analyse, write the results and the report into it
    in one atomic step (``microfacet analyze`` and each batch worker).

    The output folder is checked before the stack is read, and the stack (its headers, the
    memory its analysis needs) before any work.

    Parameters
    ----------
    stack : path-like, StackSource or Stack
    out : path-like
        The results folder (the rules of :mod:`microfacet.io.outdir`).
    options : AnalysisOptions, optional
    overwrite : bool
        Replace an earlier results folder.
    report : bool
        Also write ``report.pdf`` and its page PNGs.
    progress : callable, optional
        ``progress(stage)`` (a :class:`~microfacet.analysis.stages.Stage`) per stage, the
        analysis' and then ``Stage.WRITE`` and ``Stage.REPORT``.

    Returns
    -------
    AnalysisResult
    """
    options = AnalysisOptions() if options is None else options
    check_output(out, kind="results", inputs=[_path_of(stack)], overwrite=overwrite)
    st = stack if isinstance(stack, Stack) else (
        stack if isinstance(stack, StackSource) else StackSource(stack)).open()
    check_stack_for_analysis(st)
    step = progress or (lambda stage: None)
    with OutputFolder(out, kind="results", inputs=[st.path], overwrite=overwrite,
                      expected_bytes=results_size_bytes(st.shape, report=report)) as claim:
        result = run_stages(st, options, progress=progress)
        step(Stage.WRITE)         # (the stage timer gave back what the last stage freed)
        with claim.writing() as tmp:
            # the report's imports in a thread while the files are written (their compression
            # and writes release the GIL); joined before the report, which may fork
            imports = threading.Thread(target=preload, daemon=True) if report else None
            if imports is not None:
                imports.start()
            try:
                written = save_results(result, tmp)
            finally:
                if imports is not None:
                    imports.join()
            if report:
                step(Stage.REPORT)
                return_free_memory()
                write_report(tmp, png_dir=tmp, maps=written)   # the maps held: no 2nd copy
    return result
