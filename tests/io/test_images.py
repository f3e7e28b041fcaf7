"""Image files (microfacet.io.images): headers read without decoding, decoding, writing.

PNGs are written here byte by byte (signature, IHDR, PLTE, IDAT, IEND with zlib and CRC), an
encoder independent of OpenCV, so the header parser and the decoder are checked against
known pixels for every PNG colour type; JPEGs and TIFFs come from OpenCV and tifffile, and
their headers are compared with what decoding gives.
"""

from __future__ import annotations

import struct
import zlib

import cv2
import numpy as np
import pytest
import tifffile
from PIL import Image

from microfacet.core.errors import InputError
from microfacet.io.images import (
    ImageInfo,
    MultiPageTiff,
    convert_samples,
    decode_image,
    image_info,
    npy_info,
    png_pixel_size_um,
    read_png,
    read_tiff_headers,
    to_code_values,
    write_float_tiff,
    write_image,
)

H, W = 5, 7
WHERE = "slices[1] (x)"   # how callers name the file in messages


def _chunk(kind: bytes, data: bytes) -> bytes:
    return (struct.pack(">I", len(data)) + kind + data
            + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF))


def _png(samples: np.ndarray, colour_type: int, bit_depth: int = 8, palette=None) -> bytes:
    """A PNG of ``samples`` (H, W[, C]) written by hand: filter 0 on every row, 8- or 16-bit
    samples (big-endian), optional PLTE."""
    h, w = samples.shape[:2]
    raw = samples.astype(">u2" if bit_depth == 16 else np.uint8).reshape(h, -1) if h else []
    rows = b"".join(b"\x00" + r.tobytes() for r in raw)
    ihdr = struct.pack(">IIBBBBB", w, h, bit_depth, colour_type, 0, 0, 0)
    out = b"\x89PNG\r\n\x1a\n" + _chunk(b"IHDR", ihdr)
    if palette is not None:
        out += _chunk(b"PLTE", np.asarray(palette, np.uint8).tobytes())
    return out + _chunk(b"IDAT", zlib.compress(rows)) + _chunk(b"IEND", b"")


def _samples(channels, bit_depth, seed=0):
    rng = np.random.default_rng(seed)
    top = 65535 if bit_depth == 16 else 255
    shape = (H, W) if channels == 1 else (H, W, channels)
    return rng.integers(0, top + 1, shape).astype(np.uint16 if bit_depth == 16 else np.uint8)


# ------------------------------------------------------------------------------ PNG


@pytest.mark.parametrize("colour_type, channels_in, bit_depth, channels, dtype", [
    (0, 1, 8, 1, np.uint8),       # grey
    (0, 1, 16, 1, np.uint16),
    (4, 2, 8, 1, np.uint8),       # grey + alpha: grey
    (4, 2, 16, 1, np.uint16),
    (2, 3, 8, 3, np.uint8),       # RGB
    (2, 3, 16, 3, np.uint16),
    (6, 4, 8, 3, np.uint8),       # RGBA: RGB
    (6, 4, 16, 3, np.uint16),
])
def test_png_header_and_decoding_of_every_colour_type(tmp_path, colour_type, channels_in,
                                                      bit_depth, channels, dtype):
    s = _samples(channels_in, bit_depth)
    p = tmp_path / "x.png"
    p.write_bytes(_png(s, colour_type, bit_depth))
    info = image_info(p, WHERE)
    assert info == ImageInfo((H, W), np.dtype(dtype), channels)
    img = decode_image(p, WHERE, channels=info.channels)
    expected = s if channels_in in (1, 3) else s[..., :-1] if channels == 3 else s[..., 0]
    assert img.dtype == info.dtype and img.shape[:2] == info.shape
    assert (img.ndim == 2) == (info.channels == 1)
    np.testing.assert_array_equal(img, expected)        # values and RGB order


def test_palette_png(tmp_path):
    palette = np.array([[255, 0, 0], [0, 200, 0], [10, 20, 250], [7, 7, 7]], np.uint8)
    idx = np.random.default_rng(1).integers(0, 4, (H, W)).astype(np.uint8)
    p = tmp_path / "p.png"
    p.write_bytes(_png(idx, 3, 8, palette=palette.ravel()))
    info = image_info(p, WHERE)
    assert info == ImageInfo((H, W), np.dtype(np.uint8), 3)
    np.testing.assert_array_equal(decode_image(p, WHERE, channels=3), palette[idx])


def test_header_is_read_without_decoding(tmp_path):
    """Only the header and the last bytes are read: a PNG whose pixel data is garbage has a
    valid header (the garbage is found when decoding, naming the file)."""
    good = _png(_samples(3, 8), 2)
    bad = bytearray(good)
    start = 8 + 25 + 8                                  # signature, IHDR chunk, IDAT header
    bad[start:len(bad) - 16] = b"\x55" * (len(bad) - 16 - start)
    p = tmp_path / "g.png"
    p.write_bytes(bytes(bad))
    assert image_info(p, WHERE) == ImageInfo((H, W), np.dtype(np.uint8), 3)
    with pytest.raises(InputError, match=r"slices\[1\] \(x\): cannot decode"):
        decode_image(p, WHERE)


@pytest.mark.parametrize("cut, match", [
    (lambda b: b[:-12], r"truncated PNG"),                  # no IEND
    (lambda b: b[: len(b) // 2], r"truncated PNG"),
    (lambda b: b[:20], r"not a PNG"),                       # header cut inside IHDR
    (lambda b: b"GIF89a" + b[6:], r"not a PNG"),
])
def test_truncated_or_foreign_png_is_refused_naming_the_file(tmp_path, cut, match):
    p = tmp_path / "t.png"
    p.write_bytes(cut(_png(_samples(1, 8), 0)))
    with pytest.raises(InputError, match=rf"^slices\[1\] \(x\): {match}"):
        image_info(p, WHERE)


def test_png_of_zero_size_or_unknown_colour_type_is_refused(tmp_path):
    p = tmp_path / "z.png"
    p.write_bytes(_png(np.zeros((0, 3), np.uint8), 0))
    with pytest.raises(InputError, match="zero size"):
        image_info(p, WHERE)
    data = bytearray(_png(_samples(1, 8), 0))
    data[25] = 5                                         # colour type 5 does not exist
    p.write_bytes(bytes(data))
    with pytest.raises(InputError, match="colour type 5"):
        image_info(p, WHERE)


# ------------------------------------------------------------------------ JPEG and TIFF


@pytest.mark.parametrize("rgb", [False, True])
def test_jpeg_header_matches_decoding(tmp_path, rgb):
    img = np.full((H, W, 3) if rgb else (H, W), 90, np.uint8)
    p = tmp_path / "j.jpg"
    assert cv2.imwrite(str(p), img)
    info = image_info(p, WHERE)
    dec = decode_image(p, WHERE, channels=info.channels)
    assert info == ImageInfo(dec.shape[:2], dec.dtype, 1 if dec.ndim == 2 else 3, info.jpeg)
    assert info.channels == (3 if rgb else 1)
    assert info.jpeg.quality == 95                       # OpenCV's default
    # truncated: no end-of-image marker, and cut before the frame header
    data = p.read_bytes()
    p.write_bytes(data[: len(data) - 80])
    with pytest.raises(InputError, match=r"^slices\[1\] \(x\): truncated JPEG"):
        image_info(p, WHERE)
    p.write_bytes(data[:4])
    with pytest.raises(InputError, match=r"^slices\[1\] \(x\): truncated or corrupt JPEG"):
        image_info(p, WHERE)
    p.write_bytes(b"not a jpeg")
    with pytest.raises(InputError, match=r"not a JPEG"):
        image_info(p, WHERE)


@pytest.mark.parametrize("quality", [50, 70, 90, 97])
@pytest.mark.parametrize("writer", ["opencv", "pillow 4:4:4", "pillow grey"])
def test_jpeg_quantization_is_read_from_the_file(tmp_path, quality, writer):
    """The IJG quality and the DC steps, against the writers' own tables (Pillow reads them
    back independently); the chroma block is 16 × 16 pixels with 4:2:0 subsampling
    (OpenCV's default), 8 × 8 without."""
    img = np.random.default_rng(0).integers(0, 256, (32, 48, 3), dtype=np.uint8)
    p = tmp_path / "q.jpg"
    if writer == "opencv":
        assert cv2.imwrite(str(p), img, [cv2.IMWRITE_JPEG_QUALITY, quality])
    elif writer == "pillow grey":
        Image.fromarray(img[..., 0]).save(p, quality=quality)
    else:
        Image.fromarray(img).save(p, quality=quality, subsampling=0)
    jpeg = image_info(p, WHERE).jpeg
    with Image.open(p) as im:
        tables = im.quantization
    assert jpeg.quality == quality
    assert jpeg.dc_steps == (tables[0][0], tables[1][0] if 1 in tables else tables[0][0])
    assert jpeg.chroma_block_px == (256 if writer == "opencv" else 64)


def test_a_camera_s_own_jpeg_table_has_no_ijg_quality(tmp_path):
    img = np.random.default_rng(1).integers(0, 256, (16, 16, 3), dtype=np.uint8)
    p = tmp_path / "cam.jpg"
    own = [2 + (i % 7) for i in range(64)]
    Image.fromarray(img).save(p, qtables=[own, own], subsampling=0)
    jpeg = image_info(p, WHERE).jpeg
    assert jpeg.quality is None and jpeg.dc_steps == (2, 2)
    png = tmp_path / "a.png"
    cv2.imwrite(str(png), img)
    assert image_info(png, WHERE).jpeg is None


@pytest.mark.parametrize("shape, dtype, channels", [
    ((H, W), np.uint8, 1),
    ((H, W), np.uint16, 1),
    ((H, W, 3), np.uint8, 3),
    ((H, W, 3), np.uint16, 3),
    ((H, W, 4), np.uint8, 3),      # RGBA: RGB
])
def test_tiff_header_matches_decoding(tmp_path, shape, dtype, channels):
    top = np.iinfo(dtype).max
    img = np.random.default_rng(2).integers(0, top + 1, shape).astype(dtype)
    p = tmp_path / "t.tif"
    tifffile.imwrite(p, img, photometric="rgb" if len(shape) == 3 else "minisblack")
    info = image_info(p, WHERE)
    assert info == ImageInfo((H, W), np.dtype(dtype), channels)
    dec = decode_image(p, WHERE, channels=info.channels)
    np.testing.assert_array_equal(dec, img[..., :3] if len(shape) == 3 else img)
    data = p.read_bytes()
    p.write_bytes(data[: len(data) // 2])
    with pytest.raises(InputError, match=r"^slices\[1\] \(x\): (truncated|unreadable) TIFF"):
        image_info(p, WHERE)


def test_tiff_of_float_samples_is_refused(tmp_path):
    p = tmp_path / "f.tif"
    tifffile.imwrite(p, np.zeros((H, W), np.float32))
    with pytest.raises(InputError, match=r"TIFF sample type float32 is not supported"):
        image_info(p, WHERE)


def test_multi_page_tiff_headers_in_one_pass_and_pages_read(tmp_path):
    pages = np.random.default_rng(3).integers(0, 65536, (4, H, W, 3)).astype(np.uint16)
    p = tmp_path / "stack.tif"
    with tifffile.TiffWriter(p) as tw:
        for page in pages:
            tw.write(page, photometric="rgb")
    seen = []
    uniform = read_tiff_headers(p, "key 'tiff'", lambda *a: seen.append(a))
    assert uniform is True and len(seen) == 4
    assert [s[2] for s in seen] == [ImageInfo((H, W), np.dtype(np.uint16), 3)] * 4
    assert "page 3" in seen[3][1]
    mp = MultiPageTiff(p, uniform)
    try:
        for k in (2, 0, 3):
            np.testing.assert_array_equal(mp.read(k, f"page {k}", 3), pages[k])
        with pytest.raises(InputError, match="page 9: cannot decode"):
            mp.read(9, "page 9", 3)
    finally:
        mp.close()


def test_unsupported_suffix_and_unreadable_file(tmp_path):
    p = tmp_path / "x.bmp"
    p.write_bytes(b"BM")
    with pytest.raises(InputError, match=r"unsupported image type '\.bmp'"):
        image_info(p, WHERE)
    with pytest.raises(InputError, match=r"^slices\[1\] \(x\): cannot read"):
        image_info(tmp_path / "missing.png", WHERE)


# -------------------------------------------------------------------------------- npy


def test_npy_header_without_loading(tmp_path):
    a = np.zeros((6, 4), np.float32)
    p = tmp_path / "h.npy"
    np.save(p, a)
    assert npy_info(p, WHERE) == ((6, 4), np.dtype(np.float32))
    data = p.read_bytes()
    p.write_bytes(data[:-10])
    with pytest.raises(InputError, match=r"^slices\[1\] \(x\): truncated \.npy"):
        npy_info(p, WHERE)
    np.save(p, np.array([{"a": 1}], dtype=object), allow_pickle=True)
    with pytest.raises(InputError, match="Python objects"):
        npy_info(p, WHERE)
    p.write_bytes(b"not numpy")
    with pytest.raises(InputError, match="not a readable .npy"):
        npy_info(p, WHERE)


# ------------------------------------------------------------------------- writing


@pytest.mark.parametrize("channels, bit_depth", [(1, 8), (1, 16), (3, 8), (3, 16)])
def test_write_and_decode_round_trip(tmp_path, channels, bit_depth):
    s = _samples(channels, bit_depth, seed=4)
    p = tmp_path / "w.png"
    write_image(p, s)
    info = image_info(p, WHERE)
    assert info == ImageInfo((H, W), s.dtype, channels)
    np.testing.assert_array_equal(decode_image(p, WHERE, channels=channels), s)
    # floats are encoded values in [0, 1]: rounded to the nearest code value
    top = 65535 if bit_depth == 16 else 255
    write_image(p, s / top, bit_depth=bit_depth)
    np.testing.assert_array_equal(decode_image(p, WHERE, channels=channels), s)


def test_rgb_order_is_kept_on_disk(tmp_path):
    """The file is RGB for every other reader (here the hand-made parser's view: OpenCV's
    own reader gives BGR)."""
    img = np.zeros((H, W, 3), np.uint8)
    img[..., 0] = 200
    p = tmp_path / "red.png"
    write_image(p, img)
    assert cv2.imread(str(p))[0, 0].tolist() == [0, 0, 200]     # BGR in OpenCV
    assert decode_image(p, WHERE)[0, 0].tolist() == [200, 0, 0]


@pytest.mark.parametrize("bit_depth", [8, 16])
def test_code_values_worked_a_block_at_a_time_equal_the_whole_image_formula(tmp_path,
                                                                           bit_depth):
    """An image of several blocks of rows (BLOCK_VALUES) gets the code values of the formula
    applied to the whole image at once, NaN and ±inf included, and write_image writes them
    (in OpenCV's BGR order) as read back."""
    from microfacet.core.threads import BLOCK_VALUES

    rng = np.random.default_rng(9)
    rows = 3 * (BLOCK_VALUES // (40 * 3)) + 5
    img = rng.normal(0.5, 0.4, (rows, 40, 3)).astype(np.float32)
    img[1, 2, 0], img[-1, 3, 1], img[rows // 2, 0, 2] = np.nan, np.inf, -np.inf
    top = 255 if bit_depth == 8 else 65535
    ref = np.round(np.clip(np.nan_to_num(img, nan=0.0), 0, 1) * np.float32(top))
    ref = ref.astype(np.uint8 if bit_depth == 8 else np.uint16)
    np.testing.assert_array_equal(to_code_values(img, bit_depth=bit_depth), ref)
    write_image(tmp_path / "i.png", img, bit_depth=bit_depth, pixel_size_um=0.5)
    back = cv2.imread(str(tmp_path / "i.png"), cv2.IMREAD_UNCHANGED)[..., ::-1]
    np.testing.assert_array_equal(back, ref)


def test_to_code_values_clips_rounds_and_maps_nan_to_zero():
    x = np.array([-0.5, 0.0, 0.6 / 255, 0.4 / 255, 1.0, 2.0, np.nan])
    np.testing.assert_array_equal(to_code_values(x), [0, 0, 1, 0, 255, 255, 0])
    assert to_code_values(x, bit_depth=16).dtype == np.uint16
    assert to_code_values(np.array([0.5]), bit_depth=16)[0] == 32768
    ints = np.array([3, 400], np.uint16)
    assert to_code_values(ints) is ints
    before = x.copy()
    to_code_values(x)                                  # worked on a copy of its own
    np.testing.assert_array_equal(x, before)
    with pytest.raises(ValueError, match="bit_depth"):
        to_code_values(x, bit_depth=12)


def test_write_image_failure_names_the_path(tmp_path):
    with pytest.raises(OSError, match="cannot write .*nowhere"):
        write_image(tmp_path / "nowhere" / "a.png", np.zeros((H, W), np.uint8))


@pytest.mark.parametrize("channels, bit_depth", [(1, 8), (3, 8), (1, 16), (3, 16), (4, 8)])
def test_read_png_scales_to_0_1(tmp_path, channels, bit_depth):
    s = _samples(channels, bit_depth, seed=5)
    p = tmp_path / "r.png"
    p.write_bytes(_png(s, {1: 0, 3: 2, 4: 6}[channels], bit_depth))
    img = read_png(p)
    assert img.dtype == np.float32
    top = 65535.0 if bit_depth == 16 else 255.0
    expected = (s[..., :3] if channels == 4 else s) / top
    np.testing.assert_allclose(img, expected, rtol=1e-6, atol=0)
    assert img.min() >= 0 and img.max() <= 1
    np.testing.assert_allclose(convert_samples(s, np.float64), s / top)


def test_read_png_of_a_broken_file_names_it(tmp_path):
    p = tmp_path / "broken.png"
    p.write_bytes(b"\x89PNG\r\n\x1a\n" + b"\x00" * 40)
    with pytest.raises(InputError, match=r"broken\.png.*cannot decode"):
        read_png(p)


# ---------------------------------------------------------------- outputs for microscopy tools


@pytest.mark.parametrize("pixel, channels, bit_depth", [(0.5, 3, 8), ((0.25, 0.4), 1, 16)])
def test_png_phys_chunk_gives_the_pixel_size(tmp_path, pixel, channels, bit_depth):
    s = _samples(channels, bit_depth, seed=6)
    p = tmp_path / "p.png"
    write_image(p, s, pixel_size_um=pixel)
    py, px = np.broadcast_to(pixel, (2,))
    assert png_pixel_size_um(p) == pytest.approx((py, px), rel=1e-6)
    with Image.open(p) as im:                                   # PIL: dpi from pHYs (metre)
        dpi_x, dpi_y = im.info["dpi"]
    assert (25400 / dpi_y, 25400 / dpi_x) == pytest.approx((py, px), rel=1e-6)
    np.testing.assert_array_equal(decode_image(p, WHERE, channels=channels), s)  # pixels kept
    write_image(p, s)                                           # without: no pHYs
    assert png_pixel_size_um(p) is None


def test_phys_chunk_has_a_valid_crc_and_sits_before_idat(tmp_path):
    p = tmp_path / "p.png"
    write_image(p, np.zeros((H, W), np.uint8), pixel_size_um=2.0)
    data = p.read_bytes()
    pos, kinds = 8, []
    while pos < len(data):
        n, kind = struct.unpack(">I4s", data[pos:pos + 8])
        body = data[pos + 4:pos + 8 + n]
        assert struct.unpack(">I", data[pos + 8 + n:pos + 12 + n])[0] == zlib.crc32(body)
        if kind == b"pHYs":
            assert struct.unpack(">IIB", body[4:]) == (500000, 500000, 1)   # px per metre
        kinds.append(kind)
        pos += 12 + n
    assert kinds.count(b"pHYs") == 1 and kinds.index(b"pHYs") < kinds.index(b"IDAT")


def test_float_tiff_round_trip_with_calibration(tmp_path):
    rng = np.random.default_rng(7)
    a = rng.normal(100, 5, (H, W))
    a[2, 3] = np.nan
    p = tmp_path / "m.tif"
    write_float_tiff(p, a, pixel_size_um=(0.25, 0.5), value_unit="nm")
    with tifffile.TiffFile(p) as tf:
        page = tf.pages[0]
        got = page.asarray()
        meta = tf.imagej_metadata
        xres, yres = page.resolution
    assert got.dtype == np.float32
    np.testing.assert_array_equal(got, a.astype(np.float32))
    assert meta["unit"] == "um" and meta["vunit"] == "nm"
    assert (1 / yres, 1 / xres) == pytest.approx((0.25, 0.5), rel=1e-7)   # px per µm
    assert meta["min"] == pytest.approx(np.nanmin(a)) and meta["max"] == pytest.approx(
        np.nanmax(a))


def test_float_tiff_without_pixel_size_and_bad_arguments(tmp_path):
    p = tmp_path / "m.tif"
    write_float_tiff(p, np.full((2, 3), np.nan))
    with tifffile.TiffFile(p) as tf:
        assert "unit" not in tf.imagej_metadata
        assert np.isnan(tf.asarray()).all()
    with pytest.raises(ValueError, match="image"):
        write_float_tiff(p, np.zeros(3))
    with pytest.raises(ValueError, match="pixel_size_um"):
        write_float_tiff(p, np.zeros((2, 2)), pixel_size_um=-1.0)
