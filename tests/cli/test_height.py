"""Tests of ``microfacet height STACK --out OUT``."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

from microfacet.cli import main
from microfacet.focus.normals import normals_from_height
from microfacet.io.stack import write_stack

COU = (Path(__file__).resolve().parents[2] / "fixtures" / "focus-stacks"
       / "cou2023-synthetic-rough")


@pytest.fixture()
def small_stack(tmp_path, render_stack):
    """An RGB 8-bit stack of a tilted plane (height 1..5 µm across x), pixel 0.5 µm."""
    H, W = 40, 56
    h = np.add.outer(np.zeros(H), np.linspace(1.0, 5.0, W)).astype(np.float32)
    z = np.arange(0.0, 6.5, 0.5)
    imgs = render_stack(h, z, rgb=True, seed=7)
    d = tmp_path / "stack"
    write_stack(d, [np.round(im * 255).astype(np.uint8) for im in imgs], z_um=z,
                pixel_size_um=0.5)
    return d, h


def test_outputs(small_stack, tmp_path, capsys):
    d, h = small_stack
    out = tmp_path / "out"
    assert main(["height", str(d), "--out", str(out), "-q"]) == 0
    names = {p.name for p in out.iterdir()}
    assert {"height_um.npy", "normals.npy", "all_in_focus.png", "reliability_db.npy",
            "reliability.png", "height.json", "height.png"} <= names
    hu = np.load(out / "height_um.npy")
    n = np.load(out / "normals.npy")
    rel = np.load(out / "reliability_db.npy")
    assert hu.dtype == np.float32 and hu.shape == h.shape
    assert n.dtype == np.float32 and n.shape == h.shape + (3,)
    assert rel.dtype == np.float32 and rel.shape == h.shape
    ok = np.isfinite(hu)
    assert ok.mean() > 0.9
    assert np.sqrt(np.mean((hu - h)[5:-5, 5:-5][ok[5:-5, 5:-5]] ** 2)) < 0.15
    # normals are those of the written height map with the stack's pixel size
    np.testing.assert_allclose(n, normals_from_height(hu, pixel_size_um=0.5), equal_nan=True)
    img = cv2.imread(str(out / "all_in_focus.png"), cv2.IMREAD_UNCHANGED)
    assert img.shape == h.shape + (3,) and img.dtype == np.uint8
    meta = json.loads((out / "height.json").read_text())
    assert meta["parameters"]["operator"] == "tenengrad"
    assert meta["pixel_size_um"] == 0.5 and meta["n_slices"] == 13
    assert "total" in meta["timings_s"]
    err = capsys.readouterr().err
    assert "[" not in err            # no progress bar when not a terminal / quiet
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".out")]


def test_refuses_existing_out_and_overwrites(small_stack, tmp_path, capsys):
    """A folder that is not a height folder is never replaced, not even with --overwrite; an
    earlier height folder is replaced only with --overwrite."""
    d, _ = small_stack
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "keep.txt").write_text("x")
    for extra in ([], ["--overwrite"]):
        assert main(["height", str(d), "--out", str(mine)] + extra) == 2
        assert "never replaced" in capsys.readouterr().err
    assert (mine / "keep.txt").read_text() == "x"
    out = tmp_path / "out"
    assert main(["height", str(d), "--out", str(out), "-q"]) == 0
    (out / "note.txt").write_text("x")
    assert main(["height", str(d), "--out", str(out)]) == 2
    assert "already exists" in capsys.readouterr().err and (out / "note.txt").exists()
    assert main(["height", str(d), "--out", str(out), "--overwrite", "--operator", "sml",
                 "--window-px", "5", "--fill"]) == 0
    assert not (out / "note.txt").exists()
    hu = np.load(out / "height_um.npy")
    assert np.isfinite(hu).all()
    assert json.loads((out / "height.json").read_text())["parameters"]["operator"] == "sml"


@pytest.mark.parametrize("mutate,pattern", [
    (lambda d: (d / "stack.json").unlink(), "missing stack.json"),
    (lambda d: (d / "slices/003.png").write_bytes(b"\x89PNG\r\n\x1a\n trunc"), r"slices'\]?\[3\]"),
    (lambda d: (d / "stack.json").write_text(
        (d / "stack.json").read_text().replace('"pixel_size_um": 0.5', '"pixel_size_um": -2')),
     "pixel_size_um"),
])
def test_bad_input_one_line_exit_2(small_stack, tmp_path, capsys, mutate, pattern):
    import re

    d, _ = small_stack
    mutate(d)
    out = tmp_path / "out"
    assert main(["height", str(d), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and err.startswith("microfacet height: error:")
    assert re.search(pattern, err)
    assert not out.exists()
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".out")]


def test_bad_window_option(small_stack, tmp_path, capsys):
    d, _ = small_stack
    assert main(["height", str(d), "--out", str(tmp_path / "o"), "--window-px", "4"]) == 2
    assert "--window-px" in capsys.readouterr().err


def test_focus_flags_reach_the_options(small_stack, tmp_path, capsys):
    """The flags generated from FocusOptions set the options height.json records; errors of
    the workflow's own parameters name their flag."""
    d, _ = small_stack
    out = tmp_path / "o"
    assert main(["height", str(d), "--out", str(out), "-q", "--window", "box",
                 "--interpolation", "lsq", "--fit-radius", "3", "--min-reliability-db=-inf",
                 "--fill", "nearest"]) == 0
    p = json.loads((out / "height.json").read_text())["parameters"]
    assert (p["window"], p["interpolation"], p["fit_radius"], p["fill"]) == (
        "box", "lsq", 3, "nearest")
    assert p["min_reliability_db"] == -float("inf") and p["align"] is None
    assert main(["height", str(d), "--out", str(tmp_path / "p"), "--smooth-sigma-px",
                 "-1"]) == 2
    assert "--smooth-sigma-px: must be >= 0" in capsys.readouterr().err
    assert main(["height", str(d), "--out", str(tmp_path / "p"), "--fit-radius", "0"]) == 2
    assert "--fit-radius: must be an integer in 1..10" in capsys.readouterr().err


@pytest.mark.slow
def test_plain_image_folder(tmp_path):
    """A folder of images without stack.json works with --pixel-size-um and --z-step-um."""
    d = tmp_path / "plain"
    d.mkdir()
    for i in (1, 2, 3, 10, 11):         # natural order: 1, 2, 3, 10, 11
        shutil.copy(COU / "stack1" / f"image_{i + 15}.jpg", d / f"image_{i}.jpg")
    out = tmp_path / "o"
    assert main(["height", str(d), "--out", str(out), "--pixel-size-um", "2",
                 "--z-step-um", "1", "-q"]) == 0
    meta = json.loads((out / "height.json").read_text())
    assert meta["n_slices"] == 5 and meta["pixel_size_um"] == 2.0


@pytest.mark.slow
def test_cou_stack_end_to_end(tmp_path):
    """The console script on a ground-truth stack: RMSE of the written map <= 0.25 slices."""
    out = tmp_path / "o"
    r = subprocess.run([sys.executable, "-m", "microfacet", "height", str(COU / "stack3"),
                        "--out", str(out)], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    assert r.stderr == ""                      # not a terminal: no progress bar
    hu = np.load(out / "height_um.npy")
    ref = -np.load(COU / "stack3" / "reference.npy")
    d = hu[20:379, 20:379]
    ok = np.isfinite(d)
    assert ok.mean() > 0.95
    assert np.sqrt(np.mean((d[ok] - ref[ok]) ** 2)) < 0.25


def test_progress_bar_on_terminal(small_stack, tmp_path, monkeypatch, capsys):
    d, _ = small_stack
    monkeypatch.setattr(sys.stderr, "isatty", lambda: True, raising=False)
    assert main(["height", str(d), "--out", str(tmp_path / "o")]) == 0
    err = capsys.readouterr().err
    assert "13/13 slices" in err


def test_options_overridden_by_stack_json_are_ignored_with_a_warning(batch_drawer, tmp_path,
                                                                     caplog):
    out = tmp_path / "o"
    assert main(["height", str(batch_drawer / "a"), "--out", str(out), "--z-step-um", "7",
                 "--pixel-size-um", "9"]) == 0
    err = [r.getMessage() for r in caplog.records if "ignored" in r.getMessage()]
    assert len(err) == 2 and all("ignored" in line and "stack.json" in line for line in err)
    assert "--z-step-um 7" in err[0] + err[1] and "--pixel-size-um 9" in err[0] + err[1]
    meta = json.loads((out / "height.json").read_text())
    assert meta["pixel_size_um"] != 9.0
