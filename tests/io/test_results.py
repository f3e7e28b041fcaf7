"""The results folder (microfacet.io.results, format ``microfacet-results/1``): what
:func:`write_results_files` writes, :class:`Results` reads back (summary at once, the rest
lazily), :func:`json_safe`, completeness and errors. What the analysis puts in a results
folder: tests/analysis/test_output.py."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
import tifffile
from PIL import Image

from microfacet.core.distributions import NDFMixture, ThicknessMixture
from microfacet.core.errors import InputError
from microfacet.io.results import (
    FORMAT,
    IMAGES,
    MAPS,
    TABLES,
    TIFF_COPIES,
    X3P_COPIES,
    Results,
    json_safe,
    pixel_size_of,
    write_results_files,
)
from microfacet.io.x3p import read_x3p

H, W = 6, 9
G = ThicknessMixture([(0.4, 112.0, 3.0), (0.6, 130.0, 2.5)])
F = NDFMixture([(0.6, 3.0), (0.4, 9.0)])


def _maps(rng):
    return {
        "thickness_nm": rng.uniform(100, 150, (H, W)),              # float64 in
        "tilt_deg": np.where(rng.random((H, W)) < 0.2, np.nan, rng.uniform(0, 20, (H, W))),
        "normals": rng.normal(size=(H, W, 3)).astype(np.float32),
        "mask": rng.integers(0, 2, (H, W)),                          # ints in
        "facets": rng.integers(0, 40, (H, W)).astype(np.int64),
        "height_um": None,                                           # skipped
    }


@pytest.fixture
def folder(tmp_path):
    rng = np.random.default_rng(0)
    maps = _maps(rng)
    img = rng.integers(0, 65536, (H, W, 3)).astype(np.uint16)
    rows = np.column_stack([np.arange(5.0), rng.uniform(0, 1, 5), rng.uniform(0, 1, 5)])
    write_results_files(
        tmp_path,
        summary={"thickness": {"mixture": {**G.to_json(), "bic": 1.5}},
                 "ndf": {"mixture": {**F.to_json(), "bic": np.float64(2.5)}},
                 "parameters": {"mode": "joint", "roi_size_px": np.int64(255)},
                 "delta_e": {"mean": np.float32(1.25), "max": np.nan},
                 "masked_fraction": np.inf, "flags": np.array([True, False])},
        maps=maps, images={"all_in_focus": (img, 16)},
        tables={"ndf_pdf": (rows, ["tilt_deg", "density", "mixture_density"],
                            ["%.2f", "%.6g", "%.6g"])})
    return tmp_path, maps, img, rows


def test_written_files_are_read_back(folder):
    path, maps, img, rows = folder
    names = sorted(p.name for p in path.iterdir())
    assert names == sorted(["summary.json", "all_in_focus.png", "ndf_pdf.csv"]
                           + [MAPS[k][0] for k, v in maps.items() if v is not None]
                           + [TIFF_COPIES[k][0] for k, v in maps.items()
                              if v is not None and k in TIFF_COPIES])   # no pixel size: no x3p
    r = Results(path)
    for name, arr in maps.items():
        got = r.map(name)
        if arr is None:
            assert got is None
        elif name == "mask":
            assert got.dtype == bool
            np.testing.assert_array_equal(got, arr != 0)
        elif name == "facets":
            assert got.dtype == np.int32
            np.testing.assert_array_equal(got, arr)
        else:
            assert got.dtype == np.float32
            np.testing.assert_array_equal(got, np.asarray(arr, np.float32))
    np.testing.assert_allclose(r.image("all_in_focus"), img / 65535.0, rtol=1e-6)
    t = r.table("ndf_pdf")
    assert list(t) == ["tilt_deg", "density", "mixture_density"]
    np.testing.assert_allclose(t["tilt_deg"], rows[:, 0])
    np.testing.assert_allclose(t["density"], rows[:, 1], rtol=1e-5)
    assert r.table("thickness_roi") is None and r.map("reliability_db") is None
    assert r.map("thickness_nm") is r.map("thickness_nm")          # read once


def test_summary_is_strict_json_with_the_format(folder):
    path = folder[0]
    text = (path / "summary.json").read_text()
    s = json.loads(text, parse_constant=lambda c: pytest.fail(f"{c} in summary.json"))
    assert s["format"] == FORMAT
    assert s["delta_e"] == {"mean": 1.25, "max": None}
    assert s["masked_fraction"] is None and s["flags"] == [True, False]
    assert s["parameters"] == {"mode": "joint", "roi_size_px": 255}
    assert not [p for p in path.iterdir() if p.name.startswith(".")]   # no temporary file


def test_summary_accessors_and_mixtures(folder):
    r = Results(folder[0])
    assert r.get("delta_e", "mean") == 1.25
    assert r.get("delta_e", "nothing") is None and r.get("format", "x") is None
    # a summary without a version is version 1: its flat parameters read as the options tree
    assert r.parameters == {"mode": "joint", "roi": {"size_px": 255}}
    assert r.parameter("roi.size_px") == 255 and r.parameter("roi.nothing") is None
    assert r.thickness_mixture() == G and r.ndf_mixture() == F
    assert r.differing_parameters({"mode": "joint", "roi": {"size_px": np.int64(255)}}) == []
    assert r.differing_parameters({"mode": "seed", "roi": {"size_px": 128}, "new": 1.0}) == [
        "mode", "new", "roi.size_px"]


def test_record_rewrites_the_summary(folder):
    path = folder[0]
    r = Results(path)
    r.record("timings_s", "report", np.float64(2.5))
    r.record("ndf", "identified", False)
    again = Results(path)
    assert again.get("timings_s", "report") == 2.5
    assert again.get("ndf", "identified") is False
    assert again.ndf_mixture() == F
    assert not [p for p in path.iterdir() if p.name.startswith(".")]


def test_no_mixture_reads_as_none(tmp_path):
    write_results_files(tmp_path, summary={"thickness": {"mixture": {"components": []}}},
                        maps={})
    r = Results(tmp_path)
    assert r.thickness_mixture() is None and r.ndf_mixture() is None


def test_maps_are_read_lazily(tmp_path):
    """A broken map does not stop the folder from opening; it is reported when used."""
    write_results_files(tmp_path, summary={}, maps={"thickness_nm": np.ones((H, W))})
    (tmp_path / MAPS["tilt_deg"][0]).write_bytes(b"not an npy file")
    r = Results(tmp_path)
    assert r.map("thickness_nm").shape == (H, W)
    with pytest.raises(InputError, match=r"tilt_deg\.npy: cannot read"):
        r.map("tilt_deg")


def test_maps_given_as_callables_are_made_when_written(tmp_path):
    """A map may be given as a callable, called once when its file is written; one that gives
    None writes no file. Released maps and images are read again; tables are kept."""
    calls = []

    def normals():
        calls.append(1)
        return np.ones((H, W, 3))
    write_results_files(tmp_path, summary={}, maps={"normals": normals,
                                                    "thickness_nm": lambda: None,
                                                    "tilt_deg": np.full((H, W), 2.0),
                                                    "facets": np.zeros((H, W), int)},
                        tables={"ndf_pdf": (np.ones((2, 3)), ["tilt_deg", "density",
                                                              "mixture_density"], ["%g"] * 3),
                                "facets": (np.ones((2, len(TABLES["facets"][1]))),
                                           list(TABLES["facets"][1]),
                                           ["%g"] * len(TABLES["facets"][1]))})
    assert calls == [1]
    assert not (tmp_path / MAPS["thickness_nm"][0]).exists()
    r = Results(tmp_path)
    first, table = r.map("normals"), r.table("ndf_pdf")
    assert first.dtype == np.float32 and np.all(first == 1.0)
    assert r.map("normals") is first                     # read once...
    r.release()
    again = r.map("normals")                             # ...and again once released
    assert again is not first and np.array_equal(again, first)
    assert r.table("ndf_pdf") is table
    facets_table = r.table("facets")                     # a map and a table of one name
    assert isinstance(facets_table, dict) and r.map("facets").shape == (H, W)
    r.release()
    assert r.table("facets") is facets_table and r.map("facets").dtype == np.int32


def test_the_maps_written_come_back_as_their_files_hold_them(tmp_path):
    """``write_results_files`` returns the maps given as arrays as their files hold them (the
    array itself where it has the file's dtype); ``Results(folder, maps=...)`` gives those
    instead of reading the files, read-only, and keeps them when released."""
    rng = np.random.default_rng(3)
    maps = _maps(rng)
    maps["tilt_deg"] = maps["tilt_deg"].astype(np.float32)
    maps["delta_e"] = lambda: np.ones((H, W))                       # made for its file
    stored = write_results_files(tmp_path, summary={}, maps=maps)
    assert set(stored) == {"thickness_nm", "tilt_deg", "normals", "mask", "facets"}
    assert stored["tilt_deg"] is maps["tilt_deg"] and stored["normals"] is maps["normals"]
    from_files = Results(tmp_path)
    for name, a in stored.items():
        f = from_files.map(name)
        assert a.dtype == f.dtype and np.array_equal(a, f, equal_nan=a.dtype.kind == "f")
    np.save(tmp_path / MAPS["thickness_nm"][0], np.zeros((H, W)))   # not what is given
    r = Results(tmp_path, maps=stored)
    given = r.map("thickness_nm")
    assert np.shares_memory(given, stored["thickness_nm"]) and not given.flags.writeable
    with pytest.raises(ValueError, match="read-only"):
        given[0, 0] = 1.0
    assert stored["tilt_deg"].flags.writeable                   # the caller's stays its own
    r.release()
    assert r.map("thickness_nm") is given and r.map("delta_e").dtype == np.float32
    with pytest.raises(ValueError, match="maps: unknown map 'thickness'"):
        Results(tmp_path, maps={"thickness": np.ones((H, W))})


@pytest.mark.parametrize("name, value, match", [
    ("tilt_deg", np.zeros((H, W, 2)), r"tilt_deg\.npy: expected a 2-D array"),
    ("normals", np.zeros((H, W)), r"normals\.npy: expected a 3-D array"),
    ("delta_e", np.zeros((0, W)), r"delta_e\.npy: expected a 2-D array"),
    ("delta_e", np.array([["a"]]), r"delta_e\.npy: expected numbers"),
])
def test_malformed_maps_are_refused_naming_the_file(tmp_path, name, value, match):
    write_results_files(tmp_path, summary={}, maps={})
    np.save(tmp_path / MAPS[name][0], value)
    with pytest.raises(InputError, match=match):
        Results(tmp_path).map(name)


@pytest.mark.parametrize("text, match", [
    ("", r"ndf_pdf\.csv: empty"),
    ("tilt_deg,density\n0.25,1\n", r"ndf_pdf\.csv: missing column\(s\) mixture_density"),
    ("tilt_deg,density,mixture_density\n0.25,x,1\n", r"column density holds a value"),
])
def test_malformed_tables_are_refused_naming_the_file(tmp_path, text, match):
    write_results_files(tmp_path, summary={}, maps={})
    (tmp_path / TABLES["ndf_pdf"][0]).write_text(text)
    with pytest.raises(InputError, match=match):
        Results(tmp_path).table("ndf_pdf")


def test_unknown_names_are_refused(tmp_path):
    for kw, match in (({"maps": {"thickness": np.ones((2, 2))}}, "maps: unknown map"),
                      ({"maps": {}, "images": {"photo": (np.ones((2, 2)), 8)}},
                       "images: unknown image"),
                      ({"maps": {}, "tables": {"roi": (np.ones((1, 1)), ["a"], "%g")}},
                       "tables: unknown table")):
        with pytest.raises(ValueError, match=match):
            write_results_files(tmp_path, summary={}, **kw)
    write_results_files(tmp_path, summary={}, maps={})
    with pytest.raises(ValueError, match="name: unknown map"):
        Results(tmp_path).map("thickness")
    assert set(IMAGES) == {"all_in_focus"}


@pytest.mark.parametrize("setup, match", [
    (lambda d: None, r"summary\.json: missing \(not a results folder\)"),
    (lambda d: (d / "summary.json").write_text("[1, 2]"), "must hold a JSON object"),
    (lambda d: (d / "summary.json").write_text('{"format": "microfacet-height/1"}'),
     r"key 'format': 'microfacet-height/1' is not 'microfacet-results/1'"),
    (lambda d: (d / "summary.json").write_text('{"ndf": {"mixture": {"form": "ggx"}}}'),
     None),
])
def test_folders_that_are_not_results(tmp_path, setup, match):
    d = tmp_path / "r"
    d.mkdir()
    setup(d)
    if match is None:       # opens; the bad mixture is named when asked for
        with pytest.raises(InputError, match=r"key 'ndf\.mixture': NDF mixture: unsupported"):
            Results(d).ndf_mixture()
    else:
        with pytest.raises(InputError, match=match):
            Results(d)
    with pytest.raises(InputError, match="results folder not found"):
        Results(tmp_path / "missing")


def test_complete(folder, tmp_path):
    path = folder[0]
    assert Results.complete(path) == (True, "")
    assert Results.complete(path, {"mode": "joint", "roi": {"size_px": 255}}) == (True, "")
    ok, why = Results.complete(path, {"mode": "seed"})
    assert not ok and "different parameters (mode)" in why and "overwrite" in why
    assert Results.complete(tmp_path / "nothing") == (False, "")
    (tmp_path / "empty").mkdir()
    ok, why = Results.complete(tmp_path / "empty")
    assert not ok and "summary.json" in why
    (tmp_path / "old").mkdir()
    (tmp_path / "old" / "summary.json").write_text('{"thickness": {}}')   # no format key
    ok, why = Results.complete(tmp_path / "old")
    assert not ok and "key 'format'" in why


# ------------------------------------------------------------------------------ json_safe


def test_json_safe_makes_strict_json():
    x = {1: np.float32(0.5), "a": [np.nan, np.inf, -np.inf, np.int64(3)],
         "b": (np.bool_(False), np.arange(3), np.array([[1.5, np.nan]])),
         "c": {"d": np.uint8(7), "e": "text", "f": None, "g": 2.0}}
    y = json_safe(x)
    assert y == {"1": 0.5, "a": [None, None, None, 3], "b": [False, [0, 1, 2], [[1.5, None]]],
                 "c": {"d": 7, "e": "text", "f": None, "g": 2.0}}
    assert json.loads(json.dumps(y, allow_nan=False)) == y
    assert type(y["a"][3]) is int and type(y["b"][0]) is bool and type(y["1"]) is float
    assert json_safe(math.nan) is None and json_safe(True) is True


# ---------------------------------------------------------------- copies for microscopy tools


def _tool_folder(tmp_path, pixel_size_um, **kw):
    rng = np.random.default_rng(8)
    maps = {"height_um": np.where(rng.random((H, W)) < 0.1, np.nan, rng.normal(5, 2, (H, W))),
            "thickness_nm": rng.uniform(100, 150, (H, W)).astype(np.float32),
            "tilt_deg": rng.uniform(0, 20, (H, W)), "tilt_sigma_deg": rng.uniform(0, 2, (H, W)),
            "delta_e": rng.uniform(0, 3, (H, W))}
    img = rng.integers(0, 256, (H, W, 3)).astype(np.uint8)
    write_results_files(tmp_path, summary={"inputs": {"pixel_size_um": pixel_size_um}},
                        maps=maps, images={"all_in_focus": (img, 8)}, **kw)
    return maps


def test_tiff_copies_carry_values_pixel_size_and_units(tmp_path):
    maps = _tool_folder(tmp_path, 0.65)
    units = {"height_um": "um", "thickness_nm": "nm", "tilt_deg": "degree",
             "tilt_sigma_deg": "degree"}
    assert set(TIFF_COPIES) == set(units)
    for name, (file, unit) in TIFF_COPIES.items():
        with tifffile.TiffFile(tmp_path / file) as tf:
            got = tf.asarray()
            meta = tf.imagej_metadata
            xres, yres = tf.pages[0].resolution
        assert got.dtype == np.float32 and unit == units[name]
        np.testing.assert_array_equal(got, np.asarray(maps[name], np.float32))
        assert meta["unit"] == "um" and meta["vunit"] == unit
        assert (1 / yres, 1 / xres) == pytest.approx((0.65, 0.65), rel=1e-7)
    assert not (tmp_path / "delta_e.tif").exists()              # only the listed maps


def test_x3p_copy_and_png_pixel_size(tmp_path):
    maps = _tool_folder(tmp_path, [0.5, 0.25])                  # (y, x)
    m = read_x3p(tmp_path / X3P_COPIES["height_um"])
    np.testing.assert_array_equal(m.height_um, maps["height_um"].astype(np.float32))
    np.testing.assert_array_equal(m.height_um, Results(tmp_path).map("height_um"))
    assert m.pixel_size_um == (0.5, 0.25)
    with Image.open(tmp_path / IMAGES["all_in_focus"]) as im:   # pHYs, read by PIL
        dpi_x, dpi_y = im.info["dpi"]
    assert (25400 / dpi_y, 25400 / dpi_x) == pytest.approx((0.5, 0.25), rel=1e-6)


def test_without_pixel_size_or_copies(tmp_path):
    a, b = tmp_path / "a", tmp_path / "b"
    a.mkdir()
    b.mkdir()
    _tool_folder(a, None)
    assert not (a / "height_um.x3p").exists()
    with tifffile.TiffFile(a / "height_um.tif") as tf:
        assert "unit" not in tf.imagej_metadata
    with Image.open(a / "all_in_focus.png") as im:
        assert "dpi" not in im.info
    _tool_folder(b, 0.5, tool_copies=False)
    assert sorted(p.suffix for p in b.iterdir()) == [".json"] + [".npy"] * 5 + [".png"]
    with Image.open(b / "all_in_focus.png") as im:
        assert "dpi" not in im.info


@pytest.mark.parametrize("summary, expected", [
    ({"inputs": {"pixel_size_um": 2}}, (2.0, 2.0)),
    ({"inputs": {"pixel_size_um": [1.5, 0.5]}}, (1.5, 0.5)),
    ({"inputs": {"pixel_size_um": None}}, None),
    ({"inputs": {"pixel_size_um": -1.0}}, None),
    ({"inputs": {"pixel_size_um": "x"}}, None),
    ({"inputs": {"pixel_size_um": [1, 2, 3]}}, None),
    ({"inputs": []}, None),
])
def test_pixel_size_of(summary, expected):
    assert pixel_size_of(summary) == expected
