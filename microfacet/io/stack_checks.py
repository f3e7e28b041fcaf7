"""Validation of a ``stack.json`` (format ``microfacet-stack/1``) before any work.

:func:`stack_fields` checks every key against its spec and the rules between keys
(:mod:`microfacet.io.stack_schema`), then what the keys name: the files inside the folder and
every image header (each against the :class:`~microfacet.io.limits.Limits` as soon as it is
read), and returns the fields of a :class:`~microfacet.io.stack.Stack`; any breach raises
:class:`~microfacet.core.errors.InputError` with one message naming the file and the key or
slice at fault. Keys the format does not define, and valid values that are almost surely a
unit mistake, are logged as warnings (docs/stack-format.md).

The pixel size and the z spacing come, in this order of precedence, from stack.json, from the
values the caller gives (``given``), from a microscope export's instrument file, or from the
metadata of the first TIFF (:func:`~.tiff_meta.tiff_scale`: OME-XML, ImageJ, resolution tags
in cm).
"""

from __future__ import annotations

import difflib
import logging
import math
import os
import re
import stat
from dataclasses import dataclass, field
from pathlib import Path
from typing import NamedTuple

import numpy as np

from ..core.errors import InputError, one_line
from ..core.lazy import load
from ..core.pixels import pixel_size_yx
from .images import IMAGE_SUFFIXES, ImageInfo, image_info, npy_info, read_tiff_headers
from .limits import Limits
from .stack_schema import (
    DEFAULT_ILLUMINATION,
    FORMAT,
    KNOWN_KEYS,
    SPECS,
    check_relative_path,
    check_rules,
    check_value,
    checked_values,
    is_number,
    number_reason,
    present,
)
from .tiff_meta import tiff_scale
from .vendor import is_vendor, vendor_headers, vendor_scale

tifffile = load("tifffile")

__all__ = ["DEFAULT_ILLUMINATION", "FORMAT", "KNOWN_KEYS", "PLAUSIBLE_PIXEL_SIZE_UM",
           "find_images", "stack_fields", "warn_height_unit"]

log = logging.getLogger("microfacet.io.stack")

#: Pixel sizes outside this range (µm) are almost surely a unit mistake: warned about.
PLAUSIBLE_PIXEL_SIZE_UM = SPECS["pixel_size_um"].plausible
_TIFF = (".tif", ".tiff")


# ------------------------------------------------------------------- the stack being checked
@dataclass
class _Check:
    """A stack.json being checked: the folder, the keys, the file's name in messages and
    the image headers read so far."""

    root: Path
    meta: dict
    jpath: Path
    limits: Limits
    given: dict
    plain: bool
    infos: list = field(default_factory=list)
    series: int = 0

    @property
    def shown(self) -> str:
        return one_line(self.jpath)

    def where(self, key: str) -> str:
        return f"{self.shown}: key {key!r}"

    def has(self, key: str) -> bool:
        return present(self.meta, key)

    def add(self, name: str, where_text: str, info: ImageInfo) -> None:
        """One image header: checked against the limits and the first header."""
        self.limits.check_image(info.shape, where_text)
        if self.infos:
            _check_consistent(self.shown, name, info, *self.infos[0])
        self.infos.append((name, info))


def _check_given(given: dict) -> None:
    """The caller's ``pixel_size_um`` and ``z_step_um`` (an error names the parameter)."""
    for key, value in given.items():
        if value is None:
            continue
        if key == "pixel_size_um":
            try:
                pixel_size_yx(value)
            except ValueError:
                raise InputError(f"must be a finite number > 0 or a [y, x] pair, got "
                                 f"{value!r}", param=key) from None
            continue
        reason = number_reason(SPECS[key], value)
        if reason is not None:
            raise InputError(reason, param=key)


# ------------------------------------------------------------------------------ files
def _resolve_inside(root: Path, rel, where: str) -> Path:
    """The file ``rel`` names, which must be inside ``root``."""
    check_relative_path(rel, where)
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


def _file(c: _Check, key: str, index: int | None = None) -> Path:
    """The file of a path key (of item ``index`` of a list of paths), of a type its spec
    allows."""
    spec = SPECS[key]
    rel = c.meta[key] if index is None else c.meta[key][index]
    where = c.where(key) if index is None else f"{c.where(key)}[{index}]"
    p = _resolve_inside(c.root, rel, where)
    if spec.suffixes and p.suffix.lower() not in spec.suffixes:
        raise InputError(f"{where}: {p.name} is not a {'/'.join(spec.suffixes)} file")
    return p


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


def _slices(c: _Check) -> tuple[Path, ...]:
    """The files of ``slices``, every header read and checked."""
    paths = tuple(_file(c, "slices", i) for i in range(len(c.meta["slices"])))
    for i, p in enumerate(paths):
        wt = f"{c.where('slices')}[{i}] ({one_line(p.name)})"
        c.add(f"slices[{i}] ({one_line(p.name)})", wt, image_info(p, wt))
    c.limits.check_stack(len(paths), c.infos[0][1].shape, c.where("slices"))
    return paths


def _multipage(c: _Check) -> tuple[Path, bool]:
    """The file of ``tiff``, every page header read and checked; True when every page is
    encoded like the first."""
    path = _file(c, "tiff")
    if is_vendor(path):
        uniform = vendor_headers(path, c.where("tiff"), c.add, c.series)
    elif c.series:
        raise InputError(f"{c.where('tiff')} ({path.name}): a TIFF holds one series; `series` "
                         f"{c.series} is for a .czi, .nd2 or .lif file")
    else:
        uniform = read_tiff_headers(path, c.where("tiff"), c.add)
    if not c.infos:
        raise InputError(f"{c.where('tiff')} ({path.name}): the file has no pages or planes")
    c.limits.check_stack(len(c.infos), c.infos[0][1].shape, c.where("tiff"))
    return path, uniform


# ----------------------------------------------------------------------------- the export
class _Export(NamedTuple):
    """A microscope export: the height map, the image, its header, and the pixel size the
    instrument file gives (None: none)."""

    height: Path | None = None
    image: Path | None = None
    info: ImageInfo | None = None
    pixel_size_um: object = None


def _tiff_height_header(path: Path, wh: str) -> tuple[tuple, np.dtype]:
    try:
        with tifffile.TiffFile(path) as tf:
            page = tf.pages[0]
            shape, dtype = tuple(page.shape), np.dtype(page.dtype)
            offs, cnts = page.dataoffsets, page.databytecounts
    except Exception as exc:
        raise InputError(f"{wh}: unreadable TIFF ({exc})") from None
    if any(o + c > path.stat().st_size for o, c in zip(offs, cnts)):
        raise InputError(f"{wh}: truncated TIFF")
    return shape, dtype


def _instrument_header(path: Path, wh: str) -> tuple[tuple, object]:
    """Shape and pixel size of an instrument file (Keyence, Zygo, Digital Surf, ...)."""
    try:
        # looked up here, not at import: the module may not be installed
        hm = load("microfacet.io.instruments").read_height_map(path)
    except ModuleNotFoundError as exc:
        if exc.name != "microfacet.io.instruments":
            raise
        raise InputError(f"{wh}: height map must be a TIFF or .npy file") from None
    except (InputError, OSError, ValueError) as exc:
        raise InputError(f"{wh}: {one_line(exc)}") from None
    return tuple(hm.height_um.shape), hm.pixel_size_um


def _height_map_header(path: Path, wh: str) -> tuple[tuple, object]:
    """Shape of a height map (floating point) and the pixel size its file gives, if any."""
    suffix = path.suffix.lower()
    if suffix == ".npy":
        shape, dtype = npy_info(path, wh)
    elif suffix in _TIFF:
        shape, dtype = _tiff_height_header(path, wh)
    else:
        shape, px = _instrument_header(path, wh)
        return shape, px
    if dtype.kind != "f":
        raise InputError(f"{wh}: height map must be floating point, got {dtype}")
    return shape, None


def _export(c: _Check) -> _Export:
    """The microscope export (``height_um`` + ``image``), headers checked."""
    if not c.has("height_um"):
        return _Export()
    height = _file(c, "height_um")
    wh = f"{c.where('height_um')} ({height.name})"
    hshape, px = _height_map_header(height, wh)
    if len(hshape) != 2:
        raise InputError(f"{wh}: height map must be 2-D, got shape {hshape}")
    c.limits.check_image(hshape, wh)
    image = _file(c, "image")
    wi = f"{c.where('image')} ({one_line(image.name)})"
    info = image_info(image, wi)
    c.limits.check_image(info.shape, wi)
    if info.shape != hshape:
        raise InputError(f"{c.where('image')} ({image.name}): size {info.shape} does not "
                         f"match the height map {hshape}")
    return _Export(height, image, info, px)


# --------------------------------------------------- pixel size and z: where they come from
def _differs(given, used, where: str) -> None:
    """Warn when the caller gave a value that stack.json overrides."""
    if given is not None and is_number(used) and not math.isclose(given, used, rel_tol=1e-9):
        log.warning("%s: %g µm is used, not the given %g µm (stack.json wins)", where, used,
                    given)


def _missing(c: _Check, where: str, *, need_z: bool, has_ps: bool = False) -> None:
    """Raise the one-line error for a pixel size or z spacing found nowhere."""
    if not c.plain:
        hint = "give 'z_um' or 'z_step_um'" if has_ps else "not in the image metadata either"
        raise InputError(f"{where}: missing ({hint})")
    what = " and ".join(n for n, need in (("`pixel_size_um`", not has_ps),
                                           ("`z_step_um`", need_z)) if need)
    found = c.meta.get("slices") or [c.meta.get("tiff")]
    raise InputError(f"{one_line(c.root / 'stack.json')}: missing stack.json; to read the "
                     f"{len(found)} image(s) in the folder ({one_line(found[0])} ...) as a "
                     f"stack give {what} (their metadata has no such value), or write a "
                     f"stack.json (microfacet init)")


def _metadata_scale(c: _Check, files: list, tiff_path: Path | None, need: bool):
    """The scale in the first TIFF's metadata (the multi-page TIFF, the first slice or the
    export's height map) when a value is needed and there is one."""
    if need and tiff_path is not None and is_vendor(tiff_path):
        return vendor_scale(tiff_path, c.where("tiff"), c.series)
    first = next((p for p in files if p is not None and p.suffix.lower() in _TIFF), None)
    if first is None or not need:
        return None
    return tiff_scale(first, c.where("tiff" if tiff_path else "slices"))


def _size_yx(value, where: str) -> tuple[float, float]:
    """A ``pixel_size_um`` (a number, or ``[y, x]``) as ``(y, x)`` µm."""
    check_value(SPECS["pixel_size_um"], value, where)
    vals = value if isinstance(value, list) else [value]
    return (float(vals[0]), float(vals[-1]))


def _pixel_size(c: _Check, ps, export: _Export, scale, need_z: bool):
    """``(y, x)`` µm and where it came from."""
    given = c.given.get("pixel_size_um")
    if ps is not None:
        yx = _size_yx(ps, c.where("pixel_size_um"))
        if given is not None:
            for g, used in zip(pixel_size_yx(given), yx):
                _differs(g, used, c.where("pixel_size_um"))
        return yx, "stack.json"
    if given is not None:
        return pixel_size_yx(given), "given"
    if export.pixel_size_um is not None:
        yx = _size_yx([float(v) for v in export.pixel_size_um], c.where("height_um"))
        return yx, f"instrument file {one_line(export.height.name)}"
    if scale is not None and scale.pixel_size_yx_um is not None:
        return scale.pixel_size_yx_um, scale.source
    _missing(c, c.where("pixel_size_um"),
             need_z=need_z and (scale is None or scale.z_step_um is None))


def _z_step(c: _Check, scale) -> tuple[float | None, str]:
    """The z step (None: the positions are stack.json's) and where z came from."""
    given = c.given.get("z_step_um")
    if c.has("z_um") or c.has("z_step_um"):
        if c.has("z_step_um"):
            _differs(given, c.meta["z_step_um"], c.where("z_step_um"))
        return None, "given" if c.plain else "stack.json"
    if given is not None:
        return float(given), "given"
    if scale is not None and scale.z_step_um is not None:
        return scale.z_step_um, scale.source
    _missing(c, c.where("z_um"), need_z=True, has_ps=True)


def _z_positions(c: _Check, n: int, step: float | None, what: str) -> np.ndarray:
    """The height of each of the ``n`` slices, µm (``what``: the slices, in messages)."""
    if step is None and not c.has("z_um"):
        step = float(c.meta["z_step_um"])
    if step is not None:
        return np.arange(n, dtype=np.float64) * step
    z = c.meta["z_um"]                                 # a list of finite numbers (its spec)
    if len(z) != n:
        raise InputError(f"{c.where('z_um')}: has {len(z)} values but there are {n} {what}")
    z_um = np.asarray(z, dtype=np.float64)
    vals, counts = np.unique(z_um, return_counts=True)
    if vals.size != n:
        raise InputError(f"{c.where('z_um')}: duplicate height {vals[counts > 1][0]:g} µm")
    return z_um


def _series(c: _Check, value) -> int:
    """The series to read: the caller's (``series``) over stack.json's; a whole number."""
    given = c.given.get("series")
    value = value if given is None else given
    if float(value) == int(value):
        return int(value)
    reason = f"must be a whole number (a series counted from 0), got {value!r}"
    if given is None:
        raise InputError(f"{c.where('series')}: {reason}")
    raise InputError(reason, param="series")


def _scale_and_z(c: _Check, values: dict, export: _Export, files: dict):
    """The pixel size ``(y, x)``, the z positions and where each came from."""
    n = len(c.infos)
    need_ps = (values["pixel_size_um"] is None and c.given.get("pixel_size_um") is None
               and export.pixel_size_um is None)
    need_z = bool(n) and not c.has("z_um") and not c.has("z_step_um") and \
        c.given.get("z_step_um") is None
    tiff_path = files["tiff"]
    scale = _metadata_scale(c, [tiff_path, *files["slices"][:1], export.height], tiff_path,
                            need_ps or need_z)
    ps_yx, source = _pixel_size(c, values["pixel_size_um"], export, scale, need_z)
    sources = {"pixel_size_um": source}
    if not n:
        return ps_yx, np.zeros(0, dtype=np.float64), sources
    step, sources["z_um"] = _z_step(c, scale)
    what = f"pages in {tiff_path.name}" if tiff_path else "slices"
    return ps_yx, _z_positions(c, n, step, what), sources


# -------------------------------------------------------------------------------- warnings
def _warn_unknown(keys, known, shown: str, inside: str = "") -> None:
    for key in keys:
        if key not in known:
            near = difflib.get_close_matches(key, known, n=1, cutoff=0.6)
            hint = f"; did you mean {near[0]!r}?" if near else \
                " (not used)" if inside else " (kept, not used)"
            log.warning("%s: %sunknown key %r%s", shown, inside, key, hint)


def _warn_unknown_keys(meta: dict, jpath: Path) -> None:
    _warn_unknown(meta, KNOWN_KEYS, one_line(jpath))
    illum = meta.get("illumination")
    if isinstance(illum, dict):
        _warn_unknown(illum, [f.name for f in SPECS["illumination"].fields], one_line(jpath),
                      "key 'illumination': ")


def _warn_implausible(jpath: Path, pixel_size_yx_um, z_um: np.ndarray, shape) -> None:
    """Valid values that are almost surely a unit mistake (warnings, not errors)."""
    lo, hi = PLAUSIBLE_PIXEL_SIZE_UM
    for size in sorted(set(pixel_size_yx_um)):
        if not lo <= size <= hi:
            log.warning("%s: key 'pixel_size_um': %g µm per pixel is outside %g-%g µm, where "
                        "optical microscopes are; check the unit (µm)", one_line(jpath),
                        size, lo, hi)
    if z_um.size >= 2:
        zs = np.sort(z_um)
        span = float(zs[-1] - zs[0])
        step = float(np.median(np.diff(zs)))
        field_um = max(s * p for s, p in zip(shape, pixel_size_yx_um))
        if span > field_um:
            log.warning("%s: key 'z_um': the slices span %g µm, more than the field of view "
                        "(%g µm wide); if z is in nm, divide it by 1000", one_line(jpath),
                        span, field_um)
        elif step < 1e-3:
            log.warning("%s: key 'z_um': slices %g µm apart is below any focus drive's "
                        "step; if z is in mm, multiply it by 1000", one_line(jpath), step)


# ------------------------------------------------------------------------------ stack.json
def _names_files(spec) -> bool:
    """The key names files (checked after the rules between keys: which files to read)."""
    return spec.kind in ("path", "paths")


def stack_fields(root: Path, meta: dict, jpath: Path, limits: Limits, *,
                 given: dict | None = None, plain: bool = False) -> dict:
    """Validate the stack.json ``meta`` of the folder ``root`` (``jpath`` names it in
    messages); the keyword arguments of :class:`~microfacet.io.stack.Stack`.

    ``given`` holds the caller's ``pixel_size_um`` and ``z_step_um`` (None when not given),
    used where stack.json has no value; ``plain`` says ``meta`` was made up for a folder
    without stack.json (the messages for a missing value say so).
    """
    c = _Check(root, meta, jpath, limits, given or {}, plain)
    _warn_unknown_keys(meta, jpath)
    # the caller's values, the keys on their own, the rules between them, the files named
    _check_given(c.given)
    values = checked_values(meta, c.where, lambda s: not s.slices_only and not _names_files(s))
    check_rules(meta, c.where)
    checked_values(meta, c.where, _names_files)
    export = _export(c)
    c.series = _series(c, values["series"])
    for key in ("white_reference", "substrate_reference", "flat_reference"):
        if c.has(key):
            image_info(_file(c, key), c.where(key))
    files = {"slices": (), "tiff": None}
    tiff_uniform = False
    if c.has("slices"):
        files["slices"] = _slices(c)
    elif c.has("tiff"):
        files["tiff"], tiff_uniform = _multipage(c)
    if c.infos:
        values.update(checked_values(meta, c.where, lambda s: s.slices_only))
    ps_yx, z_um, sources = _scale_and_z(c, values, export, files)
    ref = c.infos[0][1] if c.infos else export.info
    if c.infos and export.info is not None and export.info.shape != ref.shape:
        raise InputError(f"{c.where('image')}: export size {export.info.shape} differs from "
                         f"the slices {ref.shape}")
    _warn_implausible(jpath, ps_yx, z_um, ref.shape)
    exposure = values["exposure"]
    return dict(
        path=root, pixel_size_yx_um=ps_yx, sources=sources, z_um=z_um,
        slice_paths=files["slices"], tiff_path=files["tiff"], shape=ref.shape,
        dtype=ref.dtype, channels=ref.channels, color_space=values["color_space"],
        illuminant=values["illuminant"], illumination=values["illumination"],
        film=values["film"], substrate=values["substrate"],
        exposure=None if exposure is None else float(exposure),
        export_height_path=export.height, export_image_path=export.image, meta=meta,
        tiff_uniform=tiff_uniform, series=c.series,
        jpeg=max((i.jpeg for _, i in c.infos if i.jpeg is not None), default=None,
                 key=lambda j: j.dc_steps))


#: Median |slope| of a height map above which its unit is almost surely wrong (real
#: surfaces, even roll-dull or sand-blasted, have median slopes well below 1, i.e. 45°).
_IMPLAUSIBLE_MEDIAN_SLOPE = 5.0


def warn_height_unit(h: np.ndarray, pixel_size_yx_um, jpath: Path) -> None:
    """Warn when a height map in µm has slopes no surface has (heights in nm, most likely)."""
    step = max(1, min(h.shape) // 256)
    sub = h[::step, ::step]
    d = np.abs(np.diff(sub, axis=1)) / (pixel_size_yx_um[1] * step)
    d = d[np.isfinite(d)]
    if d.size and float(np.median(d)) > _IMPLAUSIBLE_MEDIAN_SLOPE:
        log.warning("%s: key 'height_um': the median surface slope is %.3g (%.2f°), which no "
                    "surface has; if the heights are in nm, divide them by 1000 (or check "
                    "pixel_size_um)", one_line(jpath), float(np.median(d)),
                    float(np.degrees(np.arctan(np.median(d)))))


def _natural_key(name: str):
    return [int(t) if t.isdigit() else t.lower() for t in re.split(r"(\d+)", name)]


def find_images(folder) -> dict:
    """The images of a plain folder as stack.json keys: ``{"slices": [...]}`` in natural
    order (``img_2`` before ``img_10``), or ``{"tiff": name}`` when the folder holds one TIFF
    (a multi-page stack). Hidden files (``.name``, as macOS leaves) are skipped.

    Parameters
    ----------
    folder : str or Path

    Returns
    -------
    dict
        Empty when the folder holds no image.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> d = pathlib.Path(tempfile.mkdtemp())
    >>> for n in ("img_10.png", "img_2.png", ".img_1.png", "notes.txt"):
    ...     _ = (d / n).write_bytes(b"")
    >>> find_images(d)
    {'slices': ['img_2.png', 'img_10.png']}
    """
    root = Path(folder)
    names = sorted((p.name for p in root.iterdir() if not p.name.startswith(".")
                    and p.suffix.lower() in IMAGE_SUFFIXES and p.is_file()), key=_natural_key)
    if len(names) == 1 and Path(names[0]).suffix.lower() in (".tif", ".tiff"):
        return {"tiff": names[0]}
    return {"slices": names} if names else {}
