"""Measured spectra (delimited text): the one module that reads them.

Spectrometer software writes reflectance spectra in many dialects; :func:`read_spectrum`
reads them without configuration and says what it assumed:

* **delimiter** — tab, semicolon, comma or runs of whitespace, found from the first numeric
  row (tried in that order, so ``400,5;12,3`` is a semicolon file with decimal commas);
  with any delimiter but the comma a decimal comma is accepted;
* **preamble and header** — lines before the first numeric row are skipped (instrument
  metadata; ``#`` comments and ``>>>>>`` markers anywhere); the line just before the
  numbers, if it splits into two or more fields, is the header;
* **columns** — found by name (case-insensitive: ``wavelength_nm``, ``Wavelength (nm)``,
  ``lambda``, ``WL`` / ``R``, ``%R``, ``Reflectance (%)``, ``refl``, ...), else the first
  two of a two-column file; or chosen with ``columns`` (names or 1-based indices);
* **units** — wavelengths above 30 are nm, below are µm (visible spectra in the two units
  are 1000x apart, so the values decide; the header's unit is checked against them);
  reflectance is percent when its header says so (``%``, ``percent``) or a value exceeds
  1 (a fraction cannot), else a fraction.

Each assumption is one line in :attr:`Spectrum.notes` and in the log (INFO, or WARNING
when the file contradicts itself or the choice is a guess). Checks before any work: at
most :data:`~microfacet.io.limits.MAX_SPECTRUM_ROWS` rows of at most
:data:`MAX_LINE_CHARS` characters, finite values, at least :data:`MIN_WAVELENGTHS`
distinct wavelengths (duplicates are kept and counted). See docs/fit-spectrum.md.
"""

from __future__ import annotations

import csv
import itertools
import logging
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..core.errors import InputError, one_line
from .limits import MAX_SPECTRUM_ROWS

__all__ = ["FEW_WAVELENGTHS", "MAX_LINE_CHARS", "MAX_PREAMBLE_LINES", "MIN_WAVELENGTHS",
           "PLAUSIBLE_MAX_REFLECTANCE", "Spectrum", "parse_columns", "read_spectrum",
           "read_spectrum_csv"]

log = logging.getLogger(__name__)

#: Fewest distinct wavelengths a fit accepts, and below how many it warns.
MIN_WAVELENGTHS = 3
FEW_WAVELENGTHS = 10
#: A measured spectrum whose largest value is below this is implausible for anodized titanium
#: (its reflectance maxima are 0.2-0.6): warned about as a unit or scale mistake.
PLAUSIBLE_MAX_REFLECTANCE = 0.05
#: Longest line read (a spectrum row is a few dozen characters).
MAX_LINE_CHARS = 65_536
#: Most lines of metadata before the first numeric row.
MAX_PREAMBLE_LINES = 1_000
#: Wavelengths whose largest value is below this are in µm, otherwise in nm.
MICROMETRE_BELOW = 30.0
#: Reflectance values above 1 are percent; up to this they are also an unusually dark
#: sample (warned about).
CLEARLY_PERCENT_ABOVE = 1.5

_DELIMITERS = ("\t", ";", ",", " ")          # " " stands for runs of whitespace
_DELIM_NAMES = {"\t": "tab", ";": "semicolon", ",": "comma", " ": "whitespace"}
_WL_WORDS = {"wavelength", "wavelengths", "wave", "lambda", "λ", "wl", "lam", "nm", "um"}
_R_WORDS = {"r", "reflectance", "reflectivity", "refl", "reflection", "rel"}
_NOT_R = ("transmit", "absorb", "count", "intensity")
_UM_WORDS = {"um", "micron", "microns", "micrometer", "micrometre", "micrometers"}
_DECIMAL_COMMA = re.compile(r"^[+-]?\d*,\d+(?:[eE][+-]?\d+)?$")


@dataclass(frozen=True)
class Spectrum:
    """A measured spectrum as :func:`read_spectrum` read it.

    Attributes
    ----------
    wavelength_nm : ndarray (N,), float64
        Wavelengths in nm, ascending (duplicates kept).
    reflectance : ndarray (N,), float64
        Reflectance as a fraction (1 = 100 %).
    columns : (str, str)
        The wavelength and reflectance columns read, by header name or ``"column k"``.
    notes : tuple of str
        One line per assumption (delimiter, columns, units), in the order made.
    """

    wavelength_nm: np.ndarray
    reflectance: np.ndarray
    columns: tuple[str, str]
    notes: tuple[str, ...]


def parse_columns(columns):
    """``columns`` as two selectors, each a header name (str) or a 0-based index (int).

    Accepts ``"WL,R"``, ``"1,2"`` or a pair; numbers are 1-based (as a user counts).

    >>> parse_columns("1, %R")
    (0, '%R')
    """
    if isinstance(columns, str):
        parts = [p.strip() for p in columns.split(",")]
    else:
        parts = list(columns)
    if len(parts) != 2 or any(str(p).strip() == "" for p in parts):
        raise InputError(f"expected two columns as WAVELENGTH,REFLECTANCE (names or 1-based "
                         f"numbers), got {one_line(str(columns))!r}", param="columns")
    out = []
    for p in parts:
        text = str(p).strip()
        if isinstance(p, int) or text.isdigit():
            k = int(text)
            if k < 1:
                raise InputError(f"column numbers start at 1, got {k}", param="columns")
            out.append(k - 1)
        else:
            out.append(text)
    return tuple(out)


def read_spectrum_csv(path, *, columns=None):
    """Wavelengths (nm) and reflectance (fraction) of a spectrum file, as arrays.

    :func:`read_spectrum` without the notes (they are logged).

    Returns
    -------
    wavelength_nm, reflectance : ndarray (N,), float64
    """
    s = read_spectrum(path, columns=columns)
    return s.wavelength_nm, s.reflectance


def read_spectrum(path, *, columns=None) -> Spectrum:
    """Read a reflectance spectrum exported by a spectrometer (see the module docstring).

    Parameters
    ----------
    path : str or Path
        Delimited text: UTF-8 (a byte-order mark is accepted) or, failing that, Windows-1252.
    columns : str or (str or int, str or int), optional
        The wavelength and reflectance columns, by header name (case-insensitive) or 1-based
        number (``"Wavelength,%R"``, ``"1,3"``); default: found from the header.

    Returns
    -------
    Spectrum
        Wavelength in nm and reflectance as a fraction, sorted by wavelength, with a note
        for every assumption.

    Raises
    ------
    InputError
        Naming the file and the line of a bad value, or ``columns`` for a column that is not
        there; also for more than :data:`~microfacet.io.limits.MAX_SPECTRUM_ROWS` rows or
        fewer than :data:`MIN_WAVELENGTHS` distinct wavelengths.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "s.txt"
    >>> _ = p.write_text("Wavelength (µm);R (%)\\n0,40;30,5\\n0,50;20,0\\n0,60;35,5\\n",
    ...                  encoding="utf-8")
    >>> s = read_spectrum(p)
    >>> s.wavelength_nm.tolist(), s.reflectance.tolist()
    ([400.0, 500.0, 600.0], [0.305, 0.2, 0.355])
    >>> s.notes[0]
    'semicolon-delimited, decimal comma; header on line 1'
    """
    path = Path(path)
    shown = one_line(path)
    if not path.is_file():
        raise InputError(f"{shown}: no such file")
    wanted = parse_columns(columns) if columns is not None else None
    try:
        text_lines, encoding = _read_lines(path, shown)
    except OSError as exc:
        raise InputError(f"{shown}: cannot read ({exc})") from None
    notes = [] if encoding == "utf-8" else [("not UTF-8: read as Windows-1252", logging.INFO)]
    lines = iter(text_lines)
    header, delim, first = _first_numeric_row(lines, shown, notes)
    iw, ir = _choose_columns(shown, header, len(_split(first[1], delim)), wanted, notes)
    names = [_column_name(header, i) for i in (iw, ir)]
    wl, R = _read_numbers(shown, itertools.chain([first], lines), delim, (iw, ir), names)
    distinct = np.unique(wl).size
    if distinct < MIN_WAVELENGTHS:
        raise InputError(f"{shown}: column {names[0]}: {distinct} distinct wavelength(s) "
                         f"in {len(wl)} rows; a thickness fit needs at least {MIN_WAVELENGTHS}")
    wl = _wavelength_unit(wl, names[0], header is not None, notes)
    R = _reflectance_unit(shown, R, names[1], header is not None, notes)
    _log_notes(shown, notes, distinct, R)
    order = np.argsort(wl, kind="stable")
    return Spectrum(wavelength_nm=wl[order], reflectance=R[order],
                    columns=(names[0].strip("'"), names[1].strip("'")),
                    notes=tuple(n for n, _ in notes))


def _first_numeric_row(lines, shown, notes):
    """The header (None: none), the delimiter and the first row of numbers
    ``(lineno, line)``, noted; ``lines`` is left after that row."""
    previous, first = None, None
    for lineno, line in lines:
        if _skipped(line):
            if line.strip().startswith("#"):
                previous = (lineno, line)      # "# wavelength reflectance" may be the header
            continue
        delim = _data_delimiter(line)
        if delim is not None:
            first = (lineno, line)
            break
        previous = (lineno, line)
        if lineno > MAX_PREAMBLE_LINES:
            break
    if first is None:
        if previous is None:
            raise InputError(f"{shown}: empty file")
        raise InputError(f"{shown}: no row of numbers (wavelength and reflectance) in the first "
                         f"{min(previous[0], MAX_PREAMBLE_LINES):,} lines")
    header = _header(previous, delim) if previous is not None else None
    comma = delim != "," and any(_DECIMAL_COMMA.match(f) for f in _split(first[1], delim))
    where = f"header on line {previous[0]}" if header else "no header"
    notes.append((f"{_DELIM_NAMES[delim]}-delimited{', decimal comma' if comma else ''}; "
                  f"{where}", logging.INFO))
    return header, delim, first


def _read_numbers(shown, rows, delim, columns, names):
    """Wavelengths and reflectances of the numeric ``rows`` (the chosen ``columns``)."""
    iw, ir = columns
    wl, R = [], []
    for row_no, row in rows:
        if _skipped(row):
            continue
        parts = _split(row, delim)
        try:
            w, r = _number(parts[iw], delim), _number(parts[ir], delim)
        except (ValueError, IndexError):
            raise InputError(f"{shown}: line {row_no}: expected numbers in columns {names[0]} "
                             f"and {names[1]}, got {one_line(row.strip())[:80]!r}") from None
        if not (np.isfinite(w) and np.isfinite(r)):
            raise InputError(f"{shown}: line {row_no}: non-finite value in columns "
                             f"{names[0]} and {names[1]}")
        wl.append(w)
        R.append(r)
        if len(wl) > MAX_SPECTRUM_ROWS:
            raise InputError(f"{shown}: more than {MAX_SPECTRUM_ROWS:,} rows; a spectrum has a "
                             f"few thousand at most")
    return np.array(wl), np.array(R)


def _log_notes(shown, notes, distinct, R):
    """Log every note, and warn about few wavelengths or an implausibly dark spectrum."""
    for note, level in notes:
        log.log(level, "%s: %s", shown, note)
    if distinct < FEW_WAVELENGTHS:
        log.warning("%s: only %d distinct wavelengths; interference minima of different orders "
                    "may fit equally well (compare the runner-up)", shown, distinct)
    if R.max() < PLAUSIBLE_MAX_REFLECTANCE:
        log.warning("%s: the largest reflectance is %.3g (%.2g %%); anodized titanium reflects "
                    "20-60 %% at its maxima: check the file's unit (fraction or percent) or its "
                    "scale (fit_scale fits one)", shown, R.max(), 100 * R.max())


# ------------------------------------------------------------------------------ lines
def _read_lines(path, shown):
    """``[(lineno, text), ...]`` and the encoding; long lines refused while reading."""
    with path.open("rb") as f:
        start = f.read(2)
    utf16 = start in (b"\xff\xfe", b"\xfe\xff")          # Windows "Unicode" exports
    for encoding in (("utf-16",) if utf16 else ("utf-8-sig", "cp1252")):
        out = []
        try:
            with path.open(encoding=encoding, errors="strict", newline=None) as f:
                lineno = 0
                while True:
                    line = f.readline(MAX_LINE_CHARS + 1)
                    if not line:
                        break
                    lineno += 1
                    if len(line) > MAX_LINE_CHARS and not line.endswith("\n"):
                        raise InputError(f"{shown}: line {lineno}: longer than "
                                         f"{MAX_LINE_CHARS:,} characters; not a spectrum")
                    if "\x00" in line:
                        raise InputError(f"{shown}: line {lineno}: binary data; not a text "
                                         f"spectrum")
                    out.append((lineno, line.rstrip("\r\n")))
                    if lineno > MAX_SPECTRUM_ROWS + MAX_PREAMBLE_LINES + 1:
                        raise InputError(f"{shown}: more than {MAX_SPECTRUM_ROWS:,} rows; a "
                                         f"spectrum has a few thousand at most")
        except UnicodeDecodeError:
            continue
        return out, ("utf-8" if encoding in ("utf-8-sig", "utf-16") else encoding)
    raise InputError(f"{shown}: cannot decode as text (not UTF-8, UTF-16 or Windows-1252)")


def _skipped(line):
    s = line.strip()
    return not s or s.startswith("#") or s.startswith(">>>")


def _split(line, delim):
    if delim == " ":
        return line.split()
    try:
        fields = next(csv.reader([line], delimiter=delim))
    except (csv.Error, StopIteration):
        return []
    fields = [f.strip() for f in fields]
    while fields and not fields[-1]:     # a trailing delimiter
        fields.pop()
    return fields


def _number(text, delim):
    text = text.strip()
    if delim != "," and _DECIMAL_COMMA.match(text):
        text = text.replace(",", ".")
    return float(text)


def _data_delimiter(line):
    """The delimiter under which ``line`` is a row of numbers (first field a number, two or
    more numbers), or None."""
    for delim in _DELIMITERS:
        fields = _split(line, delim)
        if len(fields) < 2:
            continue
        numbers = 0
        for f in fields:
            try:
                _number(f, delim)
                numbers += 1
            except ValueError:
                if numbers == 0:
                    break
        if numbers >= 2:
            return delim
    return None


def _header(previous, delim):
    """The field names of the line before the first numeric row, or None if it is not a
    header (fewer than two fields, or all numbers)."""
    _, line = previous
    line = line.strip().lstrip("#").strip()
    if delim == " ":
        # "wavelength (nm)  R (%)": split on tabs or 2+ spaces, else on spaces not before a
        # bracket (so a unit stays with its name).
        fields = [f for f in re.split(r"\t|\s{2,}", line) if f]
        if len(fields) < 2:
            fields = [f for f in re.split(r"\s+(?![(\[])", line) if f]
    else:
        fields = _split(line, delim)
    fields = [f.strip().strip('"').strip() for f in fields]
    if len(fields) < 2 or all(_is_number(f) for f in fields):
        return None
    return fields


def _is_number(text):
    try:
        _number(text, ";")
    except ValueError:
        return False
    return True


# ---------------------------------------------------------------------------- columns
def _tokens(name):
    name = name.lower().replace("µ", "u").replace("μ", "u")
    return [t for t in re.split(r"[^a-z0-9%λ]+", name) if t]


def _is_wavelength(name):
    t = _tokens(name)
    return bool(t) and t[0] in _WL_WORDS


def _is_reflectance(name):
    low = name.lower()
    if any(w in low for w in _NOT_R):
        return False
    t = [w.strip("%") for w in _tokens(name)]
    t = [w for w in t if w]
    return (bool(t) and t[0] in _R_WORDS) or "reflect" in low or low.strip() == "%"


def _column_name(header, i):
    if header is not None and i < len(header):
        return f"'{one_line(header[i])}'"
    return f"'column {i + 1}'"


def _choose_columns(shown, header, ncols, wanted, notes):
    """0-based indices of the wavelength and reflectance columns."""
    shown_header = ",".join(header) if header else ""
    if wanted is not None:
        idx = []
        for sel in wanted:
            if isinstance(sel, int):
                if sel >= ncols:
                    raise InputError(f"{shown} has {ncols} columns, not {sel + 1}",
                                     param="columns")
                idx.append(sel)
                continue
            if header is None:
                raise InputError(f"{shown} has no header; choose columns by number (1-{ncols})",
                                 param="columns")
            hits = [i for i, h in enumerate(header) if h.lower() == sel.lower()]
            if not hits:
                raise InputError(f"no column {sel!r} in {shown} (header: "
                                 f"{one_line(shown_header)[:120]})", param="columns")
            idx.append(hits[0])
        if idx[0] == idx[1]:
            raise InputError("the wavelength and reflectance columns are the same",
                             param="columns")
        notes.append((f"columns as chosen: wavelength {_column_name(header, idx[0])}, "
                      f"reflectance {_column_name(header, idx[1])}", logging.INFO))
        return idx[0], idx[1]
    if header is None:
        if ncols == 2:
            notes.append(("column 1 read as wavelength, column 2 as reflectance",
                          logging.INFO))
        else:
            notes.append((f"{ncols} columns and no header: column 1 read as wavelength, "
                          f"column 2 as reflectance (choose others with `columns`)",
                          logging.WARNING))
        return 0, 1
    iw = next((i for i, h in enumerate(header) if _is_wavelength(h)), None)
    ir = next((i for i, h in enumerate(header) if i != iw and _is_reflectance(h)), None)
    if iw is not None and ir is not None:
        notes.append((f"columns {_column_name(header, iw)} (wavelength) and "
                      f"{_column_name(header, ir)} (reflectance)", logging.INFO))
        return iw, ir
    if ncols == 2:
        iw = 0 if iw is None else iw
        ir = 1 - iw
        notes.append((f"header {one_line(shown_header)[:80]!r} does not name both: "
                      f"{_column_name(header, iw)} read as wavelength, "
                      f"{_column_name(header, ir)} as reflectance", logging.WARNING))
        return iw, ir
    missing = "wavelength" if iw is None else "reflectance"
    raise InputError(f"{shown}: no {missing} column found in the header "
                     f"{one_line(shown_header)[:120]!r}; name the two with `columns`")


# ------------------------------------------------------------------------------ units
def _wavelength_unit(wl, name, has_header, notes):
    t = _tokens(name) if has_header else []
    said = "nm" if "nm" in t else "µm" if any(w in _UM_WORDS for w in t) else None
    lo, hi = wl.min(), wl.max()
    values = "µm" if hi < MICROMETRE_BELOW else "nm"
    span = f"{lo:g}-{hi:g}"
    if said is None:
        notes.append((f"wavelength: no unit in the header; values {span} read as {values}",
                      logging.INFO))
    elif said == values:
        notes.append((f"wavelength in {values} (header {name})", logging.INFO))
    else:
        notes.append((f"wavelength: header {name} says {said} but values {span} can only be "
                      f"{values}; read as {values}", logging.WARNING))
    return wl * 1000.0 if values == "µm" else wl


def _reflectance_unit(shown, R, name, has_header, notes):
    t = _tokens(name) if has_header else []
    said_percent = has_header and ("%" in name or "percent" in t or "pct" in t)
    top = R.max()
    if said_percent:
        if top <= 1.0:
            notes.append((f"reflectance: header {name} says percent but every value is <= 1 "
                          f"(largest {top:g}); read as percent", logging.WARNING))
        else:
            notes.append((f"reflectance in percent (header {name}), divided by 100",
                          logging.INFO))
        R = R / 100.0
    elif top > CLEARLY_PERCENT_ABOVE:
        notes.append((f"reflectance: values up to {top:g} read as percent and divided by 100",
                      logging.INFO))
        R = R / 100.0
    elif top > 1.0:
        notes.append((f"reflectance: values up to {top:g} exceed 1 (no fraction does) but not "
                      f"{CLEARLY_PERCENT_ABOVE:g}: read as percent of a very dark sample",
                      logging.WARNING))
        R = R / 100.0
    else:
        notes.append((f"reflectance read as a fraction (values up to {top:g})", logging.INFO))
    if R.max() > 1.05:
        raise InputError(f"{shown}: column {name}: values up to {top:g} are neither a fraction "
                         f"nor a percentage (raw counts? export the reflectance, or choose "
                         f"the column with `columns`)")
    if R.min() < -0.05:
        raise InputError(f"{shown}: column {name}: reflectance down to {R.min():.3g}; a "
                         f"reflectance is not negative beyond noise (a dark-corrected "
                         f"spectrum, or the wrong column?)")
    if R.min() < 0:
        notes.append((f"reflectance: {int(np.sum(R < 0))} value(s) slightly below 0 (noise) "
                      f"kept", logging.WARNING))
    return R
