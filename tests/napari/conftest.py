"""Fixtures of the napari plugin's tests: the ND fixture analysed once (slow), and a small
synthetic results folder written through the package's own writer (fast)."""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from microfacet.analysis.options import AnalysisOptions
from microfacet.io.results import write_results_files
from microfacet.workflow import analyse_to_folder

ND_FIXTURE = Path(__file__).resolve().parents[2] / "fixtures" / "stacks" / "nd-fixture"
#: The synthetic results folder's mixtures and pixel size.
THICKNESS = {"components": [{"weight": 0.6, "mean_nm": 120.0, "sd_nm": 3.0},
                            {"weight": 0.4, "mean_nm": 150.0, "sd_nm": 4.0}],
             "identified": True, "reason": ""}
NDF = {"components": [{"weight": 1.0, "mean_deg": 0.0, "sd_deg": 5.0}]}
PIXEL_UM = (0.25, 0.5)


@pytest.fixture(scope="module")
def small_results(tmp_path_factory):
    """A results folder with height, thickness, tilt and facet maps (3×4), both mixtures and
    a (y, x) pixel size of 0.25 × 0.5 µm: ``path``, ``thickness``, ``ndf``, ``pixel_um``."""
    out = tmp_path_factory.mktemp("napari") / "small-results"
    out.mkdir()
    rng = np.random.default_rng(0)
    write_results_files(
        out, summary={"inputs": {"pixel_size_um": list(PIXEL_UM)},
                      "thickness": {"mixture": THICKNESS},
                      "ndf": {"mixture": NDF, "identified": False, "reason": "censored"}},
        maps={"height_um": rng.normal(size=(3, 4)), "thickness_nm": np.full((3, 4), 130.0),
              "tilt_deg": np.full((3, 4), 4.0), "facets": np.arange(12).reshape(3, 4)},
        tool_copies=False)
    return SimpleNamespace(path=out, thickness=THICKNESS, ndf=NDF, pixel_um=PIXEL_UM)


@pytest.fixture(scope="module")
def nd_results(tmp_path_factory):
    """fixtures/stacks/nd-fixture analysed (joint mode, no report) into a results folder."""
    out = tmp_path_factory.mktemp("napari-nd") / "nd-results"
    analyse_to_folder(ND_FIXTURE, out, options=AnalysisOptions(), report=False)
    return out
