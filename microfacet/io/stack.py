"""Reading and writing focus stacks in the ``microfacet-stack/1`` format.

A stack is a folder with a ``stack.json`` beside its images (see the project's stack-format
specification). :func:`read_stack` validates *everything* before any work starts and returns a
:class:`Stack`; bad input raises :class:`microfacet.core.errors.InputError` with one message that
names the file and the key or slice at fault.

Validation (:mod:`microfacet.io.stack_checks`) reads image *headers* only, never decodes
pixels (:mod:`microfacet.io.images`). Corrupt *compressed data* inside an intact container is
only found when the slice is decoded; :meth:`Stack.iter_slices` then raises
:class:`~microfacet.core.errors.InputError` naming the slice. Decoding every slice just to
validate would double the cost of the height step, so that trade-off is deliberate.

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

import logging
import math
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..core.defaults import DEFAULT_ILLUMINANT
from ..core.errors import InputError, one_line
from ..core.lazy import load
from .images import IMAGE_SUFFIXES, JpegTables, MultiPageTiff, convert_samples, decode_image
from .jsonfile import read_json
from .limits import Limits
from .stack_checks import DEFAULT_ILLUMINATION, FORMAT, find_images, stack_fields, warn_height_unit
from .stack_write import write_stack, write_stack_json
from .vendor import is_vendor, vendor_planes

tifffile = load("tifffile")

__all__ = [
    "FORMAT",
    "Stack",
    "StackSource",
    "find_images",
    "read_stack",
    "stack_from_images",
    "write_stack",
    "write_stack_json",
]

log = logging.getLogger(__name__)


# --------------------------------------------------------------------------------------------
# the Stack


@dataclass(frozen=True, eq=False)
class Stack:
    """A validated focus stack (``microfacet-stack/1``).

    Attributes
    ----------
    path : Path
        The stack folder (absolute).
    pixel_size_yx_um : tuple of float
        ``(y, x)`` size of one pixel on the sample, µm (equal for square pixels).
    pixel_size_um : float or list of float
        As ``stack.json`` writes it: one number for square pixels, else ``[y, x]``.
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
    series : int
        The z-stack of a vendor file the slices come from (0 for other stacks).
    jpeg : JpegTables or None
        JPEG slices: the coarsest slice's quantization (largest luma DC step), which the
        colour noise model counts; None for lossless slices.
    sources : dict
        Where ``"pixel_size_um"`` and ``"z_um"`` came from: ``"stack.json"``, ``"given"``
        (the caller's value), ``"instrument file NAME"`` or ``"ImageJ metadata of NAME"`` (or
        OME, TIFF resolution tags).
    """

    path: Path
    pixel_size_yx_um: tuple[float, float]
    z_um: np.ndarray
    slice_paths: tuple[Path, ...]
    tiff_path: Path | None
    shape: tuple[int, int]
    dtype: np.dtype
    channels: int
    color_space: str = "sRGB"
    illuminant: str = DEFAULT_ILLUMINANT
    illumination: dict = field(default_factory=lambda: dict(DEFAULT_ILLUMINATION))
    film: str = ""
    substrate: str = ""
    exposure: float | None = None
    export_height_path: Path | None = None
    export_image_path: Path | None = None
    meta: dict = field(default_factory=dict)
    sources: dict = field(default_factory=dict)
    tiff_uniform: bool = field(default=False, repr=False)
    series: int = 0
    jpeg: JpegTables | None = None

    def __post_init__(self):
        reader = None
        if self.tiff_path and is_vendor(self.tiff_path):
            reader = vendor_planes(self.tiff_path, self.tiff_uniform, self.series)
        elif self.tiff_path:
            reader = MultiPageTiff(self.tiff_path, self.tiff_uniform)
        object.__setattr__(self, "_tiff", reader)

    # -- properties ----------------------------------------------------------------------
    @property
    def square_pixels(self) -> bool:
        """True when the pixel is as tall as it is wide (to 1 part in 10⁶)."""
        y, x = self.pixel_size_yx_um
        return math.isclose(y, x, rel_tol=1e-6)

    @property
    def pixel_size_um(self) -> float | list[float]:
        """The pixel size as ``stack.json`` writes it, µm: one number for square pixels,
        else ``[y, x]`` (arithmetic uses :attr:`pixel_size_yx_um`)."""
        y, x = self.pixel_size_yx_um
        return float(x) if self.square_pixels else [float(y), float(x)]

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
            raw = decode_image(self.slice_paths[index], where, channels=self.channels)
        if raw.shape[:2] != self.shape or raw.dtype != self.dtype or (
                (raw.ndim == 3) != (self.channels == 3)):
            raise InputError(f"{where}: decoded image {raw.shape} {raw.dtype} does not match "
                             f"its header {self.shape} {self.dtype} x{self.channels}")
        return convert_samples(raw, dtype)

    def iter_slices(self, dtype=np.float32, *, order: str = "file"
                    ) -> Iterator[tuple[int, float, np.ndarray]]:
        """Yield ``(index, z_um, image)`` one slice at a time (one decoded slice alive at a
        time: memory does not grow with the number of slices).

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
            raise InputError(f"{self.path / 'stack.json'}: key 'height_um': the stack has no "
                             f"export")
        p = self.export_height_path
        if p.suffix.lower() == ".npy":
            h = np.load(p, allow_pickle=False)
        elif p.suffix.lower() in (".tif", ".tiff"):
            h = tifffile.imread(p)
        else:  # an instrument file, validated by read_stack
            h = load("microfacet.io.instruments").read_height_map(p).height_um
        h = np.array(h, dtype=np.float32)
        h[~np.isfinite(h)] = np.nan
        warn_height_unit(h, self.pixel_size_yx_um, self.path / "stack.json")
        return h

    def read_reference(self, key: str, given=None, *, where_given: str = ""):
        """A reference image of the stack's camera (a white standard, a flat field): the file
        ``given`` (an option's value, named ``where_given`` in errors), else the one
        stack.json's ``key`` names (a path inside the stack folder); None without either.
        Returns ``(image, name, where)``: float32 in [0, 1] as encoded, the file's name, and
        the key or option it came from for messages.

        Raises
        ------
        InputError
            The file is missing or not an image (one line naming it and the key or option).
        """
        where = where_given
        path = Path(given) if given else None
        if path is None and self.meta.get(key):
            path = self.path / self.meta[key]
            where = f"{one_line(self.path / 'stack.json')}: key '{key}'"
        if path is None:
            return None
        if not path.is_file():
            raise InputError(f"{where}: {one_line(path)} not found")
        where = f"{where} ({one_line(path.name)})"
        return convert_samples(decode_image(path, where), np.float32), path.name, where

    def read_export_image(self, dtype=np.float32) -> np.ndarray:
        """The microscope export's all-in-focus image, (H, W) or (H, W, 3); see
        :meth:`read_slice`."""
        if self.export_image_path is None:
            raise InputError(f"{self.path / 'stack.json'}: key 'image': the stack has no export")
        return convert_samples(decode_image(self.export_image_path,
                                f"export image ({one_line(self.export_image_path)})",
                                channels=self.channels), dtype)


def read_stack(path, *, pixel_size_um: float | None = None, z_step_um: float | None = None,
               limits: Limits | None = None, series: int | None = None) -> Stack:
    """Read and validate a stack folder (or its ``stack.json``), or a plain folder of images.

    Parameters
    ----------
    path : str or Path
        The stack folder, or the ``stack.json`` file inside it. A folder without stack.json
        is read as in :func:`stack_from_images`; nothing is written into it.
    pixel_size_um : float, optional
        Pixel size on the sample, µm, used when stack.json has none; it wins over the images'
        metadata (OME-TIFF, ImageJ TIFF), and a stack.json value wins over it.
    z_step_um : float, optional
        Slice *i* is at ``i * z_step_um`` µm, with the same precedence.
    limits : Limits, optional
        Largest image and stack, checked from the headers before anything is decoded
        (default :class:`microfacet.io.limits.Limits`).
    series : int, optional
        Which z-stack of a vendor file (``.czi`` scene, ``.nd2`` XY position, ``.lif``
        image), counted from 0; it wins over stack.json's ``series`` (default 0).

    Returns
    -------
    Stack
        The validated stack; no pixels are decoded. ``Stack.sources`` says where the pixel
        size and the z positions came from.

    Raises
    ------
    InputError
        For every breach of the format, with one message naming the file and the key or
        slice at fault (for a plain folder without the values: the parameters to give);
        also for images over ``limits``.

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
    if path.is_file() and is_vendor(path):
        return vendor_stack(path, pixel_size_um=pixel_size_um, z_step_um=z_step_um,
                            limits=limits, series=series)
    if not path.exists():
        raise InputError(f"{path}: stack folder not found")
    if not path.is_dir():
        raise InputError(f"{path}: not a stack folder (expected a folder with a stack.json)")
    root = path.resolve()
    jpath = root / "stack.json"
    if not jpath.is_file():
        return stack_from_images(root, pixel_size_um=pixel_size_um, z_step_um=z_step_um,
                                 limits=limits)
    meta = read_json(jpath)
    if not isinstance(meta, dict):
        raise InputError(f"{one_line(jpath)}: must hold a JSON object")
    return Stack(**stack_fields(root, meta, jpath, limits or Limits(),
                                given={"pixel_size_um": pixel_size_um, "z_step_um": z_step_um,
                                       "series": series}))


def stack_from_images(folder, *, pixel_size_um: float | None = None,
                      z_step_um: float | None = None, z_um: Sequence[float] | None = None,
                      limits: Limits | None = None) -> Stack:
    """A validated stack from a plain folder of images, ignoring any stack.json in it.

    The images (``.png``, ``.tif``, ``.tiff``, ``.jpg``, ``.jpeg``, any case) are found by
    :func:`find_images`; nothing is written. Validation is the same as :func:`read_stack`,
    as if a stack.json with these keys existed. Values not given are taken from the first
    TIFF's metadata (:func:`~microfacet.io.tiff_meta.tiff_scale`).

    Parameters
    ----------
    folder : str or Path
    pixel_size_um : float, optional
        Lateral pixel size on the sample, µm.
    z_step_um : float, optional
        Slice *i* is at ``i * z_step_um`` µm.
    z_um : sequence of float, optional
        Slice heights in the natural file order, µm (instead of ``z_step_um``).
    limits : Limits, optional
        As in :func:`read_stack`.
    """
    folder = Path(folder)
    if not folder.is_dir():
        raise InputError(f"{folder}: not a folder")
    root = folder.resolve()
    found = find_images(root)
    if not found:
        raise InputError(f"{one_line(root / 'stack.json')}: missing stack.json (and no images "
                         f"({', '.join(IMAGE_SUFFIXES)}) in the folder)" if not
                         (root / "stack.json").is_file() else
                         f"{one_line(root)}: no images ({', '.join(IMAGE_SUFFIXES)}) in the "
                         f"folder itself")
    meta: dict = {"format": FORMAT, **found}
    if z_um is not None:
        meta["z_um"] = list(z_um)
    st = Stack(**stack_fields(root, meta, root / "(no stack.json)", limits or Limits(),
                              given={"pixel_size_um": pixel_size_um,
                                     "z_step_um": None if z_um is not None else z_step_um},
                              plain=True))
    names = found.get("slices") or [found.get("tiff", "")]
    z = np.asarray(st.z_um, dtype=float)
    log.info("%s: plain folder, %d slices in natural order (%s ... %s), z %.4g to %.4g µm (%s), "
             "pixel size %s µm (%s)", one_line(root), st.n_slices, one_line(names[0]),
             one_line(names[-1]), float(z.min()) if z.size else 0.0,
             float(z.max()) if z.size else 0.0, st.sources.get("z_step_um", "given"),
             "x".join(f"{v:g}" for v in st.pixel_size_yx_um),
             st.sources.get("pixel_size_um", "given"))
    return st


def vendor_stack(path, *, pixel_size_um=None, z_step_um=None, limits: Limits | None = None,
                 series: int | None = None) -> Stack:
    """A validated stack from one vendor z-stack file (``.czi``, ``.nd2``, ``.lif``): the Z
    planes of one series are the slices; the pixel size and z step come from the file unless
    given (the caller's values win, as over TIFF metadata). Nothing is written beside it.

    Parameters
    ----------
    path : str or Path
        The file.
    pixel_size_um, z_step_um, limits, series
        As in :func:`read_stack`.
    """
    path = Path(path).resolve()
    meta = {"format": FORMAT, "tiff": path.name}
    st = Stack(**stack_fields(path.parent, meta, path, limits or Limits(),
                              given={"pixel_size_um": pixel_size_um, "z_step_um": z_step_um,
                                     "series": series}, plain=True))
    step = f"{np.median(np.diff(st.z_um)):.4g}" if st.n_slices > 1 else "-"
    log.info("%s: series %d, %d planes, z step %s µm (%s), pixel size %s µm (%s)",
             one_line(path), st.series, st.n_slices, step,
             st.sources.get("z_um", "given"), "x".join(f"{v:g}" for v in st.pixel_size_yx_um),
             st.sources.get("pixel_size_um", "given"))
    return st


@dataclass(frozen=True)
class StackSource:
    """Where a stack is and how to read it: a stack folder, or a plain folder of images with
    ``pixel_size_um`` and ``z_step_um``; image-size ``limits`` (:class:`~microfacet.io.limits.
    Limits`) checked from the headers before any work."""

    path: object
    pixel_size_um: object = None
    z_step_um: float | None = None
    limits: object = None
    series: int | None = None

    def open(self) -> Stack:
        return read_stack(self.path, limits=self.limits, pixel_size_um=self.pixel_size_um,
                          z_step_um=self.z_step_um, series=self.series)
