"""ISO 25178-72 (formerly ISO 5436-2) ``.x3p`` surface files: reading and writing.

An ``.x3p`` file is a ZIP archive holding ``main.xml`` (axes, grid, instrument, checksums)
and the heights, usually as a binary member (``bindata/data.bin``, little-endian, x varying
fastest) or, rarely, inline as ``<DataList><Datum>`` elements. Heights are in metres:
``z = raw × Increment + Offset`` of the ``CZ`` axis (Increment 1 and Offset 0 when absent),
for every data type ``D`` (float64), ``F`` (float32), ``L`` (int32) and ``I`` (int16).
Invalid points are NaN (float types) and/or cleared bits of the optional
``ValidPointsLink`` member (one bit per point, least significant bit first).

Orientation: point ``(i, j)`` of the grid (x index ``i``, y index ``j``) is pixel
``[row = j, col = i]`` of the image, as in Gwyddion and SurfaceTopography.

:func:`write_x3p` stores float heights as they are, in µm, with ``CZ`` Increment 1e-6 (a
scale factor that Gwyddion, SurfaceTopography and the openGPS library apply), so a float64
or float32 map reads back bit for bit; ``L`` and ``I`` quantize the range to the integer type.

Examples
--------
>>> import tempfile, pathlib
>>> p = pathlib.Path(tempfile.mkdtemp()) / "h.x3p"
>>> write_x3p(p, np.array([[0.0, 1.5, 2.25], [np.nan, -1.0, 3.0]]), 0.5)
>>> m = read_x3p(p)
>>> m.height_um.tolist()[0], bool(np.isnan(m.height_um[1, 0])), m.pixel_size_um
([0.0, 1.5, 2.25], True, (0.5, 0.5))
"""

from __future__ import annotations

import datetime
import hashlib
import math
import os
import xml.etree.ElementTree as ElementTree
import xml.sax.saxutils
import zipfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..core.errors import InputError, one_line
from ..core.pixels import pixel_size_yx

__all__ = ["HeightMap", "read_x3p", "write_x3p"]

#: X3P data types of the z axis and their numpy types (little-endian).
DATA_TYPES = {"I": np.dtype("<i2"), "L": np.dtype("<i4"), "F": np.dtype("<f4"),
              "D": np.dtype("<f8")}
_NS = "http://www.opengps.eu/2008/ISO5436_2"
_MAX_XML_BYTES = 64 << 20


@dataclass(frozen=True)
class HeightMap:
    """A height map in image orientation.

    Attributes
    ----------
    height_um : ndarray (H, W)
        Heights in µm, ``[row = y, col = x]``, NaN where the instrument recorded no value.
        float32 from :func:`microfacet.io.instruments.read_height_map`; :func:`read_x3p`
        keeps float32 for ``F`` files and gives float64 for the other data types.
    pixel_size_um : tuple of float (y, x) or None
        Grid spacing in µm along rows (y) and columns (x); None when the file has none.
    source : str
        The format and, where the file names them, the instrument and software.
    offset_um : float
        Subtracted from the file's heights (``height_um + offset_um`` are the heights the
        file holds): :func:`~microfacet.io.instruments.read_height_map` removes the median
        of maps that sit far from zero, so that float32 keeps their resolution; 0 otherwise.
    """

    height_um: np.ndarray
    pixel_size_um: tuple[float, float] | None
    source: str
    offset_um: float = 0.0


# ------------------------------------------------------------------------------------ reading


def _strip_namespaces(root):
    for el in root.iter():
        if isinstance(el.tag, str) and "}" in el.tag:
            el.tag = el.tag.split("}", 1)[1]
    return root


def _text(root, key, where, default=...):
    el = root.find(key)
    if el is None or el.text is None or not el.text.strip():
        if default is not ...:
            return default
        raise InputError(f"{where}: main.xml lacks {key}")
    return el.text.strip()


def _number(root, key, where, default=..., kind=float):
    s = _text(root, key, where, default)
    if s is default and default is not ...:
        return default
    try:
        v = kind(s)
    except ValueError:
        raise InputError(f"{where}: main.xml {key} is not a number ({s[:40]!r})") from None
    if not math.isfinite(v):
        raise InputError(f"{where}: main.xml {key} is not finite")
    return v


def _member(zf, name, where, size):
    try:
        info = zf.getinfo(name)
    except KeyError:
        raise InputError(f"{where}: archive lacks the member {name!r} that main.xml names") \
            from None
    if size is not None and info.file_size != size:
        raise InputError(f"{where}: member {name} holds {info.file_size} bytes, the grid needs "
                         f"{size}")
    if size is None and info.file_size > _MAX_XML_BYTES:
        raise InputError(f"{where}: member {name} is too large ({info.file_size} bytes)")
    return zf.read(info)


def _check_md5(data, root, key, where, name):
    want = _text(root, key, where, None)
    if want is not None and hashlib.md5(data).hexdigest().lower() != want.lower():
        raise InputError(f"{where}: member {name} does not match its MD5 checksum in main.xml "
                         f"(corrupt file)")


def _inline_data(root, n, where):
    datums = root.findall("Record3/DataList/Datum")
    if len(datums) != n:
        raise InputError(f"{where}: main.xml DataList holds {len(datums)} values, the grid "
                         f"needs {n}")
    out = np.full(n, np.nan)
    for k, d in enumerate(datums):
        s = (d.text or "").strip()
        if s:
            try:
                out[k] = float(s.rsplit(";", 1)[-1])
            except ValueError:
                raise InputError(f"{where}: main.xml DataList value {k} is not a number") \
                    from None
    return out


def _source(root):
    inst = [_text(root, f"Record2/Instrument/{k}", "", "") for k in ("Manufacturer", "Model")]
    inst = " ".join(s for s in inst if s and s.lower() not in ("unknown", "not available"))
    return f"x3p ({one_line(inst)[:120]})" if inst else "x3p"


def read_x3p(path) -> HeightMap:
    """Read an ISO 25178-72 ``.x3p`` areal surface (feature type ``SUR``).

    Parameters
    ----------
    path : path-like

    Returns
    -------
    HeightMap
        Heights in µm (float32 for ``F`` data, float64 otherwise), pixel size ``(y, x)``
        in µm from the ``CY`` and ``CX`` increments.

    Raises
    ------
    InputError
        One line naming the file: not a ZIP archive, no ``main.xml``, a profile or point
        cloud instead of a surface, non-incremental x/y axes, more than one layer, a
        member of the wrong size or failing its MD5 checksum.
    """
    path = Path(path)
    where = one_line(path)
    try:
        with zipfile.ZipFile(path) as zf:
            root = _strip_namespaces(ElementTree.fromstring(_member(zf, "main.xml", where,
                                                                    None)))
            return _read_surface(zf, root, where)
    except InputError:
        raise
    except FileNotFoundError:
        raise InputError(f"{where}: file not found") from None
    except zipfile.BadZipFile:
        raise InputError(f"{where}: not an .x3p file (not a ZIP archive)") from None
    except ElementTree.ParseError as exc:
        raise InputError(f"{where}: main.xml is not well-formed XML ({exc})") from None
    except (OSError, zipfile.LargeZipFile, RuntimeError, ValueError) as exc:
        raise InputError(f"{where}: cannot read ({one_line(exc)})") from None


def _read_surface(zf, root, where) -> HeightMap:
    if root.tag != "ISO5436_2":
        raise InputError(f"{where}: main.xml is not an ISO 5436-2 / 25178-72 document")
    feature = _text(root, "Record1/FeatureType", where)
    if feature != "SUR":
        raise InputError(f"{where}: feature type {feature!r} is not supported (an areal "
                         f"surface 'SUR' is needed)")
    for ax, want in (("CX", "I"), ("CY", "I"), ("CZ", "A")):
        got = _text(root, f"Record1/Axes/{ax}/AxisType", where)
        if got != want:
            raise InputError(f"{where}: axis {ax} has type {got!r}; only {want!r} is supported")
    nx, ny = (_number(root, f"Record3/MatrixDimension/Size{a}", where, kind=int)
              for a in "XY")
    nz = _number(root, "Record3/MatrixDimension/SizeZ", where, 1, kind=int)
    if nx < 1 or ny < 1 or nz != 1:
        raise InputError(f"{where}: grid {nx}×{ny}×{nz} is not one non-empty layer")
    dx, dy = (abs(_number(root, f"Record1/Axes/{a}/Increment", where)) for a in ("CX", "CY"))
    if dx == 0 or dy == 0:
        raise InputError(f"{where}: main.xml gives a zero x or y increment")
    z_inc = _number(root, "Record1/Axes/CZ/Increment", where, 1.0)
    z_off = _number(root, "Record1/Axes/CZ/Offset", where, 0.0)
    n = nx * ny
    link = root.find("Record3/DataLink")
    if link is not None:
        dtype_name = _text(root, "Record1/Axes/CZ/DataType", where)
        if dtype_name not in DATA_TYPES:
            raise InputError(f"{where}: CZ data type {dtype_name!r} is not one of "
                             f"{', '.join(DATA_TYPES)}")
        dtype = DATA_TYPES[dtype_name]
        name = _text(link, "PointDataLink", where)
        data = _member(zf, name, where, n * dtype.itemsize)
        _check_md5(data, link, "MD5ChecksumPointData", where, name)
        raw = np.frombuffer(data, dtype=dtype).reshape(ny, nx)
        vname = _text(link, "ValidPointsLink", where, None)
        valid = None
        if vname is not None:
            vdata = _member(zf, vname, where, (n + 7) // 8)
            _check_md5(vdata, link, "MD5ChecksumValidPoints", where, vname)
            bits = np.unpackbits(np.frombuffer(vdata, np.uint8), count=n, bitorder="little")
            valid = bits.reshape(ny, nx).astype(bool)
    elif root.find("Record3/DataList") is not None:
        raw, valid, dtype_name = _inline_data(root, n, where).reshape(ny, nx), None, "D"
    else:
        raise InputError(f"{where}: main.xml has neither a DataLink nor a DataList")
    # µm = raw × (Increment × 1e6) + Offset × 1e6; with Increment 1e-6 the factor is exactly 1.
    scale, off = z_inc * 1e6, z_off * 1e6
    h = raw.astype(np.float64)
    if scale != 1.0:
        h *= scale
    if off != 0.0:
        h += off
    h[~np.isfinite(h)] = np.nan
    if valid is not None:
        h[~valid] = np.nan
    if dtype_name == "F":
        h = h.astype(np.float32)
    return HeightMap(height_um=h, pixel_size_um=(dy * 1e6, dx * 1e6), source=_source(root))


# ------------------------------------------------------------------------------------ writing


def _quantize(h, dtype):
    info = np.iinfo(dtype)
    ok = np.isfinite(h)
    lo, hi = (float(np.min(h[ok])), float(np.max(h[ok]))) if ok.any() else (0.0, 0.0)
    step = (hi - lo) / (int(info.max) - int(info.min)) if hi > lo else 1e-6
    raw = np.where(ok, np.round((np.where(ok, h, lo) - lo) / step) + info.min, info.min)
    offset_m = (lo - info.min * step) * 1e-6
    return np.clip(raw, info.min, info.max).astype(dtype), step * 1e-6, offset_m


def _main_xml(nx, ny, dx_m, dy_m, data_type, z_inc, z_off, md5_data, md5_valid, model, comment):
    date = datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds")
    valid = ("" if md5_valid is None else
             "      <ValidPointsLink>bindata/valid.bin</ValidPointsLink>\n"
             f"      <MD5ChecksumValidPoints>{md5_valid}</MD5ChecksumValidPoints>\n")
    z_off_xml = "" if z_off is None else f"        <Offset>{z_off!r}</Offset>\n"
    esc = xml.sax.saxutils.escape
    return (
        '<?xml version="1.0" encoding="UTF-8" standalone="no" ?>\n'
        f'<p:ISO5436_2 xmlns:p="{_NS}" xmlns:xsi="http://www.w3.org/2001/XMLSchema-instance" '
        f'xsi:schemaLocation="{_NS} {_NS}/ISO5436_2.xsd">\n'
        "  <Record1>\n    <Revision>ISO5436 - 2000</Revision>\n"
        "    <FeatureType>SUR</FeatureType>\n    <Axes>\n"
        f"      <CX>\n        <AxisType>I</AxisType>\n        <DataType>D</DataType>\n"
        f"        <Increment>{dx_m!r}</Increment>\n        <Offset>0</Offset>\n      </CX>\n"
        f"      <CY>\n        <AxisType>I</AxisType>\n        <DataType>D</DataType>\n"
        f"        <Increment>{dy_m!r}</Increment>\n        <Offset>0</Offset>\n      </CY>\n"
        f"      <CZ>\n        <AxisType>A</AxisType>\n        <DataType>{data_type}</DataType>\n"
        f"        <Increment>{z_inc!r}</Increment>\n{z_off_xml}      </CZ>\n"
        "    </Axes>\n  </Record1>\n"
        f"  <Record2>\n    <Date>{date}</Date>\n    <Creator>microfacet</Creator>\n"
        "    <Instrument>\n      <Manufacturer>microfacet</Manufacturer>\n"
        f"      <Model>{esc(model)}</Model>\n      <Serial>not available</Serial>\n"
        "      <Version>1</Version>\n    </Instrument>\n"
        f"    <CalibrationDate>{date}</CalibrationDate>\n"
        "    <ProbingSystem>\n      <Type>NonContacting</Type>\n"
        "      <Identification>optical microscope</Identification>\n    </ProbingSystem>\n"
        f"    <Comment>{esc(comment)}</Comment>\n  </Record2>\n"
        "  <Record3>\n    <MatrixDimension>\n"
        f"      <SizeX>{nx}</SizeX>\n      <SizeY>{ny}</SizeY>\n      <SizeZ>1</SizeZ>\n"
        "    </MatrixDimension>\n    <DataLink>\n"
        "      <PointDataLink>bindata/data.bin</PointDataLink>\n"
        f"      <MD5ChecksumPointData>{md5_data}</MD5ChecksumPointData>\n{valid}"
        "    </DataLink>\n  </Record3>\n"
        "  <Record4>\n    <ChecksumFile>md5checksum.hex</ChecksumFile>\n  </Record4>\n"
        "</p:ISO5436_2>\n")


def write_x3p(path, height_um, pixel_size_um, *, data_type=None, model="height from focus",
              comment="") -> None:
    """Write a height map as an ISO 25178-72 ``.x3p`` file (Gwyddion, MountainsMap, ...).

    Parameters
    ----------
    path : path-like
        The file to write (replaced atomically if it exists).
    height_um : array_like (H, W)
        Heights in µm, image orientation ``[row = y, col = x]``; NaN or ±inf marks an
        invalid point (also recorded in ``bindata/valid.bin``).
    pixel_size_um : float or (float, float)
        Grid spacing in µm, one value or ``(y, x)``.
    data_type : {"D", "F", "L", "I"}, optional
        Stored type: by default ``F`` for float32 input, else ``D``. ``L`` and ``I`` quantize
        the finite range onto int32 / int16 (Increment and Offset in metres).
    model, comment : str
        ``Record2/Instrument/Model`` and ``Record2/Comment``.

    Raises
    ------
    ValueError
        A map that is not 2-D, a bad pixel size or data type.
    """
    h = np.asarray(height_um)
    if h.ndim != 2 or min(h.shape) < 1 or not np.issubdtype(h.dtype, np.number):
        raise ValueError(f"height_um: expected a non-empty 2-D numeric array, got {h.shape}")
    if data_type is None:
        data_type = "F" if h.dtype == np.float32 else "D"
    if data_type not in DATA_TYPES:
        raise ValueError(f"data_type: must be one of {', '.join(DATA_TYPES)}, got {data_type!r}")
    py, px = pixel_size_yx(pixel_size_um)
    dtype = DATA_TYPES[data_type]
    invalid = ~np.isfinite(h)
    if data_type in "FD":
        raw, z_inc, z_off = h.astype(dtype, copy=False), 1e-6, None
    else:
        raw, z_inc, z_off = _quantize(h.astype(np.float64), dtype)
    # the map's own bytes where it is stored as it is (no copy; zipfile reads a buffer)
    data = memoryview(np.ascontiguousarray(raw, dtype=dtype)).cast("B")
    vdata = (np.packbits(~invalid.ravel(), bitorder="little").tobytes() if invalid.any()
             else None)
    md5 = hashlib.md5(data).hexdigest().upper()
    md5_valid = None if vdata is None else hashlib.md5(vdata).hexdigest().upper()
    xml = _main_xml(h.shape[1], h.shape[0], px * 1e-6, py * 1e-6, data_type, z_inc, z_off,
                    md5, md5_valid, model, comment).encode("utf-8")
    path = Path(path)
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    try:
        with zipfile.ZipFile(tmp, "w", compression=zipfile.ZIP_DEFLATED,
                             compresslevel=1) as zf:
            zf.writestr("main.xml", xml)
            zf.writestr("bindata/data.bin", data)
            if vdata is not None:
                zf.writestr("bindata/valid.bin", vdata)
            zf.writestr("md5checksum.hex", f"{hashlib.md5(xml).hexdigest().upper()} *main.xml\n")
        os.replace(tmp, path)
    finally:
        if tmp.exists():
            tmp.unlink()
