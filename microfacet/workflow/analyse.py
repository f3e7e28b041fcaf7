"""One stack end to end: claim the results folder, analyse, write the results and the report
into it in one atomic step (``microfacet analyze`` and each batch worker)."""

from __future__ import annotations

from ..analysis.options import AnalysisOptions
from ..analysis.output import results_size_bytes, save_results
from ..analysis.pipeline import analyze_stack, check_analysis_memory
from ..io.outdir import OutputFolder, check_output
from ..io.stack import read_stack
from ..report.writer import write_report

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
    return read_stack(stack, limits=limits, pixel_size_um=pixel_size_um, z_step_um=z_step_um)


def analyse_to_folder(stack, out, *, options=None, overwrite=False, report=True, limits=None,
                      progress=None, pixel_size_um=None, z_step_um=None):
    """One stack end to end: claim ``out``, analyse, write the results and the report into it
    in one atomic step (``microfacet analyze`` and each batch worker).

    Parameters
    ----------
    stack : path-like or Stack
    out : path-like
        The results folder (the rules of :mod:`microfacet.io.outdir`).
    options : AnalysisOptions, optional
    overwrite : bool
    report : bool
        Also write ``report.pdf`` and its page PNGs.
    limits : Limits, optional
        Image-size limits for reading the stack.
    progress : callable, optional
        ``progress(stage_name)`` per analysis stage, then ``"write"`` and ``"report"``.
    pixel_size_um, z_step_um : float, optional
        For a plain folder of images without stack.json (see :func:`open_stack`).

    Returns
    -------
    AnalysisResult
    """
    options = options or AnalysisOptions()
    options.validate()
    check_output(out, kind="results", inputs=[getattr(stack, "path", stack)],
                 overwrite=overwrite)
    st = (open_stack(stack, limits=limits, pixel_size_um=pixel_size_um, z_step_um=z_step_um)
          if not hasattr(stack, "path") else stack)
    check_analysis_memory(st)
    step = progress or (lambda name: None)
    with OutputFolder(out, kind="results", inputs=[st.path], overwrite=overwrite,
                      expected_bytes=results_size_bytes(st.shape, report=report)) as claim:
        result = analyze_stack(st, options, progress=progress)
        step("write")
        with claim.writing() as tmp:
            save_results(result, tmp)
            if report:
                step("report")
                write_report(tmp, png_dir=tmp)
    return result
