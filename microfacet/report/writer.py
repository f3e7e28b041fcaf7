"""The analysis report: a multi-page PDF (and PNGs) drawn from a results folder.

:func:`write_report` opens a results folder (``docs/results-format.md``) through
:class:`microfacet.io.results.Results` and draws five A4-landscape pages (:data:`PAGES`),
each with a header (stack name, analysis mode, optics, date, microfacet version) and a footer
(results folder, page number):

1. **overview** (:mod:`~microfacet.report.page_overview`) — all-in-focus image, height map,
   colour mask, inputs and masking;
2. **maps** (:mod:`~microfacet.report.page_maps`) — thickness, thickness component, ΔE00,
   tilt from colour, tilt from the height map, tilt 1σ;
3. **distributions** (:mod:`~microfacet.report.page_distributions`) — thickness and tilt
   histograms with the fitted mixtures (seed Figs. 18a, 19), D(θ), ΔE00;
4. **parameters** (:mod:`~microfacet.report.page_parameters`) — fitted components, analysis
   settings and the run;
5. **angular colour** (:mod:`~microfacet.report.page_angular`) — the colour predicted over
   light × view angles by the forward models.

Only ``summary.json`` is required. A missing map or CSV skips its panel (the histograms fall
back to the maps, then to the fitted mixture alone) and is listed on page 4; a mixture with
an empty component list (no fit) is shown as "no fit". Each map is block-averaged to the
pixels its panel shows at :data:`~microfacet.report.layout.PDF_DPI` (at most
:data:`~microfacet.report.layout.MAX_MAP_PX` a side) before drawing, so the report's time
and the PDF's size hardly grow with the image; what more than one page uses is computed
once (:class:`~microfacet.report.context.Context`). The drawing helpers the pages share are
in :mod:`~microfacet.report.layout`, the array preparation in
:mod:`~microfacet.report.arrays`. On Linux, from a process without other threads (``microfacet
analyze``), the PNG pages are drawn by a forked child while this process draws the PDF: the
two renderings of each page on two cores (docs/benchmarks.md). What both renderings draw and
costs time to compute (page 5's predicted maps, a page module's ``prepare``) is computed once
before the fork, and the objects alive before the report are frozen out of the garbage
collector's scans while it draws.

Importing this module does not import matplotlib; :func:`write_report` does.
"""

from __future__ import annotations

import datetime as _dt
import gc
import os
import pickle
import re
import select
import signal
import sys
import threading
import time
import warnings
from concurrent.futures import ThreadPoolExecutor
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from .. import __version__
from ..core.defaults import DEFAULT_ILLUMINANT
from ..core.lazy import load
from ..core.threads import return_free_memory
from . import page_angular, page_distributions, page_maps, page_overview, page_parameters
from .context import Context
from .layout import PAGE_IN, PDF_DPI, PNG_DPI, RC, Page, shorten

mpl = load("matplotlib")
figure = load("matplotlib.figure")
backend_agg = load("matplotlib.backends.backend_agg")
backend_pdf = load("matplotlib.backends.backend_pdf")
mlines = load("matplotlib.lines")
pil_image = load("PIL.Image")

__all__ = ["PAGES", "preload", "write_report"]

_MODULES = (page_overview, page_maps, page_distributions, page_parameters, page_angular)
#: How long the PNG child may take after the PDF is done: this many seconds, or this many
#: times the PDF's drawing time if longer; a child that takes longer is killed.
CHILD_TIMEOUT_S, CHILD_TIMEOUT_PER_PDF = 60.0, 10.0
#: Page names, in order (also the PNG file names ``report_<n>_<name>.png``).
PAGES = tuple(m.NAME for m in _MODULES)


def write_report(results_dir, *, out_pdf=None, png_dir=None, maps=None) -> Path:
    """Write the multi-page PDF report (and optional PNGs) of an analysis results folder.

    Parameters
    ----------
    results_dir : path-like
        A results folder (``docs/results-format.md``). ``summary.json`` is required; every
        other file is optional and a missing one skips its panel: ``all_in_focus.png``,
        ``height_um.npy``, ``thickness_nm.npy``, ``tilt_deg.npy``, ``tilt_sigma_deg.npy``,
        ``thickness_pdf.csv``, ``ndf_pdf.csv``, ``thickness_roi.csv``, ``mask.npy`` (bool,
        True = masked), ``delta_e.npy`` (ΔE00 per pixel) and ``tilt_height_deg.npy`` (tilt
        from the height map).
    out_pdf : path-like, optional, keyword-only
        Where to write the PDF; default ``results_dir / "report.pdf"``. It is written under
        a temporary name and renamed when complete.
    png_dir : path-like, optional, keyword-only
        If given, each page is also written there as ``report_<n>_<name>.png``
        (names in :data:`PAGES`; 1286 × 910 pixels); the folder is created if needed.
    maps : dict of str to ndarray, optional, keyword-only
        Maps of ``results_dir`` the caller holds in memory as their files hold them (what
        :func:`~microfacet.analysis.output.save_results` returns), drawn instead of reading
        their files again: the same report without a second copy of them (never changed).

    Returns
    -------
    pathlib.Path
        The PDF written.

    Raises
    ------
    InputError
        ``results_dir`` is not a folder or has no ``summary.json``, or a file that is present
        cannot be read or is malformed (the message names it), e.g. invalid JSON, a mixture
        ``from_json`` rejects, a CSV without its required columns. Nothing is written.

    Notes
    -----
    Maps carry a scale bar in µm when ``summary["inputs"]["pixel_size_um"]`` is given, else
    in pixels.
    Maps are block-averaged (NaN-aware; categories: nearest) to the pixels their panel shows
    at :data:`~microfacet.report.layout.PDF_DPI`, at most
    :data:`~microfacet.report.layout.MAX_MAP_PX` a side; colour limits are the 1st–99th
    percentiles of the full-resolution map (arrows on the colour bar mark values beyond
    them). When the PDF is inside the results folder, the report's wall time is
    recorded in its ``summary.json`` as ``timings_s.report`` (s).

    Examples
    --------
    >>> write_report("results/sample1")                                # doctest: +SKIP
    PosixPath('results/sample1/report.pdf')
    """
    t0 = time.perf_counter()
    ctx = Context.open(results_dir, maps=maps)
    ctx.check_tables()  # a malformed CSV fails here, before anything is drawn
    results_dir = ctx.res.path
    out_pdf = Path(out_pdf) if out_pdf is not None else results_dir / "report.pdf"
    shown = _display_path(results_dir)
    written = _dt.datetime.now().strftime("%Y-%m-%d %H:%M")
    tmp = out_pdf.with_name(f".{out_pdf.name}.partial-{os.getpid()}")
    out_pdf.parent.mkdir(parents=True, exist_ok=True)
    if png_dir is not None:
        png_dir = Path(png_dir)
        png_dir.mkdir(parents=True, exist_ok=True)
    # Figure objects render through their own canvas: no global backend switch, so a
    # Jupyter session calling this keeps its inline backend.
    metadata = {"Title": f"microfacet report — {shown.name}",
                "Creator": f"microfacet {__version__}"}
    pages = _Pages(ctx, shown, written)
    child = None
    try:
        with mpl.rc_context(RC), warnings.catch_warnings(), _older_objects_frozen():
            warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN slices and the like
            for m in _MODULES:      # what both renderings draw, computed once (before a fork)
                if hasattr(m, "prepare"):
                    m.prepare(ctx)
            return_free_memory()    # the preparation's temporaries, before the child copies
            if png_dir is not None and _can_fork():
                child = _PngChild.start(pages, png_dir)      # None if it cannot start
            t_pdf = time.perf_counter()
            with backend_pdf.PdfPages(tmp, metadata=metadata) as pdf:
                # without a child, each page drawn is also rendered as a PNG here
                pages.write(pdf, png_dir if child is None else None)
            if child is not None and not child.wait(timeout_s=max(
                    CHILD_TIMEOUT_S, CHILD_TIMEOUT_PER_PDF * (time.perf_counter() - t_pdf))):
                pages.write(png_dir=png_dir)     # the child hung and was killed: draw here
        os.replace(tmp, out_pdf)
    except BaseException:
        if child is not None:
            child.stop()
        tmp.unlink(missing_ok=True)
        raise
    if out_pdf.resolve().is_relative_to(results_dir.resolve()):
        ctx.res.record("timings_s", "report", round(time.perf_counter() - t0, 4))
    return out_pdf


@contextmanager
def _older_objects_frozen():
    """The objects alive before the report (the caller's, the libraries') left out of the
    garbage collector's scans while it draws (``gc.freeze``): the full collections took ~0.1
    s of a report in an analysis process (0.017 s with them frozen; docs/benchmarks.md), and
    a forked child's collections no longer write to, and so copy, those objects' pages
    (Python's advice for a fork without exec). Garbage alive at the start would stay until
    the end: a collection first found none after an analysis (0 objects freed, 0.06 s) and
    is not made. Nothing is done when the caller has frozen objects itself."""
    if gc.get_freeze_count():
        yield
        return
    gc.freeze()
    try:
        yield
    finally:
        gc.unfreeze()


class _Pages:
    """The report's pages of one results folder, drawn one at a time."""

    def __init__(self, ctx, shown, written):
        self.ctx, self.shown, self.written = ctx, shown, written

    def draw(self, i) -> Page:
        """Page ``i`` (1-based): header, footer and the page module's content."""
        module = _MODULES[i - 1]
        pg = Page(figure.Figure(figsize=PAGE_IN))
        _header(pg, self.ctx, self.shown, module.TITLE, i, self.written)
        _footer(pg, self.shown, i)
        module.draw(pg, self.ctx)
        if not any(m.READS_MAPS for m in _MODULES[i:]):
            self.ctx.res.release()       # the last pages draw from summary.json alone
        return pg

    def write(self, pdf=None, png_dir=None) -> None:
        """Every page into ``pdf`` (a ``PdfPages``) and/or as ``png_dir/report_<n>_<name>.png``;
        each PNG is compressed by a worker thread (Pillow releases the GIL) while the next page
        is drawn."""
        with ThreadPoolExecutor(max_workers=1) as png_writer:
            pngs = []
            for i, m in enumerate(_MODULES, start=1):
                fig = self.draw(i).fig
                if pdf is not None:
                    pdf.savefig(fig, dpi=PDF_DPI)
                if png_dir is not None:
                    pngs.append(png_writer.submit(_write_png, _page_rgb(fig),
                                                  png_dir / f"report_{i}_{m.NAME}.png"))
                # the page's figure (a reference cycle) and its renderers' buffers go before
                # the next page is drawn: the report's memory that of one page, not of five
                fig = None
                gc.collect()
                return_free_memory()
            for done in pngs:
                done.result()  # raises what writing raised


def _can_fork() -> bool:
    """Whether the PNG pages may be drawn by a forked child: on Linux (macOS' system
    frameworks are not fork-safe), from a process with no other Python thread (a thread
    holding a lock at the fork would leave it held in the child; Dask and loky workers
    have such threads and draw the pages themselves). The native thread pools of OpenBLAS
    and OpenCV are idle at the fork (the child uses neither; OpenBLAS resets its pool in
    the child); a child that hangs nevertheless is killed after a timeout and the pages are
    drawn here (:meth:`_PngChild.wait`)."""
    return (hasattr(os, "fork") and sys.platform.startswith("linux")
            and threading.active_count() == 1)


class _PngChild:
    """A forked process drawing the PNG pages while this one draws the PDF (the two are
    separate renderings of each page, on two cores; docs/benchmarks.md). It exits with 0,
    or 1 after writing the exception it met (pickled) to a pipe; :meth:`wait` raises that
    exception here, as drawing here would have raised it."""

    def __init__(self, pid, err_fd):
        self.pid, self.err_fd = pid, err_fd

    @classmethod
    def start(cls, pages: _Pages, png_dir) -> _PngChild | None:
        """Fork the child; None if the pipe or the fork fails (the pages are then drawn
        here: a report never fails for want of a second process)."""
        try:
            r, w = os.pipe()
        except OSError:
            return None
        try:
            with warnings.catch_warnings():
                # Python >= 3.12 warns of any thread at a fork, the idle native pools too
                warnings.simplefilter("ignore", DeprecationWarning)
                pid = os.fork()
        except OSError:
            os.close(r)
            os.close(w)
            return None
        if pid == 0:                               # the child: never returns
            code = 1
            try:
                os.close(r)
                pages.write(png_dir=png_dir)
                code = 0
            except BaseException as exc:           # noqa: BLE001 - reported to the parent
                os.write(w, _pickled(exc))
            finally:
                os._exit(code)
        os.close(w)
        return cls(pid, r)

    def wait(self, *, timeout_s: float) -> bool:
        """Wait for the child: True when it drew the pages, False when it did not finish
        within ``timeout_s`` (it is then killed); raise the exception it reported if it
        failed. The child is reaped whatever happens here (Ctrl-C included)."""
        report = bytearray()
        try:
            deadline = time.monotonic() + timeout_s
            while (left := deadline - time.monotonic()) > 0:
                if select.select([self.err_fd], [], [], left)[0]:
                    chunk = os.read(self.err_fd, 65536)
                    if not chunk:              # the child closed the pipe: it exits
                        break
                    report += chunk
            else:
                return False
            _, status = os.waitpid(self.pid, 0)
            self.pid = None
        finally:
            self.stop()
        if os.waitstatus_to_exitcode(status) != 0:
            raise _unpickled(bytes(report))
        return True

    def stop(self) -> None:
        """Kill the child if it is still there, reap it and close the pipe (idempotent)."""
        if self.pid is not None:
            try:
                os.kill(self.pid, signal.SIGKILL)
                os.waitpid(self.pid, 0)
            except (ProcessLookupError, ChildProcessError):
                pass
            self.pid = None
        if self.err_fd is not None:
            os.close(self.err_fd)
            self.err_fd = None


def _pickled(exc) -> bytes:
    """``exc`` for the parent: pickled, or as a RuntimeError with its text if it does not
    pickle."""
    try:
        return pickle.dumps(exc)
    except Exception:                              # noqa: BLE001 - any pickling failure
        return pickle.dumps(RuntimeError(f"{type(exc).__name__}: {exc}"))


def _unpickled(data: bytes) -> BaseException:
    """The child's exception (from our own child: trusted bytes)."""
    try:
        return pickle.loads(data)
    except Exception:                              # noqa: BLE001 - a truncated report
        return RuntimeError("the report's PNG pages: the process drawing them was killed")


def preload() -> None:
    """Import what :func:`write_report` draws with (matplotlib's figure and backends, Pillow)
    and load matplotlib's font list: ~0.3 s (``python -X importtime``) that ``microfacet
    analyze`` spends in a thread while it writes the results files, whose compression and
    writes release the GIL. An error is left to :func:`write_report`, which meets it again."""
    try:
        figure.Figure, backend_pdf.PdfPages, backend_agg.FigureCanvasAgg, pil_image.open
        load("matplotlib.font_manager").fontManager
    except Exception:                              # noqa: BLE001 - raised by write_report
        pass


def _page_rgb(fig):
    """The page drawn by Agg at :data:`~microfacet.report.layout.PNG_DPI`, as an H×W×3
    uint8 array (the page is opaque: without the alpha channel its PNG is compressed a
    third faster and is smaller)."""
    canvas = backend_agg.FigureCanvasAgg(fig)
    fig.set_dpi(PNG_DPI)
    canvas.draw()
    return np.ascontiguousarray(np.asarray(canvas.buffer_rgba())[..., :3])


def _write_png(rgb, path):
    """Write the page pixels ``rgb`` as an 8-bit RGB PNG."""
    pil_image.fromarray(rgb).save(path, format="png", compress_level=3,
                                  dpi=(PNG_DPI, PNG_DPI))


def _header(pg, ctx, shown, title, i, written):
    """Title (stack name, page title), a sub-title (mode, optics, dates, versions), a rule."""
    res = ctx.res
    name = Path(str(ctx.stack)).name if ctx.stack else shown.name
    y1 = pg.H - 0.36
    pg.text(pg.left, y1, f"microfacet report — {shorten(name, 40)}", fontsize=14,
            fontweight="bold", va="baseline")
    pg.text(pg.right, y1, f"{i}. {title}", fontsize=12, fontweight="bold",
            ha="right", va="baseline", color="0.2")
    mode = res.get("mode") or res.get("parameters", "mode")
    bits = []
    if mode:
        bits.append(f"{mode} mode")
    film, sub = ctx.optics("film"), ctx.optics("substrate")
    if film and sub:
        bits.append(f"{film} on {sub}, {ctx.optics('illuminant') or DEFAULT_ILLUMINANT}")
    when = res.get("created") or res.get("date")
    analysed = str(when) if when else _dt.datetime.fromtimestamp(
        res.summary_mtime).strftime("%Y-%m-%d %H:%M")
    bits.append(f"analysed {analysed}")
    av = res.get("versions", "microfacet") or res.get("version")
    if av:
        bits.append(f"microfacet {av}" + (f" (report: {__version__})"
                                          if str(av) != __version__ else ""))
    else:
        bits.append(f"report: microfacet {__version__} (analysis version not recorded)")
    sub_line = "   ·   ".join(bits)
    pg.text(pg.left, pg.H - 0.60, shorten(sub_line, 150), fontsize=8.5, color="0.3",
            va="baseline")
    pg.text(pg.right, pg.H - 0.60, f"report written {written}", fontsize=8.5, color="0.3",
            ha="right", va="baseline")
    pg.fig.add_artist(mlines.Line2D([pg.left / pg.W, pg.right / pg.W],
                                    [(pg.H - 0.71) / pg.H] * 2, color="0.75", lw=0.6))


def _footer(pg, shown, i):
    """The results folder, the no-value note and the page number."""
    pg.text(pg.left, 0.17, shorten(str(shown), 80), fontsize=7, color="0.45", va="center")
    pg.text(0.5 * pg.W, 0.17, "grey pixels on maps: masked or no value (NaN)", fontsize=7,
            color="0.45", ha="center", va="center")
    pg.text(pg.right, 0.17, f"page {i} of {len(PAGES)}", fontsize=7, color="0.45",
            ha="right", va="center")


def _display_path(results_dir: Path) -> Path:
    """The folder's final name: ``.OUT.partial-xyz`` (being written) is shown as ``OUT``;
    relative to the working directory if it is inside it."""
    p = results_dir.resolve()
    m = re.fullmatch(r"\.(.+)\.partial-[^/]*", p.name)
    p = p.with_name(m.group(1)) if m else p
    try:
        return p.relative_to(Path.cwd().resolve())
    except (ValueError, OSError):
        return p
