"""The analysis dock widget (npe2 ``widgets`` contribution): ``microfacet analyze`` on the
open stack, in a worker thread, with a progress bar.

:func:`analysis_widget` builds a magicgui container: the stack folder (taken from the stack
layer the stack reader or the sample data opened, or chosen), the results folder (by default
``<stack>-results`` beside the stack), the mode, whether to write the report, and *Analyse*.
The analysis runs :func:`microfacet.workflow.analyse_to_folder` in a napari
``thread_worker``; its ``progress(stage)`` callback feeds the bar — each stage moves it to
the summed weight of the stages before it (:class:`~microfacet.analysis.stages.Stage`), as
the command line's bar does — and the results folder's layers
(:func:`microfacet.napari.reader.results_layers`) are added when it is done. The viewer
stays responsive meanwhile; an error is shown in the widget and napari's notifications.

napari, magicgui and Qt are imported on first use (``core.lazy.load``), so the module
imports without them.
"""

from __future__ import annotations

import queue
import threading
from pathlib import Path
from typing import TYPE_CHECKING

from ..analysis.options import AnalysisOptions
from ..analysis.stages import JOINT_ONLY, Stage
from ..core.lazy import load
from ..workflow.analyse import analyse_to_folder
from .reader import results_layers

if TYPE_CHECKING:
    import napari.viewer

#: napari, magicgui and Qt are loaded when a widget is built (:func:`_gui`), not held as
#: module-level proxies: doctest collection inspects a module's globals, which would import
#: them where they are not installed.
GUI_MODULES = {"widgets": "magicgui.widgets", "napari": "napari",
               "threading": "napari.qt.threading", "layers": "napari.layers",
               "notifications": "napari.utils.notifications"}

__all__ = ["analysis_widget", "default_out", "stage_fraction", "stage_stream"]

#: Progress bar resolution (steps of the bar).
BAR_STEPS = 1000


def stage_fraction(stage, *, mode: str | None = None, report: bool = True) -> float:
    """The share of the analysis done when ``stage`` starts: the summed weight of the stages
    before it over that of all the stages that run (``mode="seed"`` skips the joint mode's
    stages, ``report=False`` the report; ``mode=None`` is the options' default mode).

    >>> stage_fraction(Stage.HEIGHT), stage_fraction(Stage.REPORT, report=False)
    (0.0, 1.0)
    >>> 0 < stage_fraction(Stage.TILT, mode="seed") < 1
    True
    """
    mode = AnalysisOptions().mode if mode is None else mode
    skip = set(JOINT_ONLY if mode == "seed" else ()) | (set() if report else {Stage.REPORT})
    stages = [s for s in Stage if s not in skip]
    if stage not in stages:
        return 1.0
    total = sum(s.weight for s in stages) or 1.0
    return sum(s.weight for s in stages[:stages.index(stage)]) / total


def default_out(stack) -> Path:
    """The default results folder of ``stack``: ``<stack>-results`` beside it.

    >>> default_out("/data/plate-3").as_posix()
    '/data/plate-3-results'
    """
    p = Path(stack)
    return p.with_name(f"{p.name}-results")


def stage_stream(stack, out, *, options=None, overwrite=False, report=True, run=None):
    """Run the analysis in a thread of its own and yield each
    :class:`~microfacet.analysis.stages.Stage` as it starts; return ``out`` (a generator:
    what the napari worker iterates, so that the stages reach the viewer's thread as
    ``yielded`` signals). An error of the analysis is raised here.

    ``run`` replaces :func:`~microfacet.workflow.analyse_to_folder` (tests).

    >>> def fake(stack, out, progress, **kw):
    ...     progress(Stage.HEIGHT); progress(Stage.WRITE)
    >>> gen = stage_stream("s", "o", run=fake)
    >>> [s.key for s in gen]
    ['height_from_focus', 'write']
    """
    run = run or analyse_to_folder
    stages: queue.Queue = queue.Queue()
    done = object()
    failed: list[BaseException] = []

    def target():
        try:
            run(stack, out, options=options, overwrite=overwrite, report=report,
                progress=stages.put)
        except BaseException as exc:  # handed to the worker's thread below
            failed.append(exc)
        finally:
            stages.put(done)

    thread = threading.Thread(target=target, name="microfacet-analyse", daemon=True)
    thread.start()
    while (stage := stages.get()) is not done:
        yield stage
    thread.join()
    if failed:
        raise failed[0]
    return Path(out)


def _gui(name: str):
    return load(GUI_MODULES[name])


def _stack_of(viewer) -> str | None:
    """The stack folder of the selected layer, else of the topmost stack layer."""
    layers = list(viewer.layers.selection) + list(reversed(viewer.layers))
    for layer in layers:
        path = layer.metadata.get("stack_path") if isinstance(layer.metadata, dict) else None
        if path:
            return path
    return None


def _add_results(viewer, out) -> None:
    for data, kwargs, kind in results_layers(out):
        viewer.add_layer(_gui("layers").Layer.create(data, kwargs, kind))


def analysis_widget(viewer: napari.viewer.Viewer | None = None):
    """The dock widget for ``viewer`` (default: napari's current viewer, which is how the
    plugin's dock widget gets it) — a magicgui ``Container``; its widgets ``stack``,
    ``out``, ``mode``, ``report``, ``overwrite``, ``run_button``, ``progress``, ``status``,
    and ``worker`` (the running napari worker, else None)."""
    viewer = viewer if viewer is not None else _gui("napari").current_viewer()
    w = _gui("widgets")
    stack = w.FileEdit(name="stack", mode="d", tooltip="the stack folder (stack.json)")
    out = w.FileEdit(name="out", label="results", mode="d", tooltip="a new or empty folder")
    mode = w.ComboBox(name="mode", choices=["joint", "seed"], value="joint")
    report = w.CheckBox(name="report", text="write report.pdf", value=True)
    overwrite = w.CheckBox(name="overwrite", text="overwrite earlier results", value=False)
    button = w.PushButton(name="run_button", text="Analyse")
    bar = w.ProgressBar(name="progress", min=0, max=BAR_STEPS, value=0)
    status = w.Label(name="status", value="")
    box = w.Container(widgets=[stack, out, mode, report, overwrite, button, bar, status])
    box.worker = None

    def follow_layers(event=None):
        path = _stack_of(viewer)
        if path and (box.worker is None) and str(stack.value) != path:
            stack.value = path
            out.value = default_out(path)

    def start():
        if not str(stack.value) or not (Path(stack.value) / "stack.json").is_file():
            status.value = "choose a stack folder (with stack.json)"
            return
        opts = AnalysisOptions(mode=mode.value)
        target = out.value if str(out.value) not in ("", ".") else default_out(stack.value)
        worker = _gui("threading").create_worker(
            stage_stream, Path(stack.value), Path(target), options=opts,
            overwrite=overwrite.value, report=report.value, _start_thread=False,
            _ignore_errors=True)

        def on_stage(stage):
            bar.value = int(BAR_STEPS * stage_fraction(stage, mode=mode.value,
                                                        report=report.value))
            status.value = stage.label

        def on_done(path):
            bar.value = BAR_STEPS
            status.value = f"wrote {path}"
            _add_results(viewer, path)

        def on_error(exc):
            status.value = f"failed: {exc}"
            _gui("notifications").show_error(f"microfacet: {exc}")

        def on_finished():
            box.worker = None
            button.enabled = True

        worker.yielded.connect(on_stage)
        worker.returned.connect(on_done)
        worker.errored.connect(on_error)
        worker.finished.connect(on_finished)
        box.worker = worker
        button.enabled = False
        bar.value, status.value = 0, "starting"
        worker.start()

    button.changed.connect(start)
    viewer.layers.events.inserted.connect(follow_layers)
    viewer.layers.selection.events.changed.connect(follow_layers)
    follow_layers()
    return box
