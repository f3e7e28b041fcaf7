"""Height from focus into a folder (microfacet.workflow.height.height_to_folder): what it
writes, the checks before any work, and that nothing half-written is left. The command line
on top of it: tests/cli/test_height.py."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from microfacet.core.errors import InputError
from microfacet.focus.height import height_from_focus
from microfacet.focus.normals import normals_from_height
from microfacet.focus.options import FocusOptions
from microfacet.io.height_folder import HEIGHT_FILES
from microfacet.io.outdir import output_kind
from microfacet.io.stack import StackSource, read_stack, write_stack
from microfacet.workflow import HeightOutput, height_to_folder

COU = (Path(__file__).resolve().parents[2] / "fixtures" / "focus-stacks"
       / "cou2023-synthetic-rough")


@pytest.fixture()
def stack(tmp_path, render_stack):
    """A grey 8-bit stack of a tilted plane (height 1..4 µm across x), pixel 0.5 µm: its
    stack.json."""
    h = np.add.outer(np.zeros(32), np.linspace(1.0, 4.0, 40)).astype(np.float32)
    z = np.arange(0.0, 5.5, 0.5)
    imgs = render_stack(h, z, seed=3)
    return write_stack(tmp_path / "stack", [np.round(im * 255).astype(np.uint8) for im in imgs],
                       z_um=z, pixel_size_um=0.5)


def _partials(folder: Path):
    return [p.name for p in folder.iterdir() if p.name.startswith(".")]


def test_writes_the_height_folder(stack, tmp_path):
    out = tmp_path / "h"
    opts = FocusOptions(operator="sml", fill="smooth")
    seen = []
    res = height_to_folder(stack, out, options=opts, smooth_sigma_px=1.0,
                           progress=lambda k, n: seen.append((k, n)))
    assert isinstance(res, HeightOutput)
    assert res.out == out and res.stack == stack.parent and res.n_slices == 11
    assert res.shape == (32, 40) and 0.0 <= res.unreliable_fraction < 0.2
    assert seen == [(k, 11) for k in range(1, 12)]
    assert set(HEIGHT_FILES) | {"height.json"} == {p.name for p in out.iterdir()}
    assert output_kind(out) == "height" and not _partials(tmp_path)

    # the maps are those of height_from_focus with the same options
    ref = height_from_focus(read_stack(stack), opts)
    hu = np.load(out / "height_um.npy")
    np.testing.assert_array_equal(hu, ref.height_um)
    np.testing.assert_array_equal(np.load(out / "reliability_db.npy"), ref.reliability_db)
    np.testing.assert_allclose(np.load(out / "normals.npy"),
                               normals_from_height(hu, pixel_size_um=0.5, smooth_sigma_px=1.0))
    meta = json.loads((out / "height.json").read_text())
    assert meta["format"] == "microfacet-height/1"
    assert meta["parameters"] == {**ref.params, "smooth_sigma_px": 1.0}
    assert meta["parameters"]["operator"] == "sml" and meta["parameters"]["fill"] == "smooth"
    assert meta["stats"]["unreliable_fraction"] == res.unreliable_fraction
    assert meta["timings_s"] == res.timings_s and res.timings_s["total"] > 0


@pytest.mark.slow
def test_plain_folder_as_a_stack_source(tmp_path):
    d = tmp_path / "plain"
    d.mkdir()
    for i in (1, 2, 3, 10, 11):         # natural order: 1, 2, 3, 10, 11
        shutil.copy(COU / "stack1" / f"image_{i + 15}.jpg", d / f"image_{i}.jpg")
    res = height_to_folder(StackSource(d, pixel_size_um=2.0, z_step_um=1.0), tmp_path / "o")
    meta = json.loads((tmp_path / "o" / "height.json").read_text())
    assert res.n_slices == meta["n_slices"] == 5 and meta["pixel_size_um"] == 2.0
    assert meta["z_um_range"] == [0.0, 4.0]


def test_overwrites_only_an_earlier_height_folder(stack, tmp_path):
    out = tmp_path / "h"
    height_to_folder(stack, out)
    with pytest.raises(InputError) as exc:
        height_to_folder(stack, out)
    assert exc.value.param == "out" and "`overwrite`" in exc.value.raw_reason
    height_to_folder(stack, out, options=FocusOptions(window_px=5), overwrite=True)
    assert json.loads((out / "height.json").read_text())["parameters"]["window_px"] == 5
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "keep.txt").write_text("x")
    with pytest.raises(InputError, match="never replaced"):
        height_to_folder(stack, mine, overwrite=True)
    assert (mine / "keep.txt").read_text() == "x"


def test_checks_before_any_work(stack, tmp_path):
    out = tmp_path / "h"
    with pytest.raises(InputError) as exc:
        height_to_folder(stack, out, smooth_sigma_px=-1.0)
    assert exc.value.param == "smooth_sigma_px"
    # the output folder is checked before the stack is read
    with pytest.raises(InputError) as exc:
        height_to_folder(tmp_path / "nowhere", stack)
    assert exc.value.param == "out"
    two = write_stack(tmp_path / "two", [np.zeros((8, 8), np.uint8)] * 2, z_step_um=1.0,
                      pixel_size_um=1.0)
    with pytest.raises(InputError, match="at least 3 slices"):
        height_to_folder(two, out)
    assert not out.exists() and not _partials(tmp_path)


def test_export_without_slices_is_refused(tmp_path):
    export = Path(__file__).resolve().parents[2] / "fixtures" / "exports" / "nd-x3p"
    with pytest.raises(InputError, match="without slices"):
        height_to_folder(export, tmp_path / "h")
    assert not (tmp_path / "h").exists()


def test_failure_leaves_nothing(stack, tmp_path):
    out = tmp_path / "h"

    def stop(k, n):
        if k == 5:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        height_to_folder(stack, out, progress=stop)
    assert not out.exists() and not _partials(tmp_path)
