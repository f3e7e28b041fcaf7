"""Fixtures of the analysis tests: analyses of the bundled synthetic stack, made once."""

from __future__ import annotations

from pathlib import Path

import pytest

from microfacet.analysis import AnalysisOptions, analyse_stack

ND_FIXTURE = Path(__file__).resolve().parents[2] / "fixtures" / "stacks" / "nd-fixture"


@pytest.fixture(scope="session")
def nd_analysis():
    """``nd_analysis(mode)``: :func:`analyse_stack` of fixtures/stacks/nd-fixture with the
    default options in ``mode`` ("seed" or "joint"), computed once per session. Read only."""
    done = {}

    def get(mode):
        if mode not in done:
            done[mode] = analyse_stack(ND_FIXTURE, AnalysisOptions(mode=mode))
        return done[mode]
    return get
