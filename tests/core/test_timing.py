"""Stage timings (microfacet.core.timing): each stage is the time between its start and its
end on one clock, the total the time since the timer was made, progress announced on start."""

from __future__ import annotations

from types import SimpleNamespace as Stage

import pytest

from microfacet.core import timing
from microfacet.core.timing import StageTimer


@pytest.fixture
def clock(monkeypatch):
    """A fake ``time.perf_counter`` the test advances: ``clock.t = ...``."""
    class Clock:
        t = 100.0

    c = Clock()
    monkeypatch.setattr(timing.time, "perf_counter", lambda: c.t)
    return c


def test_a_stage_is_the_time_from_its_start_to_its_end(clock):
    seen = []
    read, fit = Stage(key="read"), Stage(key="fit")
    t = StageTimer(progress=seen.append)
    clock.t = 100.5
    with t.stage(read):               # announced when it starts
        clock.t = 101.75
    clock.t = 102.0                   # between stages: counted in the total only
    with t.stage(fit):
        clock.t = 102.05004
    assert seen == [read, fit]
    assert t.timings == {"read": 1.25, "fit": 0.05}          # rounded to 0.1 ms
    clock.t = 104.0
    assert t.total() == 4.0 and t.timings["total"] == 4.0


def test_between_runs_after_each_stage_outside_its_time(clock):
    """``between`` is called when each stage ends, after its time is taken (the analysis
    gives memory back there); not when a stage raises."""
    calls = []
    t = StageTimer(between=lambda: calls.append(dict(t.timings)) or setattr(clock, "t",
                                                                            clock.t + 5.0))
    with t.stage(Stage(key="read")):
        clock.t = 101.0
    with pytest.raises(RuntimeError):
        with t.stage(Stage(key="fit")):
            raise RuntimeError("boom")
    assert calls == [{"read": 1.0}]
    assert t.timings == {"read": 1.0} and t.total() == 6.0


def test_a_stage_that_raises_records_no_time(clock):
    t = StageTimer()
    with pytest.raises(RuntimeError):
        with t.stage(Stage(key="x")):
            raise RuntimeError("boom")
    assert t.timings == {}


def test_the_real_clock_is_monotonic():
    t = StageTimer()
    with t.stage(Stage(key="a")):
        pass
    with t.stage(Stage(key="b")):
        pass
    assert all(v >= 0 for v in t.timings.values())
    assert t.total() >= t.timings["a"] + t.timings["b"] - 1e-3
