"""Tests of ``microfacet init FOLDER``: stack.json for a plain folder of images."""

from __future__ import annotations

import importlib
import json
import re

import cv2
import numpy as np
import pytest
import tifffile

from microfacet.io.stack import read_stack

H, W = 12, 17


@pytest.fixture
def cli(monkeypatch):
    """``microfacet`` with ``init`` registered (whether or not cli/main.py lists it yet)."""
    main_module = importlib.import_module("microfacet.cli.main")
    if "init" not in main_module.COMMANDS:
        monkeypatch.setattr(main_module, "COMMANDS", main_module.COMMANDS + ("init",))
    return main_module.main


def _folder(d, names):
    d.mkdir()
    for k, name in enumerate(names):
        cv2.imwrite(str(d / name), np.full((H, W, 3), 10 * (k + 1), np.uint8))
    return d


def _err(capsys):
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1
    return err[0]


def test_init_writes_a_valid_stack_json_and_reports(tmp_path, cli, capsys):
    d = _folder(tmp_path / "p", ["img_10.png", "img_2.png", "img_1.png"])
    status = cli(["init", str(d), "--pixel-size-um", "0.216", "--z-step-um", "0.5",
                  "--film", "TiO2_Jolivet2023_anatase", "--numerical-aperture", "0.6"])
    assert status == 0
    out = capsys.readouterr().out
    meta = json.loads((d / "stack.json").read_text())
    assert meta["slices"] == ["img_1.png", "img_2.png", "img_10.png"]
    assert meta["pixel_size_um"] == 0.216 and meta["z_step_um"] == 0.5
    assert meta["film"] == "TiO2_Jolivet2023_anatase"
    assert meta["illumination"]["numerical_aperture"] == 0.6
    st = read_stack(d)
    assert st.n_slices == 3 and st.numerical_aperture == 0.6
    assert "slices:     3 (17x12 px, 8-bit RGB)" in out
    assert "order:      img_1.png ... img_10.png" in out
    assert "z:          0 to 1 µm in steps of 0.5 µm (option --z-step-um)" in out
    assert "pixel size: 0.216 µm (option --pixel-size-um)" in out
    assert sorted(p.name for p in d.iterdir()) == ["img_1.png", "img_10.png", "img_2.png",
                                                    "stack.json"]


def test_init_takes_values_from_imagej_metadata(tmp_path, cli, capsys):
    d = tmp_path / "ij"
    d.mkdir()
    tifffile.imwrite(d / "stack.tif", np.zeros((4, H, W), np.uint8), imagej=True,
                     resolution=(4.0, 4.0), metadata={"spacing": 0.5, "unit": "um",
                                                      "axes": "ZYX"})
    assert cli(["init", str(d), "--z-step-um", "0.25"]) == 0
    out = capsys.readouterr().out
    assert "pixel size: 0.25 µm (ImageJ metadata of stack.tif)" in out
    assert "(option --z-step-um)" in out and "stack.tif page 0 ... stack.tif page 3" in out
    meta = json.loads((d / "stack.json").read_text())
    assert meta == {"format": "microfacet-stack/1", "pixel_size_um": 0.25, "tiff": "stack.tif",
                    "z_step_um": 0.25}


def test_init_and_analyze_take_non_square_pixels_as_y_x(tmp_path, cli, capsys):
    d = _folder(tmp_path / "p", ["a.png", "b.png", "c.png"])
    assert cli(["init", str(d), "--pixel-size-um", "0.2,0.3", "--z-step-um", "1"]) == 0
    assert "pixel size: 0.2 µm high x 0.3 µm wide (non-square)" in capsys.readouterr().out
    assert json.loads((d / "stack.json").read_text())["pixel_size_um"] == [0.2, 0.3]
    assert read_stack(d).pixel_size_yx_um == (0.2, 0.3)
    e = _folder(tmp_path / "q", ["a.png", "b.png", "c.png"])
    st = read_stack(e, pixel_size_um=[0.2, 0.3], z_step_um=1.0)
    assert st.pixel_size_yx_um == (0.2, 0.3) and st.sources["pixel_size_um"] == "given"


def test_init_refuses_to_overwrite_and_names_missing_options(tmp_path, cli, capsys):
    d = _folder(tmp_path / "p", ["a.png", "b.png", "c.png"])
    assert cli(["init", str(d)]) == 2
    line = _err(capsys)
    assert "--pixel-size-um" in line and "--z-step-um" in line
    assert not (d / "stack.json").exists()
    assert cli(["init", str(d), "--pixel-size-um", "1", "--z-step-um", "1"]) == 0
    first = (d / "stack.json").read_bytes()
    assert cli(["init", str(d), "--pixel-size-um", "2", "--z-step-um", "1"]) == 2
    assert "stack.json: already exists; --overwrite replaces it" in _err(capsys)
    assert (d / "stack.json").read_bytes() == first
    assert cli(["init", str(d), "--pixel-size-um", "2", "--z-step-um", "1",
                "--overwrite"]) == 0
    assert read_stack(d).pixel_size_um == 2.0


@pytest.mark.parametrize("args,pattern", [
    (["--film", "TiO2_Nonexistent"], r"--film: unknown optical-constant set"),
    (["--numerical-aperture", "1.5"], r"--numerical-aperture: must be a number in \(0, 1\]"),
    (["--pixel-size-um", "-1"], r"--pixel-size-um: must be a finite number > 0"),
])
def test_init_bad_options(tmp_path, cli, capsys, args, pattern):
    d = _folder(tmp_path / "p", ["a.png", "b.png", "c.png"])
    base = {"--pixel-size-um": "1", "--z-step-um": "1"}
    for k, v in zip(args[::2], args[1::2]):
        base[k] = v
    assert cli(["init", str(d), *[x for kv in base.items() for x in kv]]) == 2
    assert re.search(pattern, _err(capsys))
    assert not (d / "stack.json").exists()


def test_init_invalid_stack_leaves_nothing(tmp_path, cli, capsys):
    d = _folder(tmp_path / "p", ["a.png", "b.png", "c.png"])
    cv2.imwrite(str(d / "b.png"), np.zeros((H + 1, W), np.uint8))
    assert cli(["init", str(d), "--pixel-size-um", "1", "--z-step-um", "1"]) == 2
    assert "b.png" in _err(capsys)
    assert sorted(p.name for p in d.iterdir()) == ["a.png", "b.png", "c.png"]
