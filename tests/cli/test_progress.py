"""The progress bar (microfacet.cli.progress): the fraction done follows the measured stage
weights, and the bar is drawn only on a terminal."""

import io

import pytest

from microfacet.cli.progress import ANALYZE_STAGE_WEIGHTS, Progress, StageProgress


class _Tty(io.StringIO):
    def isatty(self):
        return True


def test_fraction_done_follows_the_stage_weights():
    weights = [("a", 1.0), ("b", 3.0), ("c", 6.0)]
    bar = StageProgress("x", weights, stream=_Tty())
    seen = []
    for name in ("a", "b", "c"):
        bar.stage(name)
        seen.append(bar.fraction)
    assert seen == pytest.approx([0.0, 0.1, 0.4])      # not the equal steps 0, 1/3, 2/3
    bar.finish()
    assert bar.fraction == 1.0


def test_analyze_weights_put_the_report_at_about_half_the_time():
    """The report of the bundled fixture takes about as long as the analysis; with
    --no-report it counts for nothing."""
    names = [n for n, _ in ANALYZE_STAGE_WEIGHTS]
    bar = StageProgress("analyze", ANALYZE_STAGE_WEIGHTS, quiet=True)
    bar.stage("report")
    assert 0.4 < bar.fraction < 0.6
    assert names.index("report") / len(names) > 0.8        # what equal steps would say
    bar = StageProgress("analyze", ANALYZE_STAGE_WEIGHTS, skip=("report",), quiet=True)
    bar.stage("write")
    assert bar.fraction > 0.99
    bar.stage("report")                                    # skipped: the bar does not move
    assert bar.fraction > 0.99


def test_the_stage_names_are_those_the_pipeline_announces():
    import inspect

    from microfacet.analysis import pipeline
    from microfacet.workflow import batch as runner

    source = inspect.getsource(pipeline.analyze_stack) + inspect.getsource(
        runner.analyse_to_folder)
    for name, _ in ANALYZE_STAGE_WEIGHTS:
        assert f'"{name}"' in source, name


def test_bar_and_eta_on_a_terminal_only():
    tty = _Tty()
    with StageProgress("analyze", [("a", 1.0), ("b", 1.0)], stream=tty) as bar:
        bar.stage("a")
        assert "eta     ?" in tty.getvalue()                # nothing measured: no estimate
        bar.stage("b")
        assert "b (2/2)" in tty.getvalue() and "#" * 15 in tty.getvalue()
    assert tty.getvalue().endswith("\n")
    piped = io.StringIO()
    with Progress("slices", total=4, stream=piped) as bar:
        bar.update(2)
    assert piped.getvalue() == "" and bar.fraction == 0.5
