"""Measured spectra (CSV): the one module that reads them.

A spectrum file has a header with the columns ``wavelength_nm`` and ``reflectance`` (other
columns are ignored); reflectance as a fraction or in percent. Checks before any work: at most
:data:`~microfacet.io.limits.MAX_SPECTRUM_ROWS` rows, at least 3 distinct wavelengths, values
that are valid but almost surely a unit mistake warned about.
"""

from __future__ import annotations

import csv
import logging
from pathlib import Path

import numpy as np

from ..core.errors import InputError, one_line
from .limits import MAX_SPECTRUM_ROWS

__all__ = ["FEW_WAVELENGTHS", "MIN_WAVELENGTHS", "PLAUSIBLE_MAX_REFLECTANCE",
           "read_spectrum_csv"]

log = logging.getLogger(__name__)

#: Fewest distinct wavelengths a fit accepts, and below how many it warns.
MIN_WAVELENGTHS = 3
FEW_WAVELENGTHS = 10
#: A measured spectrum whose largest value is below this is implausible for anodized titanium
#: (its reflectance maxima are 0.2-0.6): warned about as a unit or scale mistake.
PLAUSIBLE_MAX_REFLECTANCE = 0.05


def read_spectrum_csv(path):
    """Read a ``wavelength_nm,reflectance`` CSV (header required; extra columns ignored).

    Reflectance may be a fraction (0-1) or a percentage: a column with a value above 1 (which
    no fraction has) is read as percent and divided by 100 (logged). A spectrum that never
    exceeds :data:`PLAUSIBLE_MAX_REFLECTANCE` is accepted with a warning (anodized titanium
    reflects 20-60 % at its maxima: a unit or scale mistake). A UTF-8 byte-order mark is
    accepted.

    Returns
    -------
    wavelength_nm, reflectance : ndarray (N,), float64

    Raises
    ------
    InputError
        Naming the file, and the line for a bad value; also for more than
        :data:`~microfacet.io.limits.MAX_SPECTRUM_ROWS` rows or fewer than
        :data:`MIN_WAVELENGTHS` distinct wavelengths.
    """
    path = Path(path)
    shown = one_line(path)
    if not path.is_file():
        raise InputError(f"{shown}: no such file")
    rows = []
    try:
        with path.open(newline="", encoding="utf-8-sig") as f:
            for row in csv.reader(f):
                if row and any(c.strip() for c in row):
                    rows.append(row)
                    if len(rows) > MAX_SPECTRUM_ROWS + 1:
                        raise InputError(f"{shown}: more than {MAX_SPECTRUM_ROWS:,} rows; a "
                                         f"spectrum has a few thousand at most")
    except (OSError, UnicodeDecodeError, csv.Error) as exc:
        raise InputError(f"{shown}: cannot read ({exc})") from None
    if not rows:
        raise InputError(f"{shown}: empty file")
    header = [c.strip() for c in rows[0]]
    for key in ("wavelength_nm", "reflectance"):
        if key not in header:
            raise InputError(f"{shown}: missing column {key!r} (header is {','.join(header)})")
    iw, ir = header.index("wavelength_nm"), header.index("reflectance")
    wl, R = [], []
    for lineno, row in enumerate(rows[1:], start=2):
        try:
            w, r = float(row[iw]), float(row[ir])
        except (ValueError, IndexError):
            raise InputError(f"{shown}: line {lineno}: expected numbers in columns "
                             f"wavelength_nm and reflectance, got "
                             f"{one_line(','.join(row))[:80]!r}") from None
        if not (np.isfinite(w) and np.isfinite(r)):
            raise InputError(f"{shown}: line {lineno}: non-finite value")
        wl.append(w)
        R.append(r)
    wl, R = np.array(wl), np.array(R)
    distinct = np.unique(wl).size
    if distinct < MIN_WAVELENGTHS:
        raise InputError(f"{shown}: column 'wavelength_nm': {distinct} distinct wavelength(s) "
                         f"in {len(wl)} rows; a thickness fit needs at least {MIN_WAVELENGTHS}")
    if distinct < FEW_WAVELENGTHS:
        log.warning("%s: only %d distinct wavelengths; interference minima of different orders "
                    "may fit equally well (compare the runner-up)", shown, distinct)
    if 1.0 + 1e-6 < R.max() <= 100:  # a reflectance above 1 cannot be a fraction
        log.info("%s: reflectance read as percent (largest value %g) and divided by 100",
                 shown, R.max())
        R = R / 100.0
    if R.min() < 0 or R.max() > 1.0 + 1e-6:
        raise InputError(f"{shown}: column 'reflectance' must be a fraction 0-1 or a percentage")
    if R.max() < PLAUSIBLE_MAX_REFLECTANCE:
        log.warning("%s: the largest reflectance is %.3g (%.2g %%); anodized titanium reflects "
                    "20-60 %% at its maxima: check the file's unit (fraction or percent) or its "
                    "scale (fit_scale fits one)", shown, R.max(), 100 * R.max())
    order = np.argsort(wl)
    return wl[order], R[order]
