"""Image files: headers read without decoding, decoding to native samples, and writing.

Validation reads image *headers* only, never pixels:

* PNG: the IHDR chunk (size, bit depth, colour type); truncation is detected by requiring the
  ``IEND`` chunk at the end of the file.
* JPEG: the SOFn marker (size, precision, components); truncation is detected by requiring the
  end-of-image marker ``FFD9`` near the end of the file.
* TIFF (single or multi-page): the IFDs through :mod:`tifffile` (shape, dtype, samples); a page
  whose strips or tiles extend past the end of the file is reported as truncated.
* ``.npy``: the header (shape, dtype) and the file's length.

Corrupt *compressed data* inside an intact container is only found when the image is decoded
(:func:`decode_image` then raises :class:`~microfacet.core.errors.InputError` naming it).
Multi-page TIFFs are read through :class:`MultiPageTiff`, one pass over the pages.

Images are channels-last, RGB order: grey ``(H, W)`` or colour ``(H, W, 3)``; alpha is dropped.

Writing: PNG/TIFF/JPEG images through OpenCV (PNGs optionally with a ``pHYs`` chunk giving the
pixel size, :func:`png_pixel_size_um` reads it back) and float maps as calibrated float32
ImageJ TIFFs for Fiji (:func:`write_float_tiff`).

Examples
--------
>>> import tempfile, pathlib
>>> p = pathlib.Path(tempfile.mkdtemp()) / "a.png"
>>> write_image(p, np.full((4, 5, 3), 0.5))
>>> image_info(p, "a.png")
ImageInfo(shape=(4, 5), dtype=dtype('uint8'), channels=3, jpeg=None)
>>> decode_image(p, "a.png")[0, 0].tolist()
[128, 128, 128]
"""

from __future__ import annotations

import contextlib
import functools
import os
import struct
import threading
import zlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..core.errors import InputError, one_line
from ..core.lazy import load
from ..core.pixels import pixel_size_yx
from ..core.threads import row_chunks

cv2 = load("cv2")
tifffile = load("tifffile")

__all__ = ["ImageInfo", "JpegTables", "MultiPageTiff", "convert_samples", "decode_image",
           "image_info", "png_pixel_size_um", "read_png", "read_tiff_headers",
           "write_float_tiff", "write_image"]

#: File suffixes accepted for slices and export images (lower case).
IMAGE_SUFFIXES = (".png", ".tif", ".tiff", ".jpg", ".jpeg")


# ------------------------------------------------------------------------------------ headers


@dataclass(frozen=True)
class JpegTables:
    """What a JPEG's quantization tables say of its compression error.

    Attributes
    ----------
    dc_steps : tuple of int
        Quantization step of the DC coefficient (the 8 × 8 block's mean × 8, code values) of
        the luma table and of the chroma table (the luma's again for a grey JPEG).
    chroma_block_px : int
        Pixels one chroma block covers: 64, or 128 / 256 with 4:2:2 / 4:2:0 subsampling.
    quality : int or None
        The IJG quality (libjpeg, OpenCV, Pillow) whose luma table this is; None: not an
        IJG-scaled table (a camera's own).
    """

    dc_steps: tuple[int, int]
    chroma_block_px: int
    quality: int | None


@dataclass(frozen=True)
class ImageInfo:
    """What a header tells about one image: ``(H, W)``, numpy dtype, channels (1 or 3) and,
    for a JPEG, its quantization (:class:`JpegTables`)."""

    shape: tuple[int, int]
    dtype: np.dtype
    channels: int
    jpeg: JpegTables | None = None


def _png_info(path: Path, where: str) -> ImageInfo:
    size = path.stat().st_size
    with open(path, "rb") as fh:
        head = fh.read(33)
        if len(head) < 33 or head[:8] != b"\x89PNG\r\n\x1a\n" or head[12:16] != b"IHDR":
            raise InputError(f"{where}: not a PNG file (bad signature or IHDR)")
        w, h, bit_depth, color_type = struct.unpack(">IIBB", head[16:26])
        fh.seek(max(0, size - 12))
        tail = fh.read(12)
    if tail[4:8] != b"IEND":
        raise InputError(f"{where}: truncated PNG (no IEND chunk at the end of the file)")
    if w == 0 or h == 0:
        raise InputError(f"{where}: PNG has zero size {w}x{h}")
    channels = {0: 1, 2: 3, 3: 3, 4: 1, 6: 3}.get(color_type)
    if channels is None:
        raise InputError(f"{where}: unsupported PNG colour type {color_type}")
    dtype = np.dtype(np.uint16) if bit_depth == 16 else np.dtype(np.uint8)
    return ImageInfo((h, w), dtype, channels)


_SOF_MARKERS = {0xC0, 0xC1, 0xC2, 0xC3, 0xC5, 0xC6, 0xC7, 0xC9, 0xCA, 0xCB, 0xCD, 0xCE, 0xCF}


#: The IJG (ITU-T T.81 Annex K) luminance quantization table at quality 50.
_IJG_LUMA = np.array([16, 11, 10, 16, 24, 40, 51, 61, 12, 12, 14, 19, 26, 58, 60, 55, 14, 13,
                      16, 24, 40, 57, 69, 56, 14, 17, 22, 29, 51, 87, 80, 62, 18, 22, 37, 56,
                      68, 109, 103, 77, 24, 35, 55, 64, 81, 104, 113, 92, 49, 64, 78, 87, 103,
                      121, 120, 101, 72, 92, 95, 98, 112, 100, 103, 99])


def ijg_quality(table) -> int | None:
    """The IJG quality 1-100 whose scaled luminance table is ``table`` (64 steps, any
    order), or None.

    >>> t = np.clip((_IJG_LUMA * (200 - 2 * 90) + 50) // 100, 1, 255)
    >>> ijg_quality(t[::-1]), ijg_quality(np.full(64, 3))
    (90, None)
    """
    want = np.sort(np.asarray(table, dtype=np.int64))
    hit = np.flatnonzero(np.all(_ijg_sorted_tables() == want, axis=1))
    return int(hit[0]) + 1 if hit.size else None


@functools.cache
def _ijg_sorted_tables() -> np.ndarray:
    """The IJG luminance tables of qualities 1-100, each sorted: (100, 64)."""
    q = np.arange(1, 101)[:, None]
    scale = np.where(q < 50, 5000 // q, 200 - 2 * q)
    return np.sort(np.clip((_IJG_LUMA * scale + 50) // 100, 1, 255), axis=1)


def _dqt_tables(seg: bytes) -> dict:
    """The quantization tables of one DQT segment: id → 64 steps (zig-zag order)."""
    out, i = {}, 0
    while i < len(seg):
        pq, tq = seg[i] >> 4, seg[i] & 15
        n = 128 if pq else 64
        vals = seg[i + 1:i + 1 + n]
        if len(vals) < n:
            break
        out[tq] = (np.frombuffer(vals, ">u2") if pq else np.frombuffer(vals, np.uint8)).astype(
            np.int64)
        i += 1 + n
    return out


def _jpeg_tables(tables: dict, comps: list) -> JpegTables | None:
    """Compression of a frame with components ``(id, H·V sampling, table id)``."""
    try:
        luma = tables[comps[0][2]]
        chroma = tables[comps[1][2]] if len(comps) > 1 else luma
    except (KeyError, IndexError):
        return None
    block = 64 * max(1, comps[0][1] // max(1, comps[1][1])) if len(comps) > 1 else 64
    return JpegTables((int(luma[0]), int(chroma[0])), int(block), ijg_quality(luma))


def _jpeg_info(path: Path, where: str) -> ImageInfo:
    size = path.stat().st_size
    tables, comps = {}, []
    with open(path, "rb") as fh:
        if fh.read(2) != b"\xff\xd8":
            raise InputError(f"{where}: not a JPEG file (no SOI marker)")
        info = None
        while True:
            b = fh.read(1)
            if not b:
                break
            if b != b"\xff":
                continue
            marker = fh.read(1)
            while marker == b"\xff":
                marker = fh.read(1)
            if not marker:
                break
            m = marker[0]
            if m in (0x01, 0xD8) or 0xD0 <= m <= 0xD7:
                continue
            seglen_b = fh.read(2)
            if len(seglen_b) < 2:
                break
            seglen = struct.unpack(">H", seglen_b)[0]
            if m == 0xDB:
                tables.update(_dqt_tables(fh.read(max(0, seglen - 2))))
                continue
            if m in _SOF_MARKERS:
                seg = fh.read(max(6, seglen - 2))
                if len(seg) < 6:
                    break
                precision, h, w, ncomp = struct.unpack(">BHHB", seg[:6])
                comps = [(seg[6 + 3 * k], (seg[7 + 3 * k] >> 4) * (seg[7 + 3 * k] & 15),
                          seg[8 + 3 * k]) for k in range(ncomp) if 9 + 3 * k <= len(seg)]
                info = (precision, h, w, ncomp)
                break
            fh.seek(seglen - 2, os.SEEK_CUR)
        fh.seek(max(0, size - 64))
        tail = fh.read(64)
    if info is None:
        raise InputError(f"{where}: truncated or corrupt JPEG (no frame header)")
    if b"\xff\xd9" not in tail:
        raise InputError(f"{where}: truncated JPEG (no end-of-image marker)")
    precision, h, w, ncomp = info
    if precision != 8:
        raise InputError(f"{where}: {precision}-bit JPEG is not supported (8-bit only)")
    if h == 0 or w == 0:
        raise InputError(f"{where}: JPEG has zero size {w}x{h}")
    if ncomp not in (1, 3):
        raise InputError(f"{where}: JPEG with {ncomp} components is not supported (grey or RGB)")
    return ImageInfo((h, w), np.dtype(np.uint8), ncomp, _jpeg_tables(tables, comps))


def _tiff_page_info(page, where: str, file_size: int) -> ImageInfo:
    shape = tuple(int(s) for s in page.shape)
    dtype = np.dtype(page.dtype) if page.dtype is not None else None
    if dtype not in (np.dtype(np.uint8), np.dtype(np.uint16)):
        raise InputError(f"{where}: TIFF sample type {dtype} is not supported (8- or 16-bit)")
    samples = int(getattr(page, "samplesperpixel", 1))
    if len(shape) == 2:
        channels = 1
    elif len(shape) == 3 and shape[-1] == samples and samples in (1, 2, 3, 4):
        channels = 1 if samples in (1, 2) else 3
        shape = shape[:2]
    else:
        raise InputError(f"{where}: TIFF page of shape {shape} is not a grey or RGB image")
    offsets = page.dataoffsets
    counts = page.databytecounts
    if not offsets or any(o + c > file_size for o, c in zip(offsets, counts)):
        raise InputError(f"{where}: truncated TIFF (image data extends past the end of the file)")
    return ImageInfo((shape[0], shape[1]), dtype, channels)


def _tiff_info(path: Path, where: str) -> ImageInfo:
    try:
        with tifffile.TiffFile(path) as tf:
            return _tiff_page_info(tf.pages[0], where, path.stat().st_size)
    except InputError:
        raise
    except Exception as exc:  # tifffile raises assorted errors on corrupt files
        raise InputError(f"{where}: unreadable TIFF ({exc})") from None


def image_info(path: Path, where: str) -> ImageInfo:
    suffix = path.suffix.lower()
    try:
        if suffix == ".png":
            return _png_info(path, where)
        if suffix in (".jpg", ".jpeg"):
            return _jpeg_info(path, where)
        if suffix in (".tif", ".tiff"):
            return _tiff_info(path, where)
    except OSError as exc:
        raise InputError(f"{where}: cannot read ({exc.strerror or exc})") from None
    raise InputError(f"{where}: unsupported image type {suffix!r} "
                     f"(expected one of {', '.join(IMAGE_SUFFIXES)})")


# ----------------------------------------------------------------------------------- decoding


def _to_rgb_or_grey(img: np.ndarray) -> np.ndarray:
    """Drop alpha; grey stays (H, W); colour comes back (H, W, 3)."""
    if img.ndim == 3:
        if img.shape[2] == 1:
            return img[:, :, 0]
        if img.shape[2] == 2:
            return img[:, :, 0]
        if img.shape[2] == 4:
            return img[:, :, :3]
    return img


_cv_log_lock = threading.Lock()
_cv_log_state = {"active": 0, "level": None}


@contextlib.contextmanager
def _opencv_warnings_off():
    """OpenCV writes its decoders' warnings about corrupt data straight to stderr (fd 2);
    a failed decode is reported as one InputError naming the slice instead. Thread-safe:
    the user's log level is restored when the last concurrent decode ends."""
    with _cv_log_lock:
        if _cv_log_state["active"] == 0:
            _cv_log_state["level"] = cv2.utils.logging.getLogLevel()
            cv2.utils.logging.setLogLevel(min(_cv_log_state["level"],
                                              cv2.utils.logging.LOG_LEVEL_ERROR))
        _cv_log_state["active"] += 1
    try:
        yield
    finally:
        with _cv_log_lock:
            _cv_log_state["active"] -= 1
            if _cv_log_state["active"] == 0:
                cv2.utils.logging.setLogLevel(_cv_log_state["level"])


def decode_image(path: Path, where: str, page: int | None = None, *,
            channels: int | None = None) -> np.ndarray:
    """Decode one image to its native dtype, grey ``(H, W)`` or RGB ``(H, W, 3)``.

    ``channels`` is what the header said: a grey image with alpha comes back from OpenCV as
    four equal-grey channels and is returned grey.
    """
    img = _decode_raw(path, where, page)
    if channels == 1 and img.ndim == 3:
        img = img[..., 0]
    return img


def _decode_raw(path: Path, where: str, page: int | None) -> np.ndarray:
    suffix = path.suffix.lower()
    try:
        if suffix in (".tif", ".tiff"):
            img = tifffile.imread(path, key=0 if page is None else page)
            return _to_rgb_or_grey(np.asarray(img))
        with _opencv_warnings_off():
            img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED | cv2.IMREAD_IGNORE_ORIENTATION)
        if img is None:
            raise InputError(f"{where}: cannot decode image")
        if img.ndim == 3:
            if img.shape[2] == 4:
                img = cv2.cvtColor(img, cv2.COLOR_BGRA2RGB)
            elif img.shape[2] == 3:
                img = cv2.cvtColor(img, cv2.COLOR_BGR2RGB)
        return _to_rgb_or_grey(img)
    except InputError:
        raise
    except Exception as exc:
        raise InputError(f"{where}: cannot decode image ({exc})") from None


class MultiPageTiff:
    """One multi-page TIFF kept open while its pages are read: each page is found once, so a
    pass over the stack is linear in the number of pages (``tifffile.imread(key=i)`` walks
    the page chain from the start every time: quadratic). Thread-safe."""

    def __init__(self, path: Path, uniform: bool):
        self.path = path
        self.uniform = uniform  # every page encoded like page 0: light TiffFrames suffice
        self._tf = None
        self._lock = threading.Lock()

    def read(self, index: int, where: str, channels: int) -> np.ndarray:
        try:
            with self._lock:
                if self._tf is None:
                    tf = tifffile.TiffFile(self.path)
                    tf.pages.cache = False
                    tf.pages.useframes = self.uniform
                    self._tf = tf
                img = self._tf.pages[index].asarray()
        except Exception as exc:
            raise InputError(f"{where}: cannot decode image ({exc})") from None
        img = _to_rgb_or_grey(np.asarray(img))
        if channels == 1 and img.ndim == 3:
            img = img[..., 0]
        return img

    def close(self):
        with self._lock:
            if self._tf is not None:
                self._tf.close()
                self._tf = None

    def __del__(self):  # pragma: no cover - best effort
        with contextlib.suppress(Exception):
            self.close()


def convert_samples(raw: np.ndarray, dtype) -> np.ndarray:
    """Native samples → ``dtype``: floating dtypes are scaled to [0, 1] (÷255 or ÷65535),
    integer dtypes cast.

    >>> convert_samples(np.array([0, 255], np.uint8), np.float32).tolist()
    [0.0, 1.0]
    """
    dtype = np.dtype(dtype)
    if np.issubdtype(dtype, np.floating):
        scale = 1.0 / (65535.0 if raw.dtype == np.uint16 else 255.0)
        return np.multiply(raw, dtype.type(scale), dtype=dtype)
    return raw.astype(dtype, copy=False)


def npy_info(path: Path, where: str) -> tuple[tuple[int, ...], np.dtype]:
    """``(shape, dtype)`` from a ``.npy`` header, checking the file holds that many bytes."""
    try:
        with open(path, "rb") as fh:
            version = np.lib.format.read_magic(fh)
            if version == (1, 0):
                shape, _, dtype = np.lib.format.read_array_header_1_0(fh)
            else:
                shape, _, dtype = np.lib.format.read_array_header_2_0(fh)
            header_end = fh.tell()
    except Exception as exc:
        raise InputError(f"{where}: not a readable .npy file ({exc})") from None
    if dtype.hasobject:
        raise InputError(f"{where}: .npy holds Python objects; a float height map is required")
    need = header_end + int(np.prod(shape)) * dtype.itemsize
    if path.stat().st_size < need:
        raise InputError(f"{where}: truncated .npy file")
    return tuple(int(s) for s in shape), dtype


_TIFF_CODING = ("compression", "predictor", "planarconfig", "photometric", "bitspersample",
                "samplesperpixel", "fillorder", "sampleformat")


def read_tiff_headers(tiff_path: Path, where: str, add) -> bool:
    """Read every page header of a multi-page TIFF in one pass (linear in the pages) and
    ``add(name, where, info)`` each; True when every page is encoded like the first."""
    name = one_line(tiff_path.name)
    fsize = tiff_path.stat().st_size
    uniform = True
    try:
        with tifffile.TiffFile(tiff_path) as tf:
            tf.pages.cache = False          # one page object alive at a time
            tf.pages.useframes = False      # full headers: every page is checked
            coding0 = None
            for k, page in enumerate(tf.pages):
                wk = f"{where} ({name} page {k})"
                add(f"{one_line(tiff_path)} page {k}", wk, _tiff_page_info(page, wk, fsize))
                coding = tuple(getattr(page, a, None) for a in _TIFF_CODING)
                coding0 = coding if coding0 is None else coding0
                uniform &= coding == coding0 and not page.is_tiled
    except InputError:
        raise
    except Exception as exc:
        raise InputError(f"{where} ({name}): unreadable TIFF ({exc})") from None
    return uniform


def read_png(path) -> np.ndarray:
    """A PNG (8- or 16-bit) as float32 in [0, 1]: RGB ``(H, W, 3)`` or grey ``(H, W)``.

    Raises
    ------
    InputError
        Naming the file, if it cannot be decoded.
    """
    return convert_samples(decode_image(Path(path), one_line(path)), np.float32)


# ------------------------------------------------------------------------------------ writing


def to_code_values(image, *, bit_depth=8):
    """Float image in [0, 1] → uint8 / uint16 code values (clipped, rounded); ints unchanged.

    Examples
    --------
    >>> to_code_values(np.array([0.0, 0.5, 1.2])).tolist()
    [0, 128, 255]
    """
    img = np.asarray(image)
    if img.dtype.kind in "ui":
        return img
    out = np.empty(img.shape, _code_dtype(bit_depth))
    _code_values_into(img, out)
    return out


def _code_dtype(bit_depth):
    """The code values' dtype of ``bit_depth`` (8 or 16; anything else raises ValueError)."""
    if bit_depth not in (8, 16):
        raise ValueError(f"bit_depth: must be 8 or 16, got {bit_depth!r}")
    return np.uint8 if bit_depth == 8 else np.uint16


def _code_values_into(img, out) -> None:
    """:func:`to_code_values` of the float image ``img`` written into ``out`` (uint8 or
    uint16, any strides: a channel-reversed view writes BGR), a block of rows at a time: the
    float copy the values are worked on in is one block's, not the image's."""
    top = float(np.iinfo(out.dtype).max)
    for a, b in row_chunks(img.shape):
        blk = np.nan_to_num(img[a:b], nan=0.0)          # this block's float copy
        np.clip(blk, 0, 1, out=blk)
        blk *= top
        out[a:b] = np.round(blk, out=blk)


def write_image(path, image, *, bit_depth=8, params=(), pixel_size_um=None):
    """Write an (H, W) grey or (H, W, 3) RGB image; floats are [0, 1] encoded values.

    ``pixel_size_um`` (a float or ``(y, x)``, µm) adds a PNG ``pHYs`` chunk: pixels per
    metre, rounded to whole pixels (read back by :func:`png_pixel_size_um`, PIL, GIMP).

    Raises
    ------
    OSError
        Naming the path, if OpenCV cannot write it.
    """
    src = np.asarray(image)
    if src.dtype.kind in "ui" or src.ndim != 3:
        img = to_code_values(src, bit_depth=bit_depth)
        img = np.ascontiguousarray(img[..., ::-1] if img.ndim == 3 else img)  # OpenCV: BGR
    else:                       # the code values written straight in OpenCV's BGR order
        img = np.empty(src.shape, _code_dtype(bit_depth))
        _code_values_into(src, img[..., ::-1])
    if pixel_size_um is None or Path(path).suffix.lower() != ".png":
        if not cv2.imwrite(str(path), img, list(params)):
            raise OSError(f"cannot write {path}")
        return
    ok, buf = cv2.imencode(".png", img, list(params))
    if not ok:
        raise OSError(f"cannot write {path}")
    Path(path).write_bytes(_with_phys(buf.tobytes(), pixel_size_um))


def _png_chunks(data: bytes):
    """``(offset, length, type)`` of each chunk of a PNG byte string."""
    pos = 8
    while pos + 8 <= len(data):
        length, ctype = struct.unpack(">I4s", data[pos:pos + 8])
        yield pos, length, ctype
        pos += 12 + length


def _with_phys(png: bytes, pixel_size_um) -> bytes:
    try:
        ppm = [round(1e6 / v) for v in pixel_size_yx(pixel_size_um)[::-1]]  # x, y
    except ValueError:
        ppm = [0, 0]
    if not all(0 < v < 2**32 for v in ppm):
        raise ValueError(f"pixel_size_um: {pixel_size_um!r} does not fit a PNG pHYs chunk")
    body = b"pHYs" + struct.pack(">IIB", ppm[0], ppm[1], 1)
    chunk = struct.pack(">I", 9) + body + struct.pack(">I", zlib.crc32(body))
    out = bytearray(png[:8])
    for pos, length, ctype in _png_chunks(png):
        if ctype != b"pHYs":
            out += png[pos:pos + 12 + length]
        if ctype == b"IHDR":
            out += chunk
    return bytes(out)


def png_pixel_size_um(path) -> tuple[float, float] | None:
    """The pixel size ``(y, x)`` in µm from a PNG's ``pHYs`` chunk in metres, else None.

    Raises
    ------
    InputError
        Naming the file, if it cannot be read.
    """
    try:
        data = Path(path).read_bytes()
    except OSError as exc:
        raise InputError(f"{one_line(path)}: cannot read ({exc.strerror or exc})") from None
    for pos, length, ctype in _png_chunks(data):
        if ctype == b"pHYs" and length == 9:
            ppx, ppy, unit = struct.unpack(">IIB", data[pos + 8:pos + 17])
            return (1e6 / ppy, 1e6 / ppx) if unit == 1 and ppx and ppy else None
        if ctype == b"IDAT":
            break
    return None


# ------------------------------------------------------------------------- float TIFF (maps)

def write_float_tiff(path, image, *, pixel_size_um=None, value_unit=None) -> None:
    """Write a 2-D map as a float32 ImageJ TIFF that Fiji and tifffile calibrate.

    Parameters
    ----------
    path : path-like
    image : array_like (H, W)
        Values (NaN stays NaN).
    pixel_size_um : float or (float, float), optional
        Pixel size in µm, one value or ``(y, x)``: written as ImageJ ``unit=um`` and the
        resolution tags in pixels per µm.
    value_unit : str, optional
        The unit of the values (``"um"``, ``"nm"``, ``"degree"``), ImageJ ``vunit``.
    """
    img = np.asarray(image, dtype=np.float32)
    if img.ndim != 2:
        raise ValueError(f"image: expected a 2-D map, got shape {img.shape}")
    meta = {"axes": "YX"}
    kw = {}
    if pixel_size_um is not None:
        py, px = pixel_size_yx(pixel_size_um)
        meta["unit"] = "um"
        kw["resolution"] = (1.0 / px, 1.0 / py)
    if value_unit is not None:
        meta["vunit"] = str(value_unit)
    finite = img[np.isfinite(img)]
    if finite.size:  # Fiji's initial display range
        meta["min"], meta["max"] = float(finite.min()), float(finite.max())
    tifffile.imwrite(path, img, imagej=True, metadata=meta, **kw)
