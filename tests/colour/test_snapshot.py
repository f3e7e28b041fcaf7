"""microfacet.colour.snapshot: colour-science's tables stored with the package.

Reference: the installed colour-science itself. The stored tables must be its numbers; a
change of colour-science's data fails here (regenerate with ``python -m
pipelines.colour_snapshot``). And the point of storing them: the colour path of an analysis
does not import colour-science.
"""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from microfacet.colour import datasets, snapshot
from microfacet.colour.colorimetry import spectral_weights
from microfacet.colour.snapshot import (
    SNAPSHOT_PATH,
    WEIGHT_GRIDS,
    grid_key,
    stored,
    write_snapshot,
)


def test_the_snapshot_is_shipped_and_complete():
    tables = stored()
    assert tables is not None, f"{SNAPSHOT_PATH} is missing"
    assert set(datasets.OBSERVERS.values()) == set(tables.cmf)
    assert set(tables.illuminant_names) == set(tables.illuminant)
    assert {"D65", "A", "D50"} <= set(tables.illuminant_names)
    assert len(tables.weights) == 2 * len(WEIGHT_GRIDS)
    assert not tables.weights[next(iter(tables.weights))].flags.writeable


def test_stored_tables_are_colour_sciences(colour_science):
    tables = stored()
    assert tables.illuminant_names == snapshot.colour_illuminant_names()
    for name, (w, v) in tables.cmf.items():
        cw, cv = snapshot.colour_cmf_table(name)
        np.testing.assert_array_equal(w, cw)
        np.testing.assert_array_equal(v, cv)
    for name, (w, v) in tables.illuminant.items():
        cw, cv = snapshot.colour_illuminant_table(name)
        np.testing.assert_array_equal(w, cw)
        np.testing.assert_array_equal(v, cv)


@pytest.mark.parametrize("observer", ["2", "10"])
@pytest.mark.parametrize("grid", WEIGHT_GRIDS)
def test_stored_weights_are_colour_sciences(colour_science, grid, observer):
    first, step, last = grid
    w = np.arange(first, last + step / 2, step)
    obs = datasets.observer_name(observer)
    assert grid_key(w, "D65", obs) in stored().weights
    want = snapshot.colour_impulse_xyz(w, "D65", obs)
    want /= want[:, 1].sum()
    np.testing.assert_array_equal(spectral_weights(w, observer=observer), want)


def test_other_grids_and_illuminants_are_computed_by_colour_science(colour_science):
    for w, ill in ((np.arange(400.0, 701.0, 2.5), "D65"), (np.arange(380.0, 781.0, 5.0), "A")):
        assert grid_key(w, ill, datasets.observer_name("2")) not in stored().weights
        want = snapshot.colour_impulse_xyz(w, ill, datasets.observer_name("2"))
        np.testing.assert_array_equal(spectral_weights(w, illuminant=ill),
                                      want / want[:, 1].sum())


def test_grid_keys():
    obs = datasets.observer_name("2")
    a = grid_key(np.arange(380.0, 781.0, 5.0), "D65", obs)
    b = grid_key(np.linspace(380.0, 780.0, 81) + 1e-12, "D65", obs)
    assert a == b and "|5|" in a
    assert grid_key(np.array([400.0, 410.0, 430.0]), "D65", obs) is None
    assert grid_key(np.array([400.0]), "D65", obs) is None


def test_missing_file_reads_as_none(tmp_path):
    assert stored(tmp_path / "none.npz") is None


def test_write_snapshot_round_trips(tmp_path, colour_science):
    path = tmp_path / "sub" / "tables.npz"
    tables = write_snapshot(path)
    assert path.is_file() and not list(path.parent.glob(".*partial*"))
    assert tables.colour_version == colour_science.__version__
    assert tables.weights.keys() == stored().weights.keys()
    for k, v in tables.weights.items():
        np.testing.assert_array_equal(v, stored().weights[k])


def test_the_colour_path_does_not_import_colour_science():
    code = ("import sys, numpy as np\n"
            "from microfacet.colour.srgb import srgb_to_lab, colours_from_spectra\n"
            "from microfacet.colour.table import build_colour_table\n"
            "srgb_to_lab(np.full((2, 2, 3), 0.5, np.float32))\n"
            "colours_from_spectra(np.ones((1, 81)), np.arange(380.0, 781.0, 5.0))\n"
            "build_colour_table(thickness_range_nm=(100.0, 140.0), theta_range_deg=(0.0, 20.0))\n"
            "assert 'colour' not in sys.modules, 'colour-science was imported'\n")
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=120)
    assert run.returncode == 0, run.stderr[-2000:]


def test_an_unreadable_file_falls_back_to_colour_science(tmp_path, caplog):
    bad = tmp_path / "broken.npz"
    bad.write_bytes(b"not a zip file")
    with caplog.at_level("WARNING", logger="microfacet.colour"):
        assert stored(bad) is None
    assert "broken.npz" in caplog.text and len(caplog.records) == 1
