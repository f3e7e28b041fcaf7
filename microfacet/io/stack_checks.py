"""Validation of a ``stack.json`` (format ``microfacet-stack/1``) before any work.

:func:`stack_fields` checks every key and every image header (each against the
:class:`~microfacet.io.limits.Limits` as soon as it is read) and returns the fields of a
:class:`~microfacet.io.stack.Stack`; any breach raises
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
from pathlib import Path

import numpy as np

from ..core.errors import InputError, one_line
from ..core.lazy import load
from ..core.pixels import pixel_size_yx
from ..optics.constants import DEFAULT_FILM, DEFAULT_SUBSTRATE, known_sets
from .images import IMAGE_SUFFIXES, ImageInfo, image_info, npy_info, read_tiff_headers
from .limits import Limits
from .tiff_meta import tiff_scale

tifffile = load("tifffile")

__all__ = ["DEFAULT_ILLUMINATION", "KNOWN_KEYS", "PLAUSIBLE_PIXEL_SIZE_UM", "find_images",
           "stack_fields", "warn_height_unit"]

log = logging.getLogger("microfacet.io.stack")

#: The ``format`` string of a stack.json.
FORMAT = "microfacet-stack/1"
DEFAULT_ILLUMINATION = {"geometry": "coaxial", "numerical_aperture": 0.8}
_COLOR_SPACES = ("sRGB", "linear-sRGB")
#: The keys of stack.json this format defines (others are kept in ``meta`` with a warning).
KNOWN_KEYS = ("format", "pixel_size_um", "slices", "tiff", "z_um", "z_step_um", "color_space",
              "illuminant", "illumination", "film", "substrate", "exposure", "height_um",
              "image", "synthetic")
_ILLUMINATION_KEYS = ("geometry", "numerical_aperture")
#: Pixel sizes outside this range (µm) are almost surely a unit mistake: warned about.
PLAUSIBLE_PIXEL_SIZE_UM = (0.01, 100.0)


def _is_number(v) -> bool:
    """A JSON number that fits a float (a 400-digit integer does not)."""
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        return False
    try:
        float(v)
    except OverflowError:
        return False
    return True


def _pixel_size_value(ps, where: str) -> tuple[float, float]:
    """A stack.json ``pixel_size_um`` (a number, or ``[y, x]``) as ``(y, x)`` µm."""
    vals = ps if isinstance(ps, list) else [ps]
    if len(vals) not in (1, 2) or not all(
            _is_number(v) and math.isfinite(v) and v > 0 for v in vals):
        raise InputError(f"{where}: must be a finite number > 0, got {ps!r} (or a list "
                         f"[y, x] of two)")
    return (float(vals[0]), float(vals[-1]))


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


def _differs(given, used, where: str) -> None:
    """Warn when the caller gave a value that stack.json overrides."""
    if given is not None and _is_number(used) and not math.isclose(given, used, rel_tol=1e-9):
        log.warning("%s: %g µm is used, not the given %g µm (stack.json wins)", where, used,
                    given)


def _missing(root: Path, meta: dict, plain: bool, where: str, *, need_z: bool,
             has_ps: bool = False) -> None:
    """Raise the one-line error for a pixel size or z spacing found nowhere."""
    if not plain:
        hint = "give 'z_um' or 'z_step_um'" if has_ps else "not in the image metadata either"
        raise InputError(f"{where}: missing ({hint})")
    what = " and ".join(n for n, need in (("`pixel_size_um`", not has_ps),
                                           ("`z_step_um`", need_z)) if need)
    found = meta.get("slices") or [meta.get("tiff")]
    raise InputError(f"{one_line(root / 'stack.json')}: missing stack.json; to read the "
                     f"{len(found)} image(s) in the folder ({one_line(found[0])} ...) as a "
                     f"stack give {what} (their metadata has no such value), or write a "
                     f"stack.json (microfacet init)")


def stack_fields(root: Path, meta: dict, jpath: Path, limits: Limits, *,
                 given: dict | None = None, plain: bool = False) -> dict:
    """Validate the stack.json ``meta`` of the folder ``root`` (``jpath`` names it in
    messages); the keyword arguments of :class:`~microfacet.io.stack.Stack`.

    ``given`` holds the caller's ``pixel_size_um`` and ``z_step_um`` (None when not given),
    used where stack.json has no value; ``plain`` says ``meta`` was made up for a folder
    without stack.json (the messages for a missing value say so).
    """
    shown = one_line(jpath)
    given = given or {}

    def where(key):
        return f"{shown}: key {key!r}"

    _warn_unknown_keys(meta, jpath)

    fmt = meta.get("format")
    if fmt is None:
        raise InputError(f"{where('format')}: missing (expected {FORMAT!r})")
    if fmt != FORMAT:
        raise InputError(f"{where('format')}: {fmt!r} is not {FORMAT!r}")

    ps = meta.get("pixel_size_um")
    ps_yx = None if ps is None else _pixel_size_value(ps, where("pixel_size_um"))
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
        if not _is_number(value) or not math.isfinite(value) or value == 0 or (
                key == "pixel_size_um" and value < 0):
            need = "> 0" if key == "pixel_size_um" else "!= 0"
            raise InputError(f"must be a finite number {need}, got {value!r}", param=key)

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
    illumination = dict(DEFAULT_ILLUMINATION)
    illumination.update(illum)
    na = illumination.get("numerical_aperture")
    if not _is_number(na) or not math.isfinite(na) or not 0 < na <= 1:
        raise InputError(f"{where('illumination')}: numerical_aperture must be a number in "
                         f"(0, 1], got {na!r}")
    if not isinstance(illumination.get("geometry"), str):
        raise InputError(f"{where('illumination')}: geometry must be a string")

    known = known_sets()
    names = {}
    for key, default in (("film", DEFAULT_FILM), ("substrate", DEFAULT_SUBSTRATE)):
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
    export_shape = export_px = None
    has_h, has_img = "height_um" in meta, "image" in meta
    if has_h != has_img:
        missing = "image" if has_h else "height_um"
        raise InputError(f"{where(missing)}: missing (a microscope export needs both "
                         f"'height_um' and 'image')")
    if has_h:
        export_height = _resolve_inside(root, meta["height_um"], where("height_um"))
        wh = f"{where('height_um')} ({export_height.name})"
        if export_height.suffix.lower() == ".npy":
            hshape, hdtype = npy_info(export_height, wh)
            if hdtype.kind != "f":
                raise InputError(f"{wh}: height map must be floating point, got {hdtype}")
        elif export_height.suffix.lower() in (".tif", ".tiff"):
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
        else:  # an instrument file (Keyence, Zygo, Digital Surf, ...)
            try:
                # looked up here, not at import: the module may not be installed
                hm = load("microfacet.io.instruments").read_height_map(export_height)
            except ModuleNotFoundError as exc:
                if exc.name != "microfacet.io.instruments":
                    raise
                raise InputError(f"{wh}: height map must be a TIFF or .npy file") from None
            except (InputError, OSError, ValueError) as exc:
                raise InputError(f"{wh}: {one_line(exc)}") from None
            hshape, export_px = tuple(hm.height_um.shape), hm.pixel_size_um
        if len(hshape) != 2:
            raise InputError(f"{wh}: height map must be 2-D, got shape {hshape}")
        limits.check_image(hshape, wh)
        export_image = _resolve_inside(root, meta["image"], where("image"))
        wi = f"{where('image')} ({one_line(export_image.name)})"
        info = image_info(export_image, wi)
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

    # z (where it comes from is settled below, once the first TIFF can be asked)
    has_z, has_step = "z_um" in meta, "z_step_um" in meta
    if n != 0 and has_z and has_step:
        raise InputError(f"{where('z_step_um')}: give either 'z_um' or 'z_step_um', not both")

    # headers, each checked against the limits and against the first as soon as it is read
    infos: list[tuple[str, ImageInfo]] = []

    def add(name, where_text, info):
        limits.check_image(info.shape, where_text)
        if infos:
            _check_consistent(shown, name, info, *infos[0])
        infos.append((name, info))

    tiff_uniform = False
    if tiff_path is not None:
        tiff_uniform = read_tiff_headers(tiff_path, where("tiff"), add)
        n = len(infos)
        if n == 0:
            raise InputError(f"{where('tiff')} ({tiff_path.name}): TIFF has no pages")
        limits.check_stack(n, infos[0][1].shape, where("tiff"))

    # --- pixel size and z: stack.json, else given, else instrument file, else TIFF metadata
    first_tiff = tiff_path or next((p for p in slice_paths[:1] + [export_height]
                                    if p is not None and p.suffix.lower() in (".tif", ".tiff")),
                                   None)
    scale = None
    if first_tiff is not None and (ps_yx is None and given.get("pixel_size_um") is None
                                   and export_px is None
                                   or n and not has_z and not has_step
                                   and given.get("z_step_um") is None):
        scale = tiff_scale(first_tiff, where("tiff" if tiff_path else "slices"))
    sources = {}
    if ps_yx is not None:
        sources["pixel_size_um"] = "stack.json"
        if given.get("pixel_size_um") is not None:
            for g, used in zip(pixel_size_yx(given["pixel_size_um"]), ps_yx):
                _differs(g, used, where("pixel_size_um"))
    elif given.get("pixel_size_um") is not None:
        ps_yx, sources["pixel_size_um"] = pixel_size_yx(given["pixel_size_um"]), "given"
    elif export_px is not None:
        ps_yx = _pixel_size_value([float(v) for v in export_px], where("height_um"))
        sources["pixel_size_um"] = f"instrument file {one_line(export_height.name)}"
    elif scale is not None and scale.pixel_size_yx_um is not None:
        ps_yx, sources["pixel_size_um"] = scale.pixel_size_yx_um, scale.source
    else:
        _missing(root, meta, plain, where("pixel_size_um"),
                 need_z=n and not has_z and not has_step and given.get("z_step_um") is None
                 and (scale is None or scale.z_step_um is None))
    step = None
    if n and (has_z or has_step):
        sources["z_um"] = "given" if plain else "stack.json"
        if has_step:
            _differs(given.get("z_step_um"), meta["z_step_um"], where("z_step_um"))
    elif n and given.get("z_step_um") is not None:
        step, sources["z_um"] = float(given["z_step_um"]), "given"
    elif n and scale is not None and scale.z_step_um is not None:
        step, sources["z_um"] = scale.z_step_um, scale.source
    elif n:
        _missing(root, meta, plain, where("z_um"), need_z=True, has_ps=True)

    if n:
        if step is not None:
            z_um = np.arange(n, dtype=np.float64) * step
        elif "z_um" in meta:
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
                raise InputError(f"{where('z_step_um')}: must be a finite non-zero number, "
                                 f"got {s!r}")
            z_um = np.arange(n, dtype=np.float64) * float(s)
    else:
        z_um = np.zeros(0, dtype=np.float64)

    if has_slices:
        for i, p in enumerate(slice_paths):
            wt = f"{where('slices')}[{i}] ({one_line(p.name)})"
            add(f"slices[{i}] ({one_line(p.name)})", wt, image_info(p, wt))
        limits.check_stack(n, infos[0][1].shape, where("slices"))

    ref_info = infos[0][1] if infos else export_shape
    if infos and export_shape is not None and export_shape.shape != ref_info.shape:
        raise InputError(f"{where('image')}: export size {export_shape.shape} differs from the "
                         f"slices {ref_info.shape}")
    _warn_implausible(jpath, ps_yx, z_um, ref_info.shape)

    return dict(
        path=root,
        pixel_size_yx_um=ps_yx,
        sources=sources,
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
