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
