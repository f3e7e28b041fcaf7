"""Tests of the stack reader and writer (microfacet.io.stack) on small stacks written in
tmp_path. What ``stack.json`` validation refuses: tests/io/test_stack_checks.py."""

from __future__ import annotations

import json
import tracemalloc

import cv2
import numpy as np
import pytest
import tifffile

from microfacet.core.errors import InputError
from microfacet.io.stack import FORMAT, read_stack, write_stack, write_stack_json

H, W = 12, 17  # the size of the random_images fixture (tests/io/conftest.py)


@pytest.mark.parametrize("fmt,dtype,rgb", [
    ("png", np.uint8, False), ("png", np.uint8, True),
    ("png", np.uint16, False), ("png", np.uint16, True),
    ("tif", np.uint8, False), ("tif", np.uint16, True),
])
def test_lossless_round_trip(tmp_path, random_images, fmt, dtype, rgb):
    imgs = random_images(4, dtype=dtype, rgb=rgb)
    z = [3.0, 0.5, 2.0, 1.0]
    write_stack(tmp_path / "s", imgs, z_um=z, pixel_size_um=0.25, fmt=fmt)
    st = read_stack(tmp_path / "s")
    assert st.shape == (H, W) and st.n_slices == 4
    assert st.dtype == np.dtype(dtype) and st.channels == (3 if rgb else 1)
    assert st.pixel_size_um == 0.25
    np.testing.assert_array_equal(st.z_um, z)
    got = list(st.iter_slices(dtype=np.uint16 if dtype == np.uint16 else np.uint8))
    assert [g[0] for g in got] == [0, 1, 2, 3]
    for (i, zi, im), ref in zip(got, imgs):
        assert zi == z[i]
        np.testing.assert_array_equal(im, ref)   # RGB order preserved, not BGR
    # float32 scaled to [0, 1]
    i, zi, f = next(st.iter_slices())
    assert f.dtype == np.float32
    np.testing.assert_allclose(f, imgs[0] / (255.0 if dtype == np.uint8 else 65535.0), rtol=1e-6)
    # z order
    assert [i for i, _, _ in st.iter_slices(order="z")] == [1, 3, 2, 0]


def test_rgb_channel_order_png(tmp_path):
    img = np.zeros((H, W, 3), np.uint8)
    img[..., 0] = 200  # pure red
    write_stack(tmp_path / "s", [img, img, img], z_step_um=1.0, pixel_size_um=1.0)
    im = read_stack(tmp_path / "s").read_slice(0, np.uint8)
    assert im[0, 0].tolist() == [200, 0, 0]


def test_jpeg_grey_and_rgb(tmp_path):
    for rgb in (False, True):
        imgs = [np.full((H, W, 3) if rgb else (H, W), 40 * i + 20, np.uint8) for i in range(3)]
        d = tmp_path / f"j{rgb}"
        write_stack(d, imgs, z_step_um=2.0, pixel_size_um=1.0, fmt="jpg")
        st = read_stack(d)
        assert st.channels == (3 if rgb else 1) and st.dtype == np.uint8
        np.testing.assert_array_equal(st.z_um, [0.0, 2.0, 4.0])
        for (i, _, im), ref in zip(st.iter_slices(np.uint8), imgs):
            assert np.abs(im.astype(int) - ref).max() <= 2  # lossy but flat images survive


def test_multipage_tiff(tmp_path, random_images):
    imgs = random_images(5, dtype=np.uint16, rgb=True)
    write_stack(tmp_path / "s", imgs, z_step_um=-0.5, pixel_size_um=2.0, multipage=True)
    st = read_stack(tmp_path / "s")
    assert st.tiff_path is not None and st.n_slices == 5 and st.channels == 3
    np.testing.assert_array_equal(st.z_um, [0, -0.5, -1.0, -1.5, -2.0])
    for (i, _, im), ref in zip(st.iter_slices(np.uint16), imgs):
        np.testing.assert_array_equal(im, ref)
    assert [i for i, _, _ in st.iter_slices(order="z")] == [4, 3, 2, 1, 0]


def test_multipage_tiff_z_mismatch(tmp_path, random_images):
    d = tmp_path / "s"
    write_stack(d, random_images(3), z_step_um=1.0, pixel_size_um=1.0, multipage=True)
    write_stack_json(d, pixel_size_um=1.0, tiff="stack.tif", z_um=[0, 1], validate=False)
    with pytest.raises(InputError, match=r"z_um.*2 values.*3 pages"):
        read_stack(d)


def test_export_only(tmp_path):
    d = tmp_path / "e"
    d.mkdir()
    h = np.linspace(0, 5, H * W, dtype=np.float32).reshape(H, W)
    np.save(d / "height.npy", h)
    cv2.imwrite(str(d / "aif.png"), np.zeros((H, W, 3), np.uint8))
    write_stack_json(d, pixel_size_um=0.5, height_um="height.npy", image="aif.png")
    st = read_stack(d)
    assert not st.has_slices and st.has_export and st.channels == 3
    np.testing.assert_array_equal(st.read_export_height(), h)
    assert st.read_export_image().shape == (H, W, 3)
    # TIFF height
    tifffile.imwrite(d / "height.tif", h)
    write_stack_json(d, pixel_size_um=0.5, height_um="height.tif", image="aif.png")
    np.testing.assert_array_equal(read_stack(d).read_export_height(), h)
    # size mismatch between export height and image
    np.save(d / "small.npy", h[:5])
    write_stack_json(d, pixel_size_um=0.5, height_um="small.npy", image="aif.png", validate=False)
    with pytest.raises(InputError, match="image"):
        read_stack(d)
    # integer height map refused
    np.save(d / "int.npy", np.zeros((H, W), np.int32))
    write_stack_json(d, pixel_size_um=0.5, height_um="int.npy", image="aif.png", validate=False)
    with pytest.raises(InputError, match="height_um.*floating"):
        read_stack(d)


def test_optional_keys(tmp_path, random_images):
    from microfacet import optics

    d = tmp_path / "s"
    write_stack(d, random_images(3), z_step_um=1.0, pixel_size_um=1.0)
    st = read_stack(d)
    assert st.color_space == "sRGB" and st.illuminant == "D65"
    assert st.numerical_aperture == 0.8 and st.illumination["geometry"] == "coaxial"
    assert st.film == optics.DEFAULT_FILM and st.substrate == optics.DEFAULT_SUBSTRATE
    assert st.exposure is None
    sets = optics.known_sets()
    film = [s for s in sets if s.startswith("TiO2")][-1]
    write_stack_json(d, pixel_size_um=1.0, slices=[f"slices/{i:03d}.png" for i in range(3)],
                     z_step_um=1.0, color_space="linear-sRGB", illuminant="A",
                     illumination={"numerical_aperture": 0.5}, film=film, exposure=1.7)
    st = read_stack(d)
    assert (st.color_space, st.illuminant, st.numerical_aperture, st.film, st.exposure) == \
        ("linear-sRGB", "A", 0.5, film, 1.7)
    assert st.illumination["geometry"] == "coaxial"


def test_corrupt_data_found_on_decode(good_stack):
    """A PNG with intact header and IEND but garbage inside passes the header check and is
    reported, naming the slice, when decoded."""
    d = good_stack()
    p = d / "slices/001.png"
    data = bytearray(p.read_bytes())
    for k in range(40, len(data) - 20):
        data[k] = 0x55
    p.write_bytes(bytes(data))
    st = read_stack(d)
    with pytest.raises(InputError, match=r"slice 1 .*001\.png"):
        list(st.iter_slices())


def test_write_stack_json_format(good_stack):
    d = good_stack()
    meta = json.loads((d / "stack.json").read_text())
    assert meta["format"] == FORMAT and meta["z_step_um"] == 1.0
    assert meta["slices"] == ["slices/000.png", "slices/001.png", "slices/002.png"]


@pytest.mark.slow
def test_lazy_reading_memory_does_not_grow(tmp_path):
    """Iterating a 40-slice stack holds about one slice, like a 10-slice stack."""
    big = (256, 256)
    rng = np.random.default_rng(0)
    img = rng.integers(0, 256, big + (3,)).astype(np.uint8)
    for n in (10, 40):
        write_stack(tmp_path / f"s{n}", (img for _ in range(n)), z_step_um=1.0,
                    pixel_size_um=1.0)
    peaks = {}
    for n in (10, 40):
        st = read_stack(tmp_path / f"s{n}")
        tracemalloc.start()
        total = 0.0
        for _, _, im in st.iter_slices():
            total += float(im[0, 0, 0])
        peaks[n] = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
    one = big[0] * big[1] * 3 * 4
    assert peaks[40] < 4 * one
    assert peaks[40] < 1.2 * peaks[10] + 64 * 1024


# -------------------------------------------------------------- a plain folder of images


def _plain_folder(d, names, *, rgb=False):
    """Images named ``names`` in ``d``, image k filled with the value 10 * (k + 1)."""
    d.mkdir()
    for k, name in enumerate(names):
        shape = (H, W, 3) if rgb else (H, W)
        cv2.imwrite(str(d / name), np.full(shape, 10 * (k + 1), np.uint8))
    return d


def _snapshot(d):
    return sorted((p.name, p.stat().st_size, p.stat().st_mtime_ns) for p in d.iterdir())


def test_plain_folder_in_natural_order_and_untouched(tmp_path):
    d = _plain_folder(tmp_path / "p", ["img_10.png", "img_2.png", "img_1.png", ".img_0.png"])
    (d / "notes.txt").write_text("objective 50x")
    before = _snapshot(d)
    st = read_stack(d, pixel_size_um=0.5, z_step_um=0.25)
    assert [p.name for p in st.slice_paths] == ["img_1.png", "img_2.png", "img_10.png"]
    np.testing.assert_array_equal(st.z_um, [0.0, 0.25, 0.5])
    assert st.pixel_size_um == 0.5 and st.pixel_size_yx_um == (0.5, 0.5)
    assert st.sources == {"pixel_size_um": "given", "z_um": "given"}
    # slice i is the file img_<i>: values 30 (img_1), 20 (img_2), 10 (img_10)
    assert [int(im[0, 0]) for _, _, im in st.iter_slices(np.uint8)] == [30, 20, 10]
    assert _snapshot(d) == before          # nothing written into the folder


def test_plain_folder_without_values_names_the_options(tmp_path):
    d = _plain_folder(tmp_path / "p", ["a.png", "b.png", "c.png"])
    with pytest.raises(InputError) as ei:
        read_stack(d)
    msg = ei.value.cli_message()
    assert "\n" not in msg and "missing stack.json" in msg and "microfacet init" in msg
    assert "--pixel-size-um" in msg and "--z-step-um" in msg
    assert "pixel_size_um" in str(ei.value) and "--" not in str(ei.value)  # library wording
    with pytest.raises(InputError) as ei:
        read_stack(d, pixel_size_um=1.0)
    assert "--z-step-um" in ei.value.cli_message()
    assert "--pixel-size-um" not in ei.value.cli_message()
    with pytest.raises(InputError, match=r"missing stack\.json"):
        read_stack(_plain_folder(tmp_path / "empty", []), pixel_size_um=1.0, z_step_um=1.0)


def _imagej_stack(path, n=4, *, px=(0.25, 0.25), spacing=0.5, unit="um", rgb=False):
    shape = (n, H, W, 3) if rgb else (n, H, W)
    data = np.arange(n, dtype=np.uint8)[:, None, None] * 20 + np.zeros(shape, np.uint8)
    if rgb:
        data = data.reshape(shape)
    tifffile.imwrite(path, data, imagej=True, resolution=(1 / px[1], 1 / px[0]),
                     photometric="rgb" if rgb else "minisblack",
                     metadata={"spacing": spacing, "unit": unit,
                               "axes": "ZYXS" if rgb else "ZYX"})
    return data


def test_imagej_multipage_metadata(tmp_path):
    d = tmp_path / "ij"
    d.mkdir()
    data = _imagej_stack(d / "stack.tif", 5, px=(0.216, 0.216), spacing=0.4)
    st = read_stack(d)
    assert st.tiff_path.name == "stack.tif" and st.n_slices == 5
    assert st.pixel_size_um == pytest.approx(0.216, rel=1e-6)
    np.testing.assert_allclose(st.z_um, np.arange(5) * 0.4)
    assert st.sources == {"pixel_size_um": "ImageJ metadata of stack.tif",
                          "z_um": "ImageJ metadata of stack.tif"}
    for (i, _, im), ref in zip(st.iter_slices(np.uint8), data):
        np.testing.assert_array_equal(im, ref)


def test_ome_multipage_metadata_with_units(tmp_path):
    d = tmp_path / "ome"
    d.mkdir()
    tifffile.imwrite(d / "s.ome.tif", np.zeros((3, H, W), np.uint16), ome=True,
                     metadata={"axes": "ZYX", "PhysicalSizeX": 0.3, "PhysicalSizeY": 0.3,
                               "PhysicalSizeZ": 1500, "PhysicalSizeZUnit": "nm"})
    st = read_stack(d)
    assert st.pixel_size_um == pytest.approx(0.3)
    np.testing.assert_allclose(st.z_um, [0.0, 1.5, 3.0])
    assert st.sources["z_um"] == "OME metadata of s.ome.tif"


def test_per_slice_tiffs_metadata(tmp_path):
    d = tmp_path / "slices"
    d.mkdir()
    for i in (0, 1, 2, 11):
        tifffile.imwrite(d / f"z{i}.tif", np.full((H, W), i, np.uint8), imagej=True,
                         resolution=(2.0, 2.0), metadata={"spacing": 0.75, "unit": "micron"})
    st = read_stack(d)
    assert [p.name for p in st.slice_paths] == ["z0.tif", "z1.tif", "z2.tif", "z11.tif"]
    assert st.pixel_size_um == 0.5
    np.testing.assert_allclose(st.z_um, [0.0, 0.75, 1.5, 2.25])


def test_precedence_stack_json_then_given_then_metadata(tmp_path, caplog):
    d = tmp_path / "ij"
    d.mkdir()
    _imagej_stack(d / "stack.tif", 3, px=(0.25, 0.25), spacing=0.5)
    st = read_stack(d, pixel_size_um=0.4)                   # given beats metadata
    assert st.pixel_size_um == 0.4 and st.sources["pixel_size_um"] == "given"
    assert st.sources["z_um"] == "ImageJ metadata of stack.tif"
    st = read_stack(d, z_step_um=2.0)
    np.testing.assert_array_equal(st.z_um, [0.0, 2.0, 4.0])
    assert st.pixel_size_um == 0.25
    # stack.json beats both; the overridden given value is warned about
    write_stack_json(d, pixel_size_um=0.1, tiff="stack.tif", z_step_um=3.0)
    st = read_stack(d, pixel_size_um=0.4, z_step_um=2.0)
    assert st.pixel_size_um == 0.1 and st.sources["pixel_size_um"] == "stack.json"
    np.testing.assert_array_equal(st.z_um, [0.0, 3.0, 6.0])
    assert "key 'pixel_size_um': 0.1 µm is used, not the given 0.4 µm" in caplog.text
    # a stack.json without pixel size takes the metadata's
    write_stack_json(d, tiff="stack.tif", z_step_um=3.0)
    st = read_stack(d)
    assert st.pixel_size_um == 0.25 and st.sources["z_um"] == "stack.json"


def test_non_square_pixels_read_as_a_pair(tmp_path, random_images):
    d = tmp_path / "s"
    write_stack(d, random_images(3), z_step_um=1.0, pixel_size_um=[0.2, 0.3])
    st = read_stack(d)
    assert st.pixel_size_yx_um == (0.2, 0.3) and not st.square_pixels
    assert json.loads((d / "stack.json").read_text())["pixel_size_um"] == [0.2, 0.3]
    assert st.pixel_size_um == [0.2, 0.3]             # the value as stack.json writes it
    assert len(list(st.iter_slices())) == 3          # the slices themselves are read
    write_stack_json(d, pixel_size_um=[0.25, 0.25], z_step_um=1.0,
                     slices=[f"slices/{i:03d}.png" for i in range(3)])
    assert read_stack(d).pixel_size_um == 0.25       # [y, x] equal: square
    # non-square from ImageJ metadata too
    e = tmp_path / "ij"
    e.mkdir()
    _imagej_stack(e / "stack.tif", 3, px=(0.3, 0.25), spacing=0.5)
    st = read_stack(e)
    assert st.pixel_size_yx_um == pytest.approx((0.3, 0.25))
    assert st.sources["pixel_size_um"] == "ImageJ metadata of stack.tif"


# -------------------------------------------------------------- write_stack_json


def test_write_stack_json_finds_the_images(tmp_path):
    d = _plain_folder(tmp_path / "p", ["s_10.png", "s_9.png", "s_1.png"])
    path = write_stack_json(d, pixel_size_um=0.5, z_step_um=1.0)
    meta = json.loads(path.read_text())
    assert meta["slices"] == ["s_1.png", "s_9.png", "s_10.png"]
    assert read_stack(d).n_slices == 3
    assert sorted(p.name for p in d.iterdir()) == ["s_1.png", "s_10.png", "s_9.png",
                                                    "stack.json"]
    # one TIFF: a multi-page stack
    e = tmp_path / "t"
    e.mkdir()
    _imagej_stack(e / "all.tif", 3)
    assert json.loads(write_stack_json(e, pixel_size_um=1.0, z_step_um=1.0).read_text())[
        "tiff"] == "all.tif"


def test_write_stack_json_never_leaves_an_invalid_file(tmp_path):
    d = _plain_folder(tmp_path / "p", ["a.png", "b.png", "c.png"])
    cv2.imwrite(str(d / "b.png"), np.zeros((H + 1, W), np.uint8))   # another size
    with pytest.raises(InputError, match=r"stack\.json: slices\[1\] \(b\.png\): size"):
        write_stack_json(d, pixel_size_um=0.5, z_step_um=1.0)
    assert sorted(p.name for p in d.iterdir()) == ["a.png", "b.png", "c.png"]
    # an existing valid stack.json is replaced only by a valid one
    cv2.imwrite(str(d / "b.png"), np.zeros((H, W), np.uint8))
    write_stack_json(d, pixel_size_um=0.5, z_step_um=1.0)
    good = (d / "stack.json").read_bytes()
    with pytest.raises(InputError, match="key 'z_step_um'"):
        write_stack_json(d, pixel_size_um=0.5, z_step_um=0.0)
    assert (d / "stack.json").read_bytes() == good
    assert sorted(p.name for p in d.iterdir()) == ["a.png", "b.png", "c.png", "stack.json"]
    with pytest.raises(InputError, match="no images"):
        write_stack_json(_plain_folder(tmp_path / "e", []), pixel_size_um=1.0, z_step_um=1.0)


# -------------------------------------------------------------- instrument export files


class _HeightMap:
    def __init__(self, height_um, pixel_size_um, source):
        self.height_um, self.pixel_size_um, self.source = height_um, pixel_size_um, source


def _export_with(d, name):
    d.mkdir()
    (d / name).write_bytes(b"instrument bytes")
    cv2.imwrite(str(d / "aif.png"), np.zeros((H, W, 3), np.uint8))
    (d / "stack.json").write_text(json.dumps({"format": FORMAT, "height_um": name,
                                              "image": "aif.png"}))
    return d


def test_instrument_export_through_read_height_map(tmp_path, monkeypatch):
    """Any other extension goes to microfacet.io.instruments.read_height_map (a stand-in
    here, so that the stack side is tested whatever that module reads); its pixel size
    replaces a missing ``pixel_size_um``."""
    import sys
    import types

    h = np.linspace(0, 3, H * W, dtype=np.float32).reshape(H, W)
    h[0, 0] = np.nan
    calls = []

    def read_height_map(path):
        calls.append(path.name)
        return _HeightMap(h.copy(), (0.4, 0.4), "stand-in")

    fake = types.ModuleType("microfacet.io.instruments")
    fake.read_height_map = read_height_map
    monkeypatch.setitem(sys.modules, "microfacet.io.instruments", fake)
    d = _export_with(tmp_path / "e", "map.sur")
    st = read_stack(d)
    assert st.has_export and not st.has_slices and st.shape == (H, W)
    assert st.pixel_size_um == 0.4 and st.sources["pixel_size_um"] == "instrument file map.sur"
    np.testing.assert_array_equal(st.read_export_height(), h)
    assert calls == ["map.sur", "map.sur"]
    # stack.json's pixel size wins
    meta = json.loads((d / "stack.json").read_text())
    (d / "stack.json").write_text(json.dumps({**meta, "pixel_size_um": 0.5}))
    assert read_stack(d).pixel_size_um == 0.5
    # a map of another size than the image is refused naming the key
    fake.read_height_map = lambda path: _HeightMap(h[:5], None, "stand-in")
    with pytest.raises(InputError, match=r"key 'image'.*does not match the height map"):
        read_stack(d)
    # its errors become one line naming the key
    def broken(path):
        raise InputError(f"{path}: not a Digital Surf file")
    fake.read_height_map = broken
    with pytest.raises(InputError, match=r"key 'height_um' \(map\.sur\): .*not a Digital Surf"):
        read_stack(d)


def test_instrument_export_without_the_module(tmp_path, monkeypatch):
    import sys

    monkeypatch.setitem(sys.modules, "microfacet.io.instruments", None)
    d = _export_with(tmp_path / "e", "map.xyz")
    with pytest.raises(InputError, match=r"key 'height_um' \(map\.xyz\): height map must be a "
                                         r"TIFF or \.npy"):
        read_stack(d)


def test_instrument_export_real_reader(tmp_path):
    """An ISO 25178-72 ``.x3p`` export read by the real microfacet.io.instruments."""
    pytest.importorskip("microfacet.io.instruments",
                        reason="microfacet.io.instruments (instrument height maps) not there yet")
    x3p = pytest.importorskip("microfacet.io.x3p", reason="microfacet.io.x3p not there yet")
    d = tmp_path / "e"
    d.mkdir()
    h = np.linspace(0, 3, H * W, dtype=np.float32).reshape(H, W)
    h[2, 3] = np.nan
    x3p.write_x3p(d / "map.x3p", h, (0.3, 0.3))
    cv2.imwrite(str(d / "aif.png"), np.zeros((H, W, 3), np.uint8))
    write_stack_json(d, height_um="map.x3p", image="aif.png")   # no pixel_size_um
    st = read_stack(d)
    assert "pixel_size_um" not in json.loads((d / "stack.json").read_text())
    assert st.pixel_size_um == pytest.approx(0.3)
    np.testing.assert_allclose(st.read_export_height(), h, rtol=1e-6, equal_nan=True)
