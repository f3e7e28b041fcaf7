"""Stage timings (microfacet.core.timing): each stage is the time since the previous lap on
one clock, the total the time since the timer was made, progress announced on start."""

from __future__ import annotations

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


def test_laps_are_the_times_between_consecutive_laps(clock):
    seen = []
    t = StageTimer(progress=seen.append)
    clock.t = 100.5
    t.start("read")                   # announces; the clock keeps running
    clock.t = 101.25
    t.lap("read")                     # 1.25 s since the timer was made
    clock.t = 101.30004
    t.lap("fit")
    clock.t = 104.0
    t.start("report")
    assert seen == ["read", "report"]
    assert t.timings == {"read": 1.25, "fit": 0.05}          # rounded to 0.1 ms
    assert t.total() == 4.0 and t.timings["total"] == 4.0
    clock.t = 105.0
    t.lap("report")                   # since the last lap, not since start("report")
    assert t.timings["report"] == pytest.approx(3.7, abs=1e-9)
    assert t.total() == 5.0


def test_a_stage_timed_twice_keeps_its_last_lap(clock):
    t = StageTimer()                  # no progress callback: start is a no-op
    t.start("x")
    clock.t = 102.0
    t.lap("x")
    clock.t = 102.5
    t.lap("x")
    assert t.timings == {"x": 0.5}


def test_the_real_clock_is_monotonic():
    t = StageTimer()
    t.lap("a")
    t.lap("b")
    assert all(v >= 0 for v in t.timings.values())
    assert t.total() >= t.timings["a"] + t.timings["b"] - 1e-3
