"""Reading and writing focus stacks in the ``microfacet-stack/1`` format.

A stack is a folder with a ``stack.json`` beside its images (see the project's stack-format
specification). :func:`read_stack` validates *everything* before any work starts and returns a
:class:`Stack`; bad input raises :class:`microfacet.core.errors.InputError` with one message that
names the file and the key or slice at fault.

Validation reads image *headers* only, never decodes pixels:

* PNG: the IHDR chunk (size, bit depth, colour type); truncation is detected by requiring the
  ``IEND`` chunk at the end of the file.
* JPEG: the SOFn marker (size, precision, components); truncation is detected by requiring the
  end-of-image marker ``FFD9`` near the end of the file.
* TIFF (single or multi-page): the IFDs through :mod:`tifffile` (shape, dtype, samples); a page
  whose strips or tiles extend past the end of the file is reported as truncated.

Corrupt *compressed data* inside an intact container is only found when the slice is decoded;
:meth:`Stack.iter_slices` then raises :class:`~microfacet.core.errors.InputError` naming the slice.
Decoding every slice just to validate would double the cost of the height step, so that
trade-off is deliberate.

Slices are read lazily, one at a time (:meth:`Stack.iter_slices`), so peak memory does not grow
with the number of slices.

Examples
--------
>>> import numpy as np, tempfile, pathlib
>>> d = pathlib.Path(tempfile.mkdtemp())
>>> imgs = [np.full((4, 5), i * 40, np.uint8) for i in range(3)]
>>> _ = write_stack(d / "s", imgs, z_um=[0.0, 1.5, 3.0], pixel_size_um=0.5)
>>> st = read_stack(d / "s")
>>> st.shape, st.n_slices, st.channels, str(st.dtype)
((4, 5), 3, 1, 'uint8')
>>> [(i, z, float(im.max())) for i, z, im in st.iter_slices()][1]
(1, 1.5, 0.1568627506494522)
"""

from __future__ import annotations

import contextlib
import difflib
import json
import logging
import math
import os
import stat
import struct
import threading
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..core.errors import InputError, one_line
from .jsonfile import read_json
from .limits import Limits

__all__ = [
    "FORMAT",
    "IMAGE_SUFFIXES",
    "Stack",
    "read_stack",
    "stack_from_images",
    "write_stack",
    "write_stack_json",
]

log = logging.getLogger(__name__)

#: The ``format`` string of a stack.json.
FORMAT = "microfacet-stack/1"
#: File suffixes accepted for slices and export images (lower case).
IMAGE_SUFFIXES = (".png", ".tif", ".tiff", ".jpg", ".jpeg")
_DEFAULT_ILLUMINATION = {"geometry": "coaxial", "numerical_aperture": 0.8}
_COLOR_SPACES = ("sRGB", "linear-sRGB")
#: The keys of stack.json this format defines (others are kept in ``meta`` with a warning).
KNOWN_KEYS = ("format", "pixel_size_um", "slices", "tiff", "z_um", "z_step_um", "color_space",
              "illuminant", "illumination", "film", "substrate", "exposure", "height_um",
              "image", "synthetic")
_ILLUMINATION_KEYS = ("geometry", "numerical_aperture")
#: Pixel sizes outside this range (µm) are almost surely a unit mistake: warned about.
PLAUSIBLE_PIXEL_SIZE_UM = (0.01, 100.0)


# --------------------------------------------------------------------------------------------
# header parsing


@dataclass(frozen=True)
class _ImageInfo:
    """What a header tells about one image: ``(H, W)``, numpy dtype, channels (1 or 3)."""

    shape: tuple[int, int]
    dtype: np.dtype
    channels: int


def _png_info(path: Path, where: str) -> _ImageInfo:
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
    return _ImageInfo((h, w), dtype, channels)


_SOF_MARKERS = {0xC0, 0xC1, 0xC2, 0xC3, 0xC5, 0xC6, 0xC7, 0xC9, 0xCA, 0xCB, 0xCD, 0xCE, 0xCF}


def _jpeg_info(path: Path, where: str) -> _ImageInfo:
    size = path.stat().st_size
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
            if m in _SOF_MARKERS:
                seg = fh.read(6)
                if len(seg) < 6:
                    break
                precision, h, w, ncomp = struct.unpack(">BHHB", seg)
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
    return _ImageInfo((h, w), np.dtype(np.uint8), ncomp)


def _tiff_page_info(page, where: str, file_size: int) -> _ImageInfo:
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
    return _ImageInfo((shape[0], shape[1]), dtype, channels)


def _tiff_info(path: Path, where: str) -> _ImageInfo:
    import tifffile

    try:
        with tifffile.TiffFile(path) as tf:
            return _tiff_page_info(tf.pages[0], where, path.stat().st_size)
    except InputError:
        raise
    except Exception as exc:  # tifffile raises assorted errors on corrupt files
        raise InputError(f"{where}: unreadable TIFF ({exc})") from None


def _image_info(path: Path, where: str) -> _ImageInfo:
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


# --------------------------------------------------------------------------------------------
# decoding


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
def _opencv_warnings_off(cv2):
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


def _decode(path: Path, where: str, page: int | None = None, *,
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
            import tifffile

            img = tifffile.imread(path, key=0 if page is None else page)
            return _to_rgb_or_grey(np.asarray(img))
        import cv2

        with _opencv_warnings_off(cv2):
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


class _MultiPageTiff:
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
                    import tifffile

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


# --------------------------------------------------------------------------------------------
# the Stack


@dataclass(frozen=True, eq=False)
class Stack:
    """A validated focus stack (``microfacet-stack/1``).

    Attributes
    ----------
    path : Path
        The stack folder (absolute).
    pixel_size_um : float
        Lateral size of one pixel on the sample, µm.
    z_um : ndarray of float64, shape (N,)
        Stage height of each slice in file order, µm (any order, any spacing, no duplicates).
        Empty for an export-only stack.
    slice_paths : tuple of Path
        One image per slice in file order (empty when the stack is a multi-page TIFF).
    tiff_path : Path or None
        The multi-page TIFF (one page per slice), if the stack uses ``"tiff"``.
    shape : tuple of int
        ``(H, W)`` of every image.
    dtype : numpy.dtype
        Native sample type of the slices: uint8 or uint16.
    channels : int
        1 (grey) or 3 (RGB).
    color_space : str
        ``"sRGB"`` or ``"linear-sRGB"``.
    illuminant : str
        Name of the white point the images are balanced to.
    illumination : dict
        ``{"geometry": ..., "numerical_aperture": ...}``.
    film, substrate : str
        Optical-constant set names (validated against :func:`microfacet.optics.known_sets`).
    exposure : float or None
        Model-to-image exposure scale, or None when it is to be estimated.
    export_height_path, export_image_path : Path or None
        The microscope export: height map in µm (TIFF or ``.npy``) and its colour image.
    meta : dict
        The whole stack.json as read (extra keys included).
    """

    path: Path
    pixel_size_um: float
    z_um: np.ndarray
    slice_paths: tuple[Path, ...]
    tiff_path: Path | None
    shape: tuple[int, int]
    dtype: np.dtype
    channels: int
    color_space: str = "sRGB"
    illuminant: str = "D65"
    illumination: dict = field(default_factory=lambda: dict(_DEFAULT_ILLUMINATION))
    film: str = ""
    substrate: str = ""
    exposure: float | None = None
    export_height_path: Path | None = None
    export_image_path: Path | None = None
    meta: dict = field(default_factory=dict)
    tiff_uniform: bool = field(default=False, repr=False)

    def __post_init__(self):
        reader = _MultiPageTiff(self.tiff_path, self.tiff_uniform) if self.tiff_path else None
        object.__setattr__(self, "_tiff", reader)

    # -- properties ----------------------------------------------------------------------
    @property
    def n_slices(self) -> int:
        """Number of focal planes (0 for an export-only stack)."""
        return int(self.z_um.size)

    @property
    def has_slices(self) -> bool:
        """True when the stack holds focal-plane images (not only an export)."""
        return self.n_slices > 0

    @property
    def has_export(self) -> bool:
        """True when the stack holds a microscope export (height map + image)."""
        return self.export_height_path is not None

    @property
    def numerical_aperture(self) -> float:
        """The objective's numerical aperture from ``illumination``."""
        return float(self.illumination["numerical_aperture"])

    @property
    def z_order(self) -> np.ndarray:
        """Slice indices sorted by increasing ``z_um``, shape (N,)."""
        return np.argsort(self.z_um, kind="stable")

    def slice_name(self, index: int) -> str:
        """A human-readable name of slice ``index`` for messages."""
        if self.tiff_path is not None:
            return f"{self.tiff_path} page {index}"
        return str(self.slice_paths[index])

    # -- reading -------------------------------------------------------------------------
    def read_slice(self, index: int, dtype=np.float32) -> np.ndarray:
        """Decode slice ``index`` (file order).

        Parameters
        ----------
        index : int
            Slice index in file order, ``0 <= index < n_slices``.
        dtype : numpy dtype, optional
            Floating dtypes scale the samples to [0, 1] (divided by 255 or 65535); integer
            dtypes return the native samples cast.

        Returns
        -------
        ndarray, shape (H, W) for grey or (H, W, 3) for RGB
            Still encoded in :attr:`color_space` (no linearisation).
        """
        if not 0 <= index < self.n_slices:
            raise IndexError(f"slice index {index} out of range 0..{self.n_slices - 1}")
        where = f"slice {index} ({one_line(self.slice_name(index))})"
        if self._tiff is not None:
            raw = self._tiff.read(index, where, self.channels)
        else:
            raw = _decode(self.slice_paths[index], where, channels=self.channels)
        if raw.shape[:2] != self.shape or raw.dtype != self.dtype or (
                (raw.ndim == 3) != (self.channels == 3)):
            raise InputError(f"{where}: decoded image {raw.shape} {raw.dtype} does not match "
                             f"its header {self.shape} {self.dtype} x{self.channels}")
        return _convert(raw, dtype)

    def iter_slices(self, dtype=np.float32, *, order: str = "file") -> Iterator[tuple[int, float, np.ndarray]]:
        """Yield ``(index, z_um, image)`` one slice at a time.

        Only one decoded slice is alive at a time inside this generator, so memory does not
        grow with the number of slices.

        Parameters
        ----------
        dtype : numpy dtype, optional
            See :meth:`read_slice` (float32 in [0, 1] by default).
        order : {"file", "z"}, keyword-only
            ``"file"`` yields in the stack.json order, ``"z"`` by increasing ``z_um``.
            ``index`` is always the file-order index.
        """
        if order == "file":
            indices = range(self.n_slices)
        elif order == "z":
            indices = self.z_order.tolist()
        else:
            raise ValueError(f"order must be 'file' or 'z', not {order!r}")
        for i in indices:
            yield int(i), float(self.z_um[i]), self.read_slice(int(i), dtype)

    def read_export_height(self) -> np.ndarray:
        """The microscope export's height map, float32 (H, W) in µm (non-finite kept as NaN)."""
        if self.export_height_path is None:
            raise InputError(f"{self.path / 'stack.json'}: key 'height_um': the stack has no export")
        p = self.export_height_path
        if p.suffix.lower() == ".npy":
            h = np.load(p, allow_pickle=False)
        else:
            import tifffile

            h = tifffile.imread(p)
        h = np.asarray(h, dtype=np.float32)
        h[~np.isfinite(h)] = np.nan
        _warn_height_unit(h, self.pixel_size_um, self.path / "stack.json")
        return h

    def read_export_image(self, dtype=np.float32) -> np.ndarray:
        """The microscope export's all-in-focus image, (H, W) or (H, W, 3), see :meth:`read_slice`."""
        if self.export_image_path is None:
            raise InputError(f"{self.path / 'stack.json'}: key 'image': the stack has no export")
        return _convert(_decode(self.export_image_path,
                                f"export image ({one_line(self.export_image_path)})",
                                channels=self.channels), dtype)


def _convert(raw: np.ndarray, dtype) -> np.ndarray:
    dtype = np.dtype(dtype)
    if np.issubdtype(dtype, np.floating):
        scale = 1.0 / (65535.0 if raw.dtype == np.uint16 else 255.0)
        return np.multiply(raw, dtype.type(scale), dtype=dtype)
    return raw.astype(dtype, copy=False)


# --------------------------------------------------------------------------------------------
# validation


def _is_number(v) -> bool:
    """A JSON number that fits a float (a 400-digit integer does not)."""
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        return False
    try:
        float(v)
    except OverflowError:
        return False
    return True


def _resolve_inside(root: Path, rel, where: str) -> Path:
    if not isinstance(rel, str) or not rel:
        raise InputError(f"{where}: must be a non-empty relative path string, got {rel!r}")
    if "\x00" in rel:
        raise InputError(f"{where}: {rel!r} contains a NUL byte")
    if os.path.isabs(rel) or rel.startswith(("/", "\\")):
        raise InputError(f"{where}: {rel!r} is an absolute path; paths must be relative "
                         f"to the stack folder")
    try:
        p = (root / rel).resolve(strict=False)
    except (RuntimeError, OSError) as exc:  # a symlink loop (RuntimeError up to Python 3.12)
        why = getattr(exc, "strerror", None) or "symbolic link loop"
        raise InputError(f"{where}: {rel!r} cannot be opened ({why})") from None
    try:
        p.relative_to(root)
    except ValueError:
        raise InputError(f"{where}: {rel!r} escapes the stack folder {one_line(root)}") from None
    try:
        st = os.stat(p)
    except FileNotFoundError:
        raise InputError(f"{where}: file not found: {one_line(p)}") from None
    except OSError as exc:
        raise InputError(f"{where}: {rel!r} cannot be opened ({exc.strerror})") from None
    if not stat.S_ISREG(st.st_mode):
        raise InputError(f"{where}: {rel!r} is not a file")
    return p


def _npy_info(path: Path, where: str) -> tuple[tuple[int, ...], np.dtype]:
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


def read_stack(path, *, limits: Limits | None = None) -> Stack:
    """Read and validate a stack folder (or its ``stack.json``).

    Parameters
    ----------
    path : str or Path
        The stack folder, or the ``stack.json`` file inside it.
    limits : Limits, optional
        Largest image and stack, checked from the headers before anything is decoded
        (default :class:`microfacet.io.limits.Limits`).

    Returns
    -------
    Stack
        The validated stack; no pixels are decoded.

    Raises
    ------
    InputError
        For every breach of the format, with one message naming the file and the key or
        slice at fault; also for images over ``limits``.

    Notes
    -----
    Keys this format does not define are kept in ``Stack.meta`` and logged as a warning
    naming the nearest known key (``colour_space`` → ``color_space``). Values that are valid
    but almost surely a unit mistake (a pixel size outside 0.01-100 µm, z in nm) are logged as
    warnings.
    """
    path = Path(path)
    if "\x00" in str(path):
        raise InputError(f"{one_line(path)}: the path contains a NUL byte")
    if path.is_file() and path.name == "stack.json":
        path = path.parent
    if not path.exists():
        raise InputError(f"{path}: stack folder not found")
    if not path.is_dir():
        raise InputError(f"{path}: not a stack folder (expected a folder with a stack.json)")
    root = path.resolve()
    jpath = root / "stack.json"
    if not jpath.is_file():
        raise InputError(f"{one_line(jpath)}: missing stack.json")
    meta = read_json(jpath)
    if not isinstance(meta, dict):
        raise InputError(f"{one_line(jpath)}: must hold a JSON object")
    return _stack_from_meta(root, meta, jpath, limits or Limits())


def _natural_key(name: str):
    import re

    return [int(t) if t.isdigit() else t.lower() for t in re.split(r"(\d+)", name)]


def stack_from_images(folder, *, pixel_size_um: float, z_step_um: float | None = None,
                      z_um: Sequence[float] | None = None, limits: Limits | None = None
                      ) -> Stack:
    """A validated stack from a plain folder of images that has no stack.json.

    The images (``.png``, ``.tif``, ``.tiff``, ``.jpg``, ``.jpeg``, any case) are taken in
    natural order (``image_2`` before ``image_10``); nothing is written. Validation is the
    same as :func:`read_stack`, as if a stack.json with these keys existed.

    Parameters
    ----------
    folder : str or Path
    pixel_size_um : float
        Lateral pixel size on the sample, µm.
    z_step_um : float, optional
        Slice *i* is at ``i * z_step_um`` (give this or ``z_um``).
    z_um : sequence of float, optional
        Slice heights in the natural file order, µm.
    """
    folder = Path(folder)
    if not folder.is_dir():
        raise InputError(f"{folder}: not a folder")
    root = folder.resolve()
    names = sorted((p.name for p in root.iterdir()
                    if p.is_file() and p.suffix.lower() in IMAGE_SUFFIXES), key=_natural_key)
    if not names:
        raise InputError(f"{root}: no images ({', '.join(IMAGE_SUFFIXES)}) in the folder")
    meta: dict = {"format": FORMAT, "pixel_size_um": pixel_size_um, "slices": names}
    if z_step_um is not None:
        meta["z_step_um"] = z_step_um
    if z_um is not None:
        meta["z_um"] = list(z_um)
    return _stack_from_meta(root, meta, root / "(no stack.json)", limits or Limits())


#: Median |slope| of a height map above which its unit is almost surely wrong (real
#: surfaces, even roll-dull or sand-blasted, have median slopes well below 1, i.e. 45°).
_IMPLAUSIBLE_MEDIAN_SLOPE = 5.0


def _warn_height_unit(h: np.ndarray, pixel_size_um: float, jpath: Path) -> None:
    """Warn when a height map in µm has slopes no surface has (heights in nm, most likely)."""
    step = max(1, min(h.shape) // 256)
    sub = h[::step, ::step]
    d = np.abs(np.diff(sub, axis=1)) / (pixel_size_um * step)
    d = d[np.isfinite(d)]
    if d.size and float(np.median(d)) > _IMPLAUSIBLE_MEDIAN_SLOPE:
        log.warning("%s: key 'height_um': the median surface slope is %.3g (%.2f°), which no "
                    "surface has; if the heights are in nm, divide them by 1000 (or check "
                    "pixel_size_um)", one_line(jpath), float(np.median(d)),
                    float(np.degrees(np.arctan(np.median(d)))))


def _check_consistent(shown, name, info, ref_name, ref_info) -> None:
    if info.shape != ref_info.shape:
        raise InputError(f"{shown}: {name}: size {info.shape[1]}x{info.shape[0]} differs from "
                         f"{ref_name} {ref_info.shape[1]}x{ref_info.shape[0]}")
    if info.dtype != ref_info.dtype:
        raise InputError(f"{shown}: {name}: bit depth {info.dtype.itemsize * 8} differs from "
                         f"{ref_name} ({ref_info.dtype.itemsize * 8}-bit); mixed bit depths")
    if info.channels != ref_info.channels:
        raise InputError(f"{shown}: {name}: {info.channels} channel(s) differ from "
                         f"{ref_name} ({ref_info.channels}); mixed grey and colour slices")


_TIFF_CODING = ("compression", "predictor", "planarconfig", "photometric", "bitspersample",
                "samplesperpixel", "fillorder", "sampleformat")


def _tiff_headers(tiff_path: Path, where: str, add) -> bool:
    """Read every page header of a multi-page TIFF in one pass (linear in the pages) and
    ``add(name, where, info)`` each; True when every page is encoded like the first."""
    import tifffile

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


def _warn_unknown_keys(meta: dict, jpath: Path) -> None:
    for key in meta:
        if key not in KNOWN_KEYS:
            near = difflib.get_close_matches(key, KNOWN_KEYS, n=1, cutoff=0.6)
            hint = f"; did you mean {near[0]!r}?" if near else " (kept, not used)"
            log.warning("%s: unknown key %r%s", one_line(jpath), key, hint)
    illum = meta.get("illumination")
    if isinstance(illum, dict):
        for key in illum:
            if key not in _ILLUMINATION_KEYS:
                near = difflib.get_close_matches(key, _ILLUMINATION_KEYS, n=1, cutoff=0.6)
                hint = f"; did you mean {near[0]!r}?" if near else " (not used)"
                log.warning("%s: key 'illumination': unknown key %r%s", one_line(jpath), key,
                            hint)


def _warn_implausible(jpath: Path, pixel_size_um: float, z_um: np.ndarray, shape) -> None:
    """Valid values that are almost surely a unit mistake (warnings, not errors)."""
    lo, hi = PLAUSIBLE_PIXEL_SIZE_UM
    if not lo <= pixel_size_um <= hi:
        log.warning("%s: key 'pixel_size_um': %g µm per pixel is outside %g-%g µm, where "
                    "optical microscopes are; check the unit (µm)", one_line(jpath),
                    pixel_size_um, lo, hi)
    if z_um.size >= 2:
        zs = np.sort(z_um)
        span = float(zs[-1] - zs[0])
        step = float(np.median(np.diff(zs)))
        field_um = max(shape) * pixel_size_um
        if span > field_um:
            log.warning("%s: key 'z_um': the slices span %g µm, more than the field of view "
                        "(%g µm wide); if z is in nm, divide it by 1000", one_line(jpath),
                        span, field_um)
        elif step < 1e-3:
            log.warning("%s: key 'z_um': slices %g µm apart is below any focus drive's "
                        "step; if z is in mm, multiply it by 1000", one_line(jpath), step)


def _stack_from_meta(root: Path, meta: dict, jpath: Path, limits: Limits) -> Stack:
    shown = one_line(jpath)

    def where(key):
        return f"{shown}: key {key!r}"

    _warn_unknown_keys(meta, jpath)

    fmt = meta.get("format")
    if fmt is None:
        raise InputError(f"{where('format')}: missing (expected {FORMAT!r})")
    if fmt != FORMAT:
        raise InputError(f"{where('format')}: {fmt!r} is not {FORMAT!r}")

    ps = meta.get("pixel_size_um")
    if ps is None:
        raise InputError(f"{where('pixel_size_um')}: missing")
    if not _is_number(ps) or not math.isfinite(ps) or ps <= 0:
        raise InputError(f"{where('pixel_size_um')}: must be a finite number > 0, got {ps!r}")

    # --- optional keys -------------------------------------------------------------------
    color_space = meta.get("color_space", "sRGB")
    if color_space not in _COLOR_SPACES:
        raise InputError(f"{where('color_space')}: {color_space!r} is not one of {_COLOR_SPACES}")
    illuminant = meta.get("illuminant", "D65")
    if not isinstance(illuminant, str) or not illuminant.strip():
        raise InputError(f"{where('illuminant')}: must be a non-empty name, got {illuminant!r}")
    illum = meta.get("illumination", {})
    if not isinstance(illum, dict):
        raise InputError(f"{where('illumination')}: must be an object, got {illum!r}")
    illumination = dict(_DEFAULT_ILLUMINATION)
    illumination.update(illum)
    na = illumination.get("numerical_aperture")
    if not _is_number(na) or not math.isfinite(na) or not 0 < na <= 1:
        raise InputError(f"{where('illumination')}: numerical_aperture must be a number in "
                         f"(0, 1], got {na!r}")
    if not isinstance(illumination.get("geometry"), str):
        raise InputError(f"{where('illumination')}: geometry must be a string")

    from ..optics import constants as optics

    known = optics.known_sets()
    names = {}
    for key, default in (("film", optics.DEFAULT_FILM), ("substrate", optics.DEFAULT_SUBSTRATE)):
        name = meta.get(key, default)
        if name not in known:
            raise InputError(f"{where(key)}: unknown optical-constant set {name!r}; known: "
                             f"{', '.join(known)}")
        names[key] = name
    exposure = meta.get("exposure")
    if exposure is not None and (not _is_number(exposure) or not math.isfinite(exposure)
                                 or exposure <= 0):
        raise InputError(f"{where('exposure')}: must be a finite number > 0, got {exposure!r}")

    # --- export ----------------------------------------------------------------------------
    export_height = export_image = None
    export_shape = None
    has_h, has_img = "height_um" in meta, "image" in meta
    if has_h != has_img:
        missing = "image" if has_h else "height_um"
        raise InputError(f"{where(missing)}: missing (a microscope export needs both "
                         f"'height_um' and 'image')")
    if has_h:
        export_height = _resolve_inside(root, meta["height_um"], where("height_um"))
        wh = f"{where('height_um')} ({export_height.name})"
        if export_height.suffix.lower() == ".npy":
            hshape, hdtype = _npy_info(export_height, wh)
            if hdtype.kind != "f":
                raise InputError(f"{wh}: height map must be floating point, got {hdtype}")
        elif export_height.suffix.lower() in (".tif", ".tiff"):
            import tifffile

            try:
                with tifffile.TiffFile(export_height) as tf:
                    page = tf.pages[0]
                    hshape, hdtype = tuple(page.shape), np.dtype(page.dtype)
                    offs, cnts = page.dataoffsets, page.databytecounts
            except Exception as exc:
                raise InputError(f"{wh}: unreadable TIFF ({exc})") from None
            if any(o + c > export_height.stat().st_size for o, c in zip(offs, cnts)):
                raise InputError(f"{wh}: truncated TIFF")
            if hdtype.kind != "f":
                raise InputError(f"{wh}: height map must be floating point, got {hdtype}")
        else:
            raise InputError(f"{wh}: height map must be a TIFF or .npy file")
        if len(hshape) != 2:
            raise InputError(f"{wh}: height map must be 2-D, got shape {hshape}")
        limits.check_image(hshape, wh)
        export_image = _resolve_inside(root, meta["image"], where("image"))
        wi = f"{where('image')} ({one_line(export_image.name)})"
        info = _image_info(export_image, wi)
        limits.check_image(info.shape, wi)
        if info.shape != hshape:
            raise InputError(f"{where('image')} ({export_image.name}): size {info.shape} does not "
                             f"match the height map {hshape}")
        export_shape = info

    # --- slices ----------------------------------------------------------------------------
    has_slices, has_tiff = "slices" in meta, "tiff" in meta
    if has_slices and has_tiff:
        raise InputError(f"{where('tiff')}: give either 'slices' or 'tiff', not both")
    if not has_slices and not has_tiff and not has_h:
        raise InputError(f"{where('slices')}: missing (give 'slices', 'tiff', or an export "
                         f"'height_um' + 'image')")
    slice_paths: list[Path] = []
    tiff_path = None
    if has_slices:
        sl = meta["slices"]
        if not isinstance(sl, list) or not sl:
            raise InputError(f"{where('slices')}: must be a non-empty list of relative paths")
        for i, rel in enumerate(sl):
            p = _resolve_inside(root, rel, f"{where('slices')}[{i}]")
            slice_paths.append(p)
        n = len(slice_paths)
    elif has_tiff:
        tiff_path = _resolve_inside(root, meta["tiff"], where("tiff"))
        if tiff_path.suffix.lower() not in (".tif", ".tiff"):
            raise InputError(f"{where('tiff')}: {tiff_path.name} is not a .tif/.tiff file")
        n = None
    else:
        n = 0

    # z
    if n != 0:
        has_z, has_step = "z_um" in meta, "z_step_um" in meta
        if has_z and has_step:
            raise InputError(f"{where('z_step_um')}: give either 'z_um' or 'z_step_um', not both")
        if not has_z and not has_step:
            raise InputError(f"{where('z_um')}: missing (give 'z_um' or 'z_step_um')")

    # headers, each checked against the limits and against the first as soon as it is read
    infos: list[tuple[str, _ImageInfo]] = []

    def add(name, where_text, info):
        limits.check_image(info.shape, where_text)
        if infos:
            _check_consistent(shown, name, info, *infos[0])
        infos.append((name, info))

    tiff_uniform = False
    if tiff_path is not None:
        tiff_uniform = _tiff_headers(tiff_path, where("tiff"), add)
        n = len(infos)
        if n == 0:
            raise InputError(f"{where('tiff')} ({tiff_path.name}): TIFF has no pages")
        limits.check_stack(n, infos[0][1].shape, where("tiff"))

    if n:
        if "z_um" in meta:
            z = meta["z_um"]
            if not isinstance(z, list):
                raise InputError(f"{where('z_um')}: must be a list of numbers")
            if len(z) != n:
                what = "slices" if has_slices else f"pages in {tiff_path.name}"
                raise InputError(f"{where('z_um')}: has {len(z)} values but there are {n} {what}")
            for i, v in enumerate(z):
                if not _is_number(v) or not math.isfinite(v):
                    raise InputError(f"{where('z_um')}[{i}]: must be a finite number, got {v!r}")
            z_um = np.asarray(z, dtype=np.float64)
            if np.unique(z_um).size != n:
                vals, counts = np.unique(z_um, return_counts=True)
                raise InputError(f"{where('z_um')}: duplicate height {vals[counts > 1][0]:g} µm")
        else:
            s = meta["z_step_um"]
            if not _is_number(s) or not math.isfinite(s) or s == 0:
                raise InputError(f"{where('z_step_um')}: must be a finite non-zero number, got {s!r}")
            z_um = np.arange(n, dtype=np.float64) * float(s)
    else:
        z_um = np.zeros(0, dtype=np.float64)

    if has_slices:
        for i, p in enumerate(slice_paths):
            wt = f"{where('slices')}[{i}] ({one_line(p.name)})"
            add(f"slices[{i}] ({one_line(p.name)})", wt, _image_info(p, wt))
        limits.check_stack(n, infos[0][1].shape, where("slices"))

    ref_info = infos[0][1] if infos else export_shape
    if infos and export_shape is not None and export_shape.shape != ref_info.shape:
        raise InputError(f"{where('image')}: export size {export_shape.shape} differs from the "
                         f"slices {ref_info.shape}")
    _warn_implausible(jpath, float(ps), z_um, ref_info.shape)

    stack = Stack(
        path=root,
        pixel_size_um=float(ps),
        z_um=z_um,
        slice_paths=tuple(slice_paths),
        tiff_path=tiff_path,
        shape=ref_info.shape,
        dtype=ref_info.dtype,
        channels=ref_info.channels,
        color_space=color_space,
        illuminant=illuminant,
        illumination=illumination,
        film=names["film"],
        substrate=names["substrate"],
        exposure=None if exposure is None else float(exposure),
        export_height_path=export_height,
        export_image_path=export_image,
        meta=meta,
        tiff_uniform=tiff_uniform,
    )
    log.debug("read stack %s: %d slices %s %s x%d", root, stack.n_slices, stack.shape,
              stack.dtype, stack.channels)
    return stack


# --------------------------------------------------------------------------------------------
# writing


def write_stack_json(folder, *, pixel_size_um: float, slices: Sequence[str] | None = None,
                     tiff: str | None = None, z_um: Sequence[float] | None = None,
                     z_step_um: float | None = None, validate: bool = True,
                     **optional) -> Path:
    """Write ``folder/stack.json`` for images that are already there.

    Parameters
    ----------
    folder : str or Path
        The stack folder (must exist).
    pixel_size_um : float
        Lateral pixel size on the sample, µm.
    slices : sequence of str, optional
        Relative image paths, one per slice, in file order. Give this or ``tiff``.
    tiff : str, optional
        Relative path of a multi-page TIFF.
    z_um : sequence of float, optional
        Stage height of each slice, µm. Give this or ``z_step_um``.
    z_step_um : float, optional
        Slice *i* is at ``i * z_step_um``.
    validate : bool
        Read the stack back with :func:`read_stack` (raises on any problem).
    **optional
        Further keys written as given (``color_space``, ``illuminant``, ``illumination``,
        ``film``, ``substrate``, ``exposure``, ``height_um``, ``image``, or project keys).

    Returns
    -------
    Path
        The path of the written stack.json.
    """
    folder = Path(folder)
    meta: dict = {"format": FORMAT, "pixel_size_um": float(pixel_size_um)}
    if slices is not None:
        meta["slices"] = [str(s) for s in slices]
    if tiff is not None:
        meta["tiff"] = str(tiff)
    if z_um is not None:
        meta["z_um"] = [float(v) for v in z_um]
    if z_step_um is not None:
        meta["z_step_um"] = float(z_step_um)
    meta.update(optional)
    out = folder / "stack.json"
    tmp = folder / ".stack.json.tmp"
    tmp.write_text(json.dumps(meta, indent=2) + "\n", encoding="utf-8")
    os.replace(tmp, out)
    if validate:
        read_stack(folder)
    return out


def write_stack(folder, images, *, pixel_size_um: float, z_um: Sequence[float] | None = None,
                z_step_um: float | None = None, fmt: str = "png", multipage: bool = False,
                validate: bool = True, **optional) -> Path:
    """Write images as a new stack folder with its stack.json.

    Parameters
    ----------
    folder : str or Path
        Created if absent.
    images : iterable of ndarray
        uint8 or uint16 images, (H, W) grey or (H, W, 3) RGB, one per slice; consumed lazily
        (a generator keeps memory at one image).
    pixel_size_um, z_um, z_step_um, **optional
        As in :func:`write_stack_json`.
    fmt : {"png", "tif", "jpg"}
        Slice file type (``multipage=True`` forces one multi-page ``stack.tif``).
    multipage : bool
        Write one multi-page TIFF instead of a slice folder.

    Returns
    -------
    Path
        The stack.json path.
    """
    import cv2

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    if fmt not in ("png", "tif", "jpg"):
        raise ValueError(f"fmt must be 'png', 'tif' or 'jpg', not {fmt!r}")
    names = []
    if multipage:
        import tifffile

        with tifffile.TiffWriter(folder / "stack.tif") as tw:
            for img in images:
                img = np.asarray(img)
                tw.write(img, photometric="rgb" if img.ndim == 3 else "minisblack",
                         contiguous=False)
        kw = {"tiff": "stack.tif"}
    else:
        (folder / "slices").mkdir(exist_ok=True)
        for i, img in enumerate(images):
            img = np.asarray(img)
            name = f"slices/{i:03d}.{fmt}"
            if fmt == "tif":
                import tifffile

                tifffile.imwrite(folder / name, img,
                                 photometric="rgb" if img.ndim == 3 else "minisblack")
            else:
                from .images import write_image

                write_image(folder / name, img,
                            params=[cv2.IMWRITE_JPEG_QUALITY, 95] if fmt == "jpg" else ())
            names.append(name)
        kw = {"slices": names}
    return write_stack_json(folder, pixel_size_um=pixel_size_um, z_um=z_um, z_step_um=z_step_um,
                            validate=validate, **kw, **optional)
