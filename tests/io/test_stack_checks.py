"""Validation of ``stack.json`` before any work (microfacet.io.stack_checks, through
:func:`~microfacet.io.stack.read_stack`): every bad key, missing or truncated image and
inconsistent slice is refused with one line naming the file and the key or slice.

The same cases end to end through the command line: tests/cli/test_bad_input.py.
"""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest

from microfacet.core.errors import InputError
from microfacet.io.stack import read_stack

H, W = 12, 17  # the size of the random_images fixture (tests/io/conftest.py)


def _patch(d, **changes):
    meta = json.loads((d / "stack.json").read_text())
    for k, v in changes.items():
        if v is _DEL:
            meta.pop(k, None)
        else:
            meta[k] = v
    (d / "stack.json").write_text(json.dumps(meta))


_DEL = object()


@pytest.mark.parametrize("changes,pattern", [
    ({"format": "microfacet-stack/2"}, r"stack\.json: key 'format'"),
    ({"format": _DEL}, r"key 'format': missing"),
    ({"pixel_size_um": _DEL}, r"key 'pixel_size_um': missing"),
    ({"pixel_size_um": -1.0}, r"key 'pixel_size_um'.*> 0"),
    ({"pixel_size_um": 0}, r"key 'pixel_size_um'"),
    ({"pixel_size_um": "1"}, r"key 'pixel_size_um'"),
    ({"pixel_size_um": True}, r"key 'pixel_size_um'"),
    ({"z_step_um": _DEL}, r"key 'z_um': missing"),
    ({"z_step_um": _DEL, "z_um": [0, 1]}, r"key 'z_um'.*2 values.*3 slices"),
    ({"z_step_um": _DEL, "z_um": [0, 1, None]}, r"key 'z_um'\[2\]"),
    ({"z_step_um": _DEL, "z_um": [0, 1, 1]}, r"key 'z_um': duplicate"),
    ({"z_step_um": 0}, r"key 'z_step_um'"),
    ({"z_um": [0, 1, 2]}, r"not both"),
    ({"slices": ["slices/000.png", "../outside.png", "slices/002.png"]},
     r"key 'slices'\[1\].*escapes the stack folder"),
    ({"slices": ["slices/000.png", "/etc/passwd", "slices/002.png"]}, r"'slices'\[1\].*absolute"),
    ({"slices": ["slices/000.png", "slices/missing.png", "slices/002.png"]},
     r"'slices'\[1\].*not found"),
    ({"slices": []}, r"key 'slices'"),
    ({"slices": _DEL}, r"key 'slices': missing"),
    ({"film": "TiO2_Nonexistent"}, r"key 'film'.*unknown.*TiO2_"),
    ({"substrate": "Unobtainium"}, r"key 'substrate'.*unknown"),
    ({"color_space": "AdobeRGB"}, r"key 'color_space'"),
    ({"illumination": {"numerical_aperture": 1.5}}, r"key 'illumination'"),
    ({"exposure": float("nan")}, r"key 'exposure'"),
    ({"height_um": "x.npy"}, r"key 'image': missing"),
])
def test_bad_stack_json(tmp_path, good_stack, changes, pattern):
    d = good_stack()
    (tmp_path / "outside.png").write_bytes((d / "slices/000.png").read_bytes())
    _patch(d, **changes)
    with pytest.raises(InputError, match=pattern) as ei:
        read_stack(d)
    assert "\n" not in str(ei.value)


def test_missing_and_invalid_json(tmp_path, good_stack):
    with pytest.raises(InputError, match="not found"):
        read_stack(tmp_path / "nope")
    (tmp_path / "empty").mkdir()
    with pytest.raises(InputError, match=r"empty.*missing stack\.json"):
        read_stack(tmp_path / "empty")
    d = good_stack()
    (d / "stack.json").write_text("{not json")
    with pytest.raises(InputError, match=r"stack\.json: invalid JSON"):
        read_stack(d)
    (d / "stack.json").write_text("[1, 2]")
    with pytest.raises(InputError, match="JSON object"):
        read_stack(d / "stack.json")


@pytest.mark.parametrize("fmt", ["png", "jpg", "tif"])
def test_truncated_image(good_stack, fmt):
    d = good_stack(fmt=fmt)
    p = d / f"slices/001.{fmt}"
    data = p.read_bytes()
    p.write_bytes(data[: len(data) * 2 // 3])
    with pytest.raises(InputError, match=rf"'slices'\[1\] \(001\.{fmt}\).*truncated"):
        read_stack(d)


def test_truncated_multipage_tiff(good_stack):
    d = good_stack(multipage=True)
    p = d / "stack.tif"
    data = p.read_bytes()
    p.write_bytes(data[: len(data) - 50])
    with pytest.raises(InputError, match=r"tiff.*(truncated|unreadable)"):
        read_stack(d)


def test_not_an_image(good_stack):
    d = good_stack()
    (d / "slices/002.png").write_bytes(b"hello world, not a png at all" * 3)
    with pytest.raises(InputError, match=r"'slices'\[2\].*not a PNG"):
        read_stack(d)
    (d / "slices/002.bmp").write_bytes(b"BM")
    _patch(d, slices=["slices/000.png", "slices/001.png", "slices/002.bmp"])
    with pytest.raises(InputError, match=r"'slices'\[2\].*unsupported image type"):
        read_stack(d)


def test_mismatched_sizes_depths_channels(good_stack):
    d = good_stack()
    cv2.imwrite(str(d / "slices/001.png"), np.zeros((H + 1, W), np.uint8))
    with pytest.raises(InputError, match=r"slices\[1\] \(001\.png\): size"):
        read_stack(d)
    cv2.imwrite(str(d / "slices/001.png"), np.zeros((H, W), np.uint16))
    with pytest.raises(InputError, match=r"slices\[1\].*mixed bit depths"):
        read_stack(d)
    cv2.imwrite(str(d / "slices/001.png"), np.zeros((H, W, 3), np.uint8))
    with pytest.raises(InputError, match=r"slices\[1\].*mixed grey and colour"):
        read_stack(d)


@pytest.mark.parametrize("value", [[0.2], [0.2, -1.0], [0.1, 0.2, 0.3], [], ["0.2", 0.2],
                                   [0.2, float("inf")]])
def test_bad_pixel_size_pair(good_stack, value):
    d = good_stack()
    _patch(d, pixel_size_um=value)
    if value == [0.2]:                       # one value in a list: a square pixel
        assert read_stack(d).pixel_size_yx_um == (0.2, 0.2)
        return
    with pytest.raises(InputError, match=r"stack\.json: key 'pixel_size_um': must be a finite "
                                         r"number > 0.*\[y, x\]"):
        read_stack(d)


def test_unknown_keys_warn_with_the_nearest_known_key(good_stack, caplog):
    d = good_stack()
    _patch(d, colour_space="sRGB", numerical_apperture=0.5, operator="Ada",
           illumination={"geometry": "coaxial", "numerical_apperture": 0.5})
    st = read_stack(d)
    assert st.meta["operator"] == "Ada"                  # kept
    lines = [r.getMessage() for r in caplog.records if r.levelname == "WARNING"]
    assert all("\n" not in line for line in lines)
    text = "\n".join(lines)
    assert "unknown key 'colour_space'; did you mean 'color_space'?" in text
    assert "unknown key 'numerical_apperture'; did you mean 'numerical_aperture'?" in text
    assert "key 'illumination': unknown key 'numerical_apperture'; did you mean " \
           "'numerical_aperture'?" in text
    assert "unknown key 'operator' (kept, not used)" in text
    assert len(lines) == 4


@pytest.mark.parametrize("kw,option", [({"pixel_size_um": -1.0}, "--pixel-size-um"),
                                       ({"pixel_size_um": float("nan")}, "--pixel-size-um"),
                                       ({"z_step_um": 0.0}, "--z-step-um")])
def test_bad_given_values_name_the_option(tmp_path, kw, option):
    d = tmp_path / "p"
    d.mkdir()
    for i in range(3):
        cv2.imwrite(str(d / f"{i}.png"), np.zeros((H, W), np.uint8))
    values = {"pixel_size_um": 1.0, "z_step_um": 1.0, **kw}
    with pytest.raises(InputError) as ei:
        read_stack(d, **values)
    assert ei.value.cli_message().startswith(f"{option}: must be a finite number")




def test_an_export_only_stack_does_not_read_the_z_keys(tmp_path):
    """``z_um`` and ``z_step_um`` are read only with slices (docs/stack-format.md)."""
    d = tmp_path / "e"
    d.mkdir()
    np.save(d / "h.npy", np.zeros((H, W), np.float32))
    cv2.imwrite(str(d / "aif.png"), np.zeros((H, W, 3), np.uint8))
    meta = {"format": "microfacet-stack/1", "pixel_size_um": 0.5, "height_um": "h.npy",
            "image": "aif.png", "z_um": "not read", "z_step_um": 0}
    (d / "stack.json").write_text(json.dumps(meta))
    st = read_stack(d)
    assert st.n_slices == 0 and st.sources == {"pixel_size_um": "stack.json"}


def test_null_is_absent_only_where_the_spec_says_so(good_stack):
    d = good_stack()
    _patch(d, exposure=None)
    assert read_stack(d).exposure is None
    _patch(d, color_space=None)
    with pytest.raises(InputError, match=r"key 'color_space': None is not one of"):
        read_stack(d)
