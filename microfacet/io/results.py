"""The results folder (format ``microfacet-results/1``): the one module that writes and reads it.

The analysis (:mod:`microfacet.analysis.output`) decides *what* a results folder holds and
hands the arrays, tables and summary to :func:`write_results_files`; the report, ``batch``
and ``simulate`` open a folder with :class:`Results`, which reads ``summary.json`` at once and
every map, image and table lazily, on first use. docs/results-format.md describes every file
and key.

Examples
--------
>>> import tempfile, pathlib
>>> d = pathlib.Path(tempfile.mkdtemp())
>>> written = write_results_files(d, summary={"thickness": {"mixture": {"components": [
...     {"weight": 1.0, "mean_nm": 51.0, "sd_nm": 2.0}]}}},
...     maps={"thickness_nm": np.full((2, 3), 51.0)})
>>> written["thickness_nm"].dtype                 # the maps as their files hold them
dtype('float32')
>>> r = Results(d)
>>> r.map("thickness_nm").shape, r.map("tilt_deg") is None
((2, 3), True)
>>> r.thickness_mixture().means_nm.tolist()
[51.0]
"""

from __future__ import annotations

import csv
import json
import os
from pathlib import Path

import numpy as np

from ..core.distributions import NDFMixture, ThicknessMixture
from ..core.errors import InputError, one_line
from ..core.pixels import pixel_size_yx
from ..core.threads import thread_map
from .images import read_png, write_float_tiff, write_image
from .jsonfile import json_safe, read_json
from .summary import FORMAT, MAX_SUMMARY_BYTES, Summary
from .x3p import write_x3p

__all__ = ["FORMAT", "IMAGES", "MAPS", "OPTICS_KEYS", "Results", "TABLES", "TIFF_COPIES",
           "X3P_COPIES", "pixel_size_of", "write_results_files"]

#: Maps of a results folder: name -> (file, what it holds). Shapes are H×W (H×W×3 for the
#: normals); floats are float32 with NaN where there is no value.
MAPS = {
    "height_um": ("height_um.npy", "height from focus, µm (NaN where unreliable)"),
    "normals": ("normals.npy", "unit normals (x right, y up, z up), H×W×3"),
    "reliability_db": ("reliability_db.npy", "focus reliability, dB"),
    "height_sigma_um": ("height_sigma_um.npy", "1-σ error of height_um, µm, scaled by the "
                        "self-check's measured errors"),
    "tilt_height_deg": ("tilt_height_deg.npy", "tilt of the (filled) height map, degrees"),
    "thickness_nm": ("thickness_nm.npy", "oxide thickness, nm (NaN where masked)"),
    "tilt_deg": ("tilt_deg.npy", "facet tilt, degrees from the optical axis"),
    "tilt_sigma_deg": ("tilt_sigma_deg.npy", "1-σ uncertainty of tilt_deg, degrees"),
    "delta_e": ("delta_e.npy", "CIEDE2000 between each pixel and its model colour"),
    "colour_weight": ("colour_weight.npy", "share of the tilt information from colour"),
    "mask": ("mask.npy", "bool, True where the pixel carries no colour information"),
    "facets": ("facets.npy", "int32 facet label per pixel (joint mode)"),
}
_NDIM = {"normals": 3}
#: The optics ``summary["inputs"]`` records (:meth:`Results.optics`).
OPTICS_KEYS = ("film", "substrate", "illuminant")
#: Images: name -> file.
IMAGES = {"all_in_focus": "all_in_focus.png"}
#: Copies of maps for microscopy tools (Fiji, tifffile): map name -> (file, value unit);
#: float32 ImageJ TIFFs calibrated with the pixel size (``unit=um``, pixels per µm).
TIFF_COPIES = {
    "height_um": ("height_um.tif", "um"),
    "thickness_nm": ("thickness_nm.tif", "nm"),
    "tilt_deg": ("tilt_deg.tif", "degree"),
    "tilt_sigma_deg": ("tilt_sigma_deg.tif", "degree"),
}
#: ISO 25178-72 copies (Gwyddion, MountainsMap): map name -> file; need the pixel size.
X3P_COPIES = {"height_um": "height_um.x3p"}
#: Tables: name -> (file, columns that must be there).
TABLES = {
    "thickness_roi": ("thickness_roi.csv",
                      ("row0", "col0", "size", "thickness_nm", "mean_delta_e", "n_pixels")),
    "thickness_pdf": ("thickness_pdf.csv", ("thickness_nm", "density", "mixture_density")),
    "ndf_pdf": ("ndf_pdf.csv", ("tilt_deg", "density", "mixture_density")),
    "facets": ("facets.csv", ("facet", "n_pixels", "tilt_deg", "tilt_sigma_deg",
                              "height_plane", "thickness_nm", "thickness_sigma_nm")),
}


def _dump(path: Path, summary: dict) -> None:
    text = json.dumps(json_safe(summary), indent=2, allow_nan=False) + "\n"
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    tmp.write_text(text, encoding="utf-8")
    os.replace(tmp, path)


def pixel_size_of(summary: dict) -> tuple[float, float] | None:
    """The pixel size ``(y, x)`` in µm of ``summary["inputs"]["pixel_size_um"]`` (one number
    or a pair), or None when it is absent or not positive and finite.

    >>> pixel_size_of({"inputs": {"pixel_size_um": 0.5}}), pixel_size_of({})
    ((0.5, 0.5), None)
    """
    inputs = summary.get("inputs") if isinstance(summary, dict) else None
    value = inputs.get("pixel_size_um") if isinstance(inputs, dict) else None
    try:
        return None if value is None else pixel_size_yx(value)
    except ValueError:
        return None


def write_results_files(folder, *, summary: dict, maps: dict, images: dict | None = None,
                        tables: dict | None = None, tool_copies: bool = True) -> dict:
    """Write the files of a results folder into ``folder`` (which exists; normally the
    temporary folder of a :class:`~microfacet.io.outdir.OutputFolder`).

    Parameters
    ----------
    folder : path-like
    summary : dict
        ``summary.json`` content (made JSON-safe; ``format`` is set).
    maps : dict of str to ndarray or callable
        Names of :data:`MAPS`; floats are written as float32, ``mask`` as bool, ``facets``
        as int32. None values are skipped. A callable is called for its map (or None) by the
        job that writes it, so that maps made for the files are not all held before them.
    images : dict of str to (ndarray, int), optional
        Names of :data:`IMAGES` → (image in [0, 1] or code values, bit depth 8 or 16).
    tables : dict of str to (ndarray (N, C), list of str, list of str), optional
        Names of :data:`TABLES` → (rows, column names, printf formats).
    tool_copies : bool
        Also write the copies for microscopy tools: :data:`TIFF_COPIES` (calibrated float32
        TIFFs) and, when the pixel size is known, :data:`X3P_COPIES`; PNG images get a
        ``pHYs`` chunk. The pixel size is ``summary["inputs"]["pixel_size_um"]``
        (:func:`pixel_size_of`).

    Returns
    -------
    dict of str to ndarray
        The maps given as arrays (not callables), as their files hold them (the dtypes
        above; the array itself where it already has its dtype): what :class:`Results`
        would read back, for a reader in the same process (``Results(folder, maps=...)``).

    Raises
    ------
    ValueError
        An unknown name.
    """
    folder = Path(folder)
    stored = {name: _as_stored(name, arr) for name, arr in maps.items()
              if arr is not None and not callable(arr)}
    pixel = pixel_size_of(summary) if tool_copies else None
    jobs = []
    for name, arr in maps.items():
        if name not in MAPS:
            raise ValueError(f"maps: unknown map {name!r}; known: {', '.join(MAPS)}")
        if arr is not None:
            arr = stored.get(name, arr)
            jobs.append(lambda name=name, arr=arr: _write_map(folder, name, arr, pixel,
                                                              tool_copies))
    for name, (img, bit_depth) in (images or {}).items():
        if name not in IMAGES:
            raise ValueError(f"images: unknown image {name!r}; known: {', '.join(IMAGES)}")
        jobs.append(lambda name=name, img=img, bit_depth=bit_depth: write_image(
            folder / IMAGES[name], img, bit_depth=bit_depth, pixel_size_um=pixel))
    for name, (rows, columns, fmt) in (tables or {}).items():
        if name not in TABLES:
            raise ValueError(f"tables: unknown table {name!r}; known: {', '.join(TABLES)}")
        rows = np.asarray(rows, dtype=np.float64).reshape(-1, len(columns))
        jobs.append(lambda name=name, rows=rows, columns=columns, fmt=fmt: np.savetxt(
            folder / TABLES[name][0], rows, delimiter=",", comments="",
            header=",".join(columns), fmt=fmt))
    # the files on the analysis' threads (core.threads.num_threads): the x3p's and the PNG's
    # compression and the writes release the GIL (docs/benchmarks.md)
    thread_map(lambda job: job(), jobs)
    _dump(folder / "summary.json", {"format": FORMAT, **summary})
    return stored


def _as_stored(name, arr) -> np.ndarray:
    """Map ``name`` as its file stores it: ``mask`` bool, ``facets`` int32, the others
    float32 (``arr`` itself where it has that dtype).

    >>> _as_stored("mask", np.array([0, 2])).tolist(), _as_stored("tilt_deg", [1]).dtype
    ([False, True], dtype('float32'))
    """
    a = np.asarray(arr)
    return (a.astype(bool, copy=False) if name == "mask" else
            a.astype(np.int32, copy=False) if name == "facets" else
            a.astype(np.float32, copy=False))


def _write_map(folder, name, arr, pixel, tool_copies) -> None:
    """One map's ``.npy`` and, with ``tool_copies``, its TIFF and x3p copies."""
    a = arr() if callable(arr) else arr
    if a is None:                       # a callable that had no map to give
        return
    a = _as_stored(name, a)
    np.save(folder / MAPS[name][0], a)
    if tool_copies and name in TIFF_COPIES and a.ndim == 2:
        file, unit = TIFF_COPIES[name]
        write_float_tiff(folder / file, a, pixel_size_um=pixel, value_unit=unit)
    if tool_copies and name in X3P_COPIES and a.ndim == 2 and pixel is not None:
        write_x3p(folder / X3P_COPIES[name], a, pixel)


class Results:
    """A results folder, opened for reading: ``summary.json`` now, the rest on first use.

    Parameters
    ----------
    folder : path-like
        A results folder (docs/results-format.md). Only ``summary.json`` is required; a
        missing map, image or table reads as None.
    maps : dict of str to ndarray, optional, keyword-only
        Maps of the folder already in memory, as :func:`write_results_files` returned them
        (what their files hold): :meth:`map` gives them, read-only, instead of reading the
        files again (the analysis' report holds no second copy).

    Raises
    ------
    InputError
        ``folder`` or its ``summary.json`` is missing, unreadable, not an object, or of
        another format (the message names the file).
    """

    def __init__(self, folder, *, maps: dict | None = None):
        self.path = Path(folder)
        f = self.path / "summary.json"
        if not self.path.is_dir():
            raise InputError(f"{one_line(self.path)}: results folder not found")
        if not f.is_file():
            raise InputError(f"{one_line(f)}: missing (not a results folder)")
        #: The validated, typed summary (:class:`~microfacet.io.summary.Summary`).
        raw = read_json(f, max_bytes=MAX_SUMMARY_BYTES)
        #: The ``format`` the file declares (None when it declares none: not written whole).
        self.declared_format = raw.get("format") if isinstance(raw, dict) else None
        self.typed = Summary.from_json(raw, where=one_line(f))
        #: ``summary.json`` as a dict (the typed summary's JSON, version-2 layout).
        self.summary = self.typed.to_json()
        self.summary_mtime = f.stat().st_mtime
        self._cache: dict = {}        # ("map" | "image" | "table", name): what was read
        self._given: dict = {}        # name: a map given in memory (kept by release)
        for name, arr in (maps or {}).items():
            if name not in MAPS:
                raise ValueError(f"maps: unknown map {name!r}; known: {', '.join(MAPS)}")
            view = _as_stored(name, arr).view()
            view.flags.writeable = False      # the caller's array: read, never changed
            self._given[name] = view

    # -- summary ---------------------------------------------------------------------
    def get(self, *keys):
        """``summary[k0][k1]...``, or None where a key is missing.

        >>> import tempfile, pathlib
        >>> d = pathlib.Path(tempfile.mkdtemp())
        >>> _ = (d / "summary.json").write_text('{"delta_e": {"mean": 1.5}}')
        >>> Results(d).get("delta_e", "mean"), Results(d).get("delta_e", "p99")
        (1.5, None)
        """
        v = self.summary
        for k in keys:
            if not isinstance(v, dict) or k not in v:
                return None
            v = v[k]
        return v

    @property
    def parameters(self) -> dict:
        """The analysis parameters recorded in ``summary.json`` (empty if absent)."""
        p = self.summary.get("parameters")
        return p if isinstance(p, dict) else {}

    def parameter(self, path: str):
        """The analysis option at the dotted ``path`` of the options tree
        (``"roi.size_px"``), or None.

        >>> import tempfile, pathlib
        >>> d = pathlib.Path(tempfile.mkdtemp())
        >>> _ = (d / "summary.json").write_text('{"parameters": {"roi_size_px": 128}}')
        >>> Results(d).parameter("roi.size_px")     # a version-1 summary's flat name
        128
        """
        return self.get("parameters", *path.split("."))

    def differing_parameters(self, parameters: dict) -> list[str]:
        """Dotted names of the ``parameters`` (a nested dict of options) that this folder was
        not made with.

        >>> import tempfile, pathlib
        >>> d = pathlib.Path(tempfile.mkdtemp())
        >>> _ = (d / "summary.json").write_text('{"parameters": {"roi": {"size_px": 255}}}')
        >>> Results(d).differing_parameters({"roi": {"size_px": 128}, "mode": "joint"})
        ['mode', 'roi.size_px']
        """
        have, want = _flat(self.parameters), _flat(json_safe(parameters))
        return sorted(k for k in want if have.get(k) != want[k])

    def _mixture(self, key, cls):
        data = self.get(key, "mixture")
        if not data or (isinstance(data, dict) and data.get("components") == []):
            return None  # no fit: no section, or the analysis' empty component list
        try:
            return cls.from_json(data)
        except (ValueError, TypeError, AttributeError) as exc:
            raise InputError(f"{one_line(self.path / 'summary.json')}: key "
                             f"'{key}.mixture': {one_line(exc)}") from None

    def thickness_mixture(self) -> ThicknessMixture | None:
        """The fitted thickness mixture, or None when there is none.

        Raises
        ------
        InputError
            One line naming ``summary.json`` and the key ``thickness.mixture``: a component
            that is not a valid Gaussian, or more than
            :data:`~microfacet.core.distributions.MAX_COMPONENTS` of them.
        """
        return self._mixture("thickness", ThicknessMixture)

    def ndf_mixture(self) -> NDFMixture | None:
        """The fitted NDF lobes, or None when there are none (errors as
        :meth:`thickness_mixture`, naming the key ``ndf.mixture``)."""
        return self._mixture("ndf", NDFMixture)

    def optics(self) -> dict:
        """The optics the analysis modelled: ``film``, ``substrate`` and ``illuminant`` from
        ``summary["inputs"]`` (the top level of an old summary), those recorded as non-empty
        text.

        >>> import tempfile, pathlib
        >>> d = pathlib.Path(tempfile.mkdtemp())
        >>> _ = (d / "summary.json").write_text('{"summary_version": 2, "inputs": '
        ...                                     '{"film": "TiO2_x", "illuminant": "D50"}}')
        >>> Results(d).optics()
        {'film': 'TiO2_x', 'illuminant': 'D50'}
        """
        out = {}
        for key in OPTICS_KEYS:
            value = self.get("inputs", key)
            if not (isinstance(value, str) and value):
                value = self.summary.get(key)
            if isinstance(value, str) and value:
                out[key] = value
        return out

    def record(self, *keys_and_value) -> None:
        """Set ``summary[k0]...[kn] = value`` and rewrite ``summary.json`` atomically
        (e.g. ``record("timings_s", "report", 2.5)`` after the report step)."""
        *keys, value = keys_and_value
        d = self.summary
        for k in keys[:-1]:
            d = d.setdefault(k, {})
        d[keys[-1]] = value
        _dump(self.path / "summary.json", self.summary)

    # -- files -----------------------------------------------------------------------
    def _file(self, name):
        f = self.path / name
        return f if f.is_file() else None

    def map(self, name) -> np.ndarray | None:
        """Map ``name`` of :data:`MAPS` (float32, ``mask`` bool, ``facets`` int32), or None.

        Raises
        ------
        InputError
            The file is present but unreadable or of the wrong dimensions.
        """
        if name in self._given:
            return self._given[name]
        if ("map", name) in self._cache:
            return self._cache["map", name]
        if name not in MAPS:
            raise ValueError(f"name: unknown map {name!r}; known: {', '.join(MAPS)}")
        f = self._file(MAPS[name][0])
        a = None
        if f is not None:
            try:
                a = np.load(f, allow_pickle=False)
            except (OSError, ValueError) as exc:
                raise InputError(f"{one_line(f)}: cannot read ({exc})") from None
            ndim = _NDIM.get(name, 2)
            if a.ndim != ndim or min(a.shape) < 1:
                raise InputError(f"{one_line(f)}: expected a {ndim}-D array, got shape "
                                 f"{a.shape}")
            if name == "mask":
                a = a != 0 if a.dtype != bool else a
            elif name != "facets":
                if not np.issubdtype(a.dtype, np.number):
                    raise InputError(f"{one_line(f)}: expected numbers, got dtype {a.dtype}")
                a = a.astype(np.float32, copy=False)
        self._cache["map", name] = a
        return a

    def image(self, name) -> np.ndarray | None:
        """Image ``name`` of :data:`IMAGES` as float RGB (or grey) in [0, 1], or None."""
        if ("image", name) in self._cache:
            return self._cache["image", name]
        f = self._file(IMAGES[name])
        img = None if f is None else read_png(f)
        self._cache["image", name] = img
        return img

    def release(self) -> None:
        """Forget the maps and images read so far (a later call reads them again): a reader
        done with them, such as the report before its last pages, holds their memory no
        longer. Tables are kept, and the maps given in memory (their memory is the
        caller's)."""
        for key in [k for k in self._cache if k[0] != "table"]:
            del self._cache[key]

    def table(self, name) -> dict | None:
        """Table ``name`` of :data:`TABLES` as a dict of float columns, or None.

        Raises
        ------
        InputError
            The file is present but empty, lacks a required column or holds a non-number.
        """
        if ("table", name) in self._cache:
            return self._cache["table", name]
        file, required = TABLES[name]
        f = self._file(file)
        out = None
        if f is not None:
            out = _read_table(f, required)
        self._cache["table", name] = out
        return out

    # -- completeness ----------------------------------------------------------------
    @staticmethod
    def complete(folder, parameters: dict | None = None) -> tuple[bool, str]:
        """Whether ``folder`` holds complete results (made with ``parameters``, if given).

        Returns
        -------
        complete : bool
        reason : str
            Why not ("" when complete, or when the folder does not exist).
        """
        folder = Path(folder)
        if not folder.exists():
            return False, ""
        try:
            res = Results(folder)
        except InputError as exc:
            return False, f"{exc} (incomplete or not results)"
        if res.declared_format != FORMAT:
            return False, f"{one_line(folder / 'summary.json')}: key 'format' is not {FORMAT}"
        if parameters is not None:
            diff = res.differing_parameters(parameters)
            if diff:
                return False, (f"{one_line(folder / 'summary.json')}: made with different "
                               f"parameters ({', '.join(diff)}); re-analysed only with "
                               f"overwrite")
        return True, ""


def _flat(d: dict, prefix: str = "") -> dict:
    out = {}
    for k, v in d.items():
        if isinstance(v, dict):
            out.update(_flat(v, f"{prefix}{k}."))
        else:
            out[f"{prefix}{k}"] = v
    return out


def _read_table(f: Path, required) -> dict:
    try:
        with open(f, newline="", encoding="utf-8-sig") as fh:
            rows = list(csv.reader(fh))
    except (OSError, UnicodeDecodeError, csv.Error) as exc:
        raise InputError(f"{one_line(f)}: cannot read ({exc})") from None
    if not rows:
        raise InputError(f"{one_line(f)}: empty (expected the header {','.join(required)})")
    head = [h.strip() for h in rows[0]]
    absent = [c for c in required if c not in head]
    if absent:
        raise InputError(f"{one_line(f)}: missing column(s) {', '.join(absent)}")
    out = {}
    for c in head:
        j = head.index(c)
        try:
            out[c] = np.array([float(r[j]) if r[j].strip() else np.nan for r in rows[1:] if r],
                              dtype=np.float64)
        except (ValueError, IndexError):
            raise InputError(f"{one_line(f)}: column {c} holds a value that is not a number") \
                from None
    return out
