"""The progress bar (microfacet.cli.progress): the fraction done follows the stages' measured
weights (the :class:`~microfacet.analysis.stages.Stage` enum for ``microfacet analyze``),
skipped stages count for nothing, and the bar is drawn only on a terminal."""

import io
from types import SimpleNamespace as S

import pytest

from microfacet.analysis.options import AnalysisOptions
from microfacet.analysis.stages import JOINT_ONLY, Stage
from microfacet.cli.progress import Progress, StageProgress
from microfacet.workflow.analyse import analyse_to_folder


class _Tty(io.StringIO):
    def isatty(self):
        return True


def _stages(*weights):
    return [S(label=name, weight=w) for name, w in zip("abcdefgh", weights)]


def test_fraction_done_follows_the_stage_weights():
    stages = _stages(1.0, 3.0, 6.0)
    bar = StageProgress("x", stages, stream=_Tty())
    seen = []
    for s in stages:
        bar.stage(s)
        seen.append(bar.fraction)
    assert seen == pytest.approx([0.0, 0.1, 0.4])      # not the equal steps 0, 1/3, 2/3
    bar.stage(S(label="other", weight=5.0))            # not one of its stages: no move
    assert bar.fraction == pytest.approx(0.4)
    bar.finish()
    assert bar.fraction == 1.0


def _expected(stage, skip=()):
    """Summed weight of the stages before ``stage`` over all, skipped ones left out (computed
    here from the enum's weights)."""
    run = [s for s in Stage if s not in skip]
    return sum(s.weight for s in run[:run.index(stage)]) / sum(s.weight for s in run)


def test_analyze_fraction_follows_the_stage_weights():
    """Every stage of ``microfacet analyze`` starts at the summed weight of those before it,
    whatever their count says: the report, the costliest stage, starts at 80 % of the
    work, not at 10/11 of the stages."""
    assert all(s.weight > 0 for s in Stage) and len({s.key for s in Stage}) == len(Stage)
    bar = StageProgress("analyze", list(Stage), quiet=True)
    for s in Stage:
        bar.stage(s)
        assert bar.fraction == pytest.approx(_expected(s)), s
    bar.stage(Stage.REPORT)
    assert bar.fraction != pytest.approx(list(Stage).index(Stage.REPORT) / len(Stage), abs=0.02)


def test_analyze_without_report_reaches_about_one_at_write():
    """With ``--no-report`` the report counts for nothing: writing, the last stage, starts
    near the end of the bar, and announcing the report does not move it."""
    bar = StageProgress("analyze", list(Stage), skip=(Stage.REPORT,), quiet=True)
    bar.stage(Stage.WRITE)
    total = sum(s.weight for s in Stage if s is not Stage.REPORT)
    assert bar.fraction == pytest.approx(1.0 - Stage.WRITE.weight / total)
    assert bar.fraction > 0.95
    bar.stage(Stage.REPORT)                                # skipped: the bar does not move
    assert bar.fraction == pytest.approx(1.0 - Stage.WRITE.weight / total)
    bar.finish()
    assert bar.fraction == 1.0


def test_the_seed_mode_skips_the_joint_stages():
    skip = JOINT_ONLY + (Stage.REPORT,)
    bar = StageProgress("analyze", list(Stage), skip=skip, quiet=True)
    for s in JOINT_ONLY:
        bar.stage(s)
        assert bar.fraction == 0.0                         # never announced: no move
    bar.stage(Stage.TILT)
    assert bar.fraction == pytest.approx(_expected(Stage.TILT, skip))
    # the joint stages are not counted as done before the tilt
    assert bar.fraction < _expected(Stage.TILT, (Stage.REPORT,))


@pytest.mark.slow
def test_the_workflow_announces_the_stages_the_bar_expects(batch_drawer, tmp_path):
    """``analyse_to_folder`` announces every stage that runs, in the enum's order: the bar,
    told which are skipped, moves forward at each and never past 1."""
    skip = JOINT_ONLY + (Stage.REPORT,)
    bar = StageProgress("analyze", list(Stage), skip=skip, quiet=True)
    seen, fractions = [], []

    def step(stage):
        seen.append(stage)
        bar.stage(stage)
        fractions.append(bar.fraction)

    analyse_to_folder(batch_drawer / "a", tmp_path / "res", options=AnalysisOptions(
        mode="seed"), report=False, progress=step)
    assert seen == [s for s in Stage if s not in skip]
    assert fractions[0] == 0.0 and all(b > a for a, b in zip(fractions, fractions[1:]))
    assert fractions[-1] == pytest.approx(_expected(Stage.WRITE, skip)) and fractions[-1] < 1
    assert (tmp_path / "res" / "summary.json").is_file()


def test_bar_and_eta_on_a_terminal_only():
    tty = _Tty()
    a, b = _stages(1.0, 1.0)
    with StageProgress("analyze", [a, b], stream=tty) as bar:
        bar.stage(a)
        assert "eta     ?" in tty.getvalue()                # nothing measured: no estimate
        bar.stage(b)
        assert "b (2/2)" in tty.getvalue() and "#" * 15 in tty.getvalue()
    assert tty.getvalue().endswith("\n")
    piped = io.StringIO()
    with Progress("slices", total=4, stream=piped) as bar:
        bar.update(2)
    assert piped.getvalue() == "" and bar.fraction == 0.5
