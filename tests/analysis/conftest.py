"""Fixtures of the analysis tests: analyses of the bundled synthetic stack, made once."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from microfacet.analysis import AnalysisOptions, analyse_stack
from microfacet.focus.height import FocusResult

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


@pytest.fixture(scope="session")
def focus_result():
    """``focus_result(height_um, texture=None)``: a :class:`FocusResult` of a known height
    map, every pixel reliable, ``texture`` (default zeros) as the all-in-focus image."""
    def make(height_um, texture=None):
        h = np.asarray(height_um)
        zero = np.zeros(h.shape, np.float32)
        return FocusResult(height_um=h, height_fit_um=h, reliability_db=zero,
                           reliable=np.ones(h.shape, bool),
                           best_index=np.zeros(h.shape, np.int32), focus_max=zero,
                           all_in_focus=zero if texture is None else texture,
                           z_um=np.zeros(0), params={}, timings_s={})
    return make
