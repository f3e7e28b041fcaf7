"""The analysis widget: its progress arithmetic and stage stream without Qt; in a viewer
(``make_napari_viewer``) only with napari installed and a display (``xvfb-run``, or Qt's
offscreen platform)."""

from __future__ import annotations

import os

import pytest

from microfacet.analysis.stages import JOINT_ONLY, Stage
from microfacet.napari import widget


def test_the_bar_moves_by_the_stages_weights_and_ends_full():
    fractions = [widget.stage_fraction(s) for s in Stage]
    assert fractions[0] == 0.0 and fractions == sorted(fractions) and fractions[-1] < 1.0
    seed = [widget.stage_fraction(s, mode="seed", report=False) for s in Stage
            if s not in JOINT_ONLY and s is not Stage.REPORT]
    assert seed == sorted(seed) and seed[-1] < 1.0
    assert widget.stage_fraction(Stage.REPORT, report=False) == 1.0


def test_the_stage_stream_yields_stages_then_returns_or_raises():
    def ok(stack, out, progress, **kw):
        for s in (Stage.HEIGHT, Stage.MIXTURES, Stage.WRITE):
            progress(s)

    gen = widget.stage_stream("stack", "out", run=ok)
    seen = []
    with pytest.raises(StopIteration) as stop:
        while True:
            seen.append(next(gen))
    assert seen == [Stage.HEIGHT, Stage.MIXTURES, Stage.WRITE]
    assert str(stop.value.value) == "out"

    def bad(stack, out, progress, **kw):
        progress(Stage.HEIGHT)
        raise ValueError("no colour")

    with pytest.raises(ValueError, match="no colour"):
        list(widget.stage_stream("stack", "out", run=bad))


def _display() -> bool:
    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")
                or os.environ.get("QT_QPA_PLATFORM") == "offscreen")


@pytest.fixture
def viewer(request):
    pytest.importorskip("napari")
    pytest.importorskip("pytestqt")
    if not _display():
        pytest.skip("no display (run under xvfb-run)")
    return request.getfixturevalue("make_napari_viewer")()


@pytest.mark.slow
def test_the_widget_analyses_the_open_stack_and_adds_the_results(viewer, qtbot, tmp_path):
    from microfacet.napari import sample_data

    viewer.open_sample("microfacet", "nd-fixture")
    box = widget.analysis_widget(viewer)
    assert str(box.stack.value) == str(sample_data.fixture_path().resolve())
    box.out.value = tmp_path / "res"
    box.report.value = False
    seen = []
    box.progress.changed.connect(seen.append)
    from qtpy.QtCore import QTimer

    ticks = []
    timer = QTimer()
    timer.timeout.connect(lambda: ticks.append(1))
    timer.start(20)
    box.run_button.clicked.emit()     # the button's signal, as a click sends it
    assert box.worker is not None and not box.run_button.enabled
    with qtbot.waitSignal(box.worker.finished, timeout=300_000):
        pass
    timer.stop()
    assert len(ticks) > 10            # the event loop ran while the analysis did
    assert box.run_button.enabled and box.worker is None
    names = [layer.name for layer in viewer.layers]
    assert {"height_um", "thickness_nm", "tilt_deg", "facets"} <= set(names)
    assert box.progress.value == widget.BAR_STEPS and len(seen) > 3
    assert viewer.layers["thickness_nm"].metadata["thickness_mixture"]["components"]
    assert (tmp_path / "res" / "summary.json").is_file()
