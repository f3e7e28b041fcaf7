"""The report's view of a results folder (microfacet.report.context). Edge cases, on small
hand-made folders written with microfacet.io.results.write_results_files."""

from __future__ import annotations

import math

import numpy as np
import pytest

from microfacet.core.errors import InputError
from microfacet.io.results import write_results_files
from microfacet.optics.defaults import DEFAULT_FILM, DEFAULT_ILLUMINANT, DEFAULT_SUBSTRATE
from microfacet.report.context import DRAWN_FILES, Context
from microfacet.report.page_angular import optics

_PDF_COLUMNS = ["thickness_nm", "density", "mixture_density"]


def _folder(path, summary, maps=None, tables=None):
    path.mkdir()
    write_results_files(path, summary=summary, maps=maps or {}, tables=tables)
    return Context.open(path)


def test_fits_geometry_and_largest_tilt(tmp_path):
    ctx = _folder(tmp_path / "a", {
        "inputs": {"stack": "/data/s1", "pixel_size_um": 0.25, "numerical_aperture": 0.8},
        "thickness": {"mixture": {"components": [{"weight": 1, "mean_nm": 51, "sd_nm": 2}]}},
        "ndf": {"mixture": {"components": [], "bic": None}}},
        maps={"mask": np.eye(3, dtype=bool)})
    assert ctx.thick.means_nm.tolist() == [51.0] and ctx.ndf is None
    assert ctx.geom.unit == "µm" and ctx.geom.extent((4, 8)) == (0.0, 2.0, 1.0, 0.0)
    assert ctx.stack == "/data/s1" and ctx.mask.dtype == bool
    # not recorded: from the numerical aperture, asin(NA)/2
    assert ctx.max_tilt() == pytest.approx(math.degrees(math.asin(0.8)) / 2)
    assert ctx.missing_files() == [f for f in DRAWN_FILES if f != "mask.npy"]
    # no optics recorded: none read, and the angular page models the defaults
    assert not Context.open(tmp_path / "a").optics("film")
    assert optics(ctx) == {"film": DEFAULT_FILM, "substrate": DEFAULT_SUBSTRATE,
                           "illuminant": DEFAULT_ILLUMINANT}


def test_recorded_values_win_and_pixels_without_a_size(tmp_path):
    ctx = _folder(tmp_path / "a", {"summary_version": 2, "inputs": {
        "numerical_aperture": 0.8, "film": "F"}, "ndf": {"max_tilt_deg": 20.0}})
    assert ctx.max_tilt() == 20.0 and ctx.optics("film") == "F"
    assert ctx.geom.unit == "pixel" and ctx.thick is None and ctx.mask is None
    # a version-1 summary recorded the optics at the top level: read as the inputs'
    old = _folder(tmp_path / "v1", {"inputs": {"numerical_aperture": 0.8}, "film": "G",
                                    "illuminant": "D50"})
    assert old.optics("film") == "G" and old.optics("illuminant") == "D50"


def test_density_tables(tmp_path):
    ok = np.column_stack([[1.0, 2.0, 3.0], [0.2, 0.6, 0.2], [0.3, 0.4, 0.3]])
    ctx = _folder(tmp_path / "a", {}, tables={
        "thickness_pdf": (ok, _PDF_COLUMNS, "%.6g"),
        "ndf_pdf": (np.empty((0, 3)), ["tilt_deg", "density", "mixture_density"], "%.6g")})
    ctx.check_tables()
    assert ctx.density_table("thickness_pdf")["density"].tolist() == [0.2, 0.6, 0.2]
    assert ctx.density_table("ndf_pdf") is None  # header only: no fit


@pytest.mark.parametrize("grid", [[1.0], [1.0, 1.0], [2.0, 1.0], [1.0, np.nan]])
def test_a_density_table_whose_bins_cannot_be_drawn_is_an_input_error(tmp_path, grid):
    rows = np.column_stack([grid, np.ones(len(grid)), np.ones(len(grid))])
    ctx = _folder(tmp_path / "a", {}, tables={"thickness_pdf": (rows, _PDF_COLUMNS, "%.6g")})
    with pytest.raises(InputError, match="thickness_pdf.csv: column thickness_nm"):
        ctx.check_tables()
