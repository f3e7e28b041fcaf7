"""What every page of the report reads: the results folder and what is derived from it once.

The folder is read only through :class:`microfacet.io.results.Results` (which reads each
file once); a :class:`Context` adds the fitted mixtures, the map geometry, the colour mask,
the largest measurable tilt, the checks the report needs before it draws anything, and the
numbers of the maps that more than one panel or page uses (shares without a value,
percentiles, colour limits), computed once.
"""

from __future__ import annotations

import math

import numpy as np

from ..core.errors import InputError, one_line
from ..io.results import IMAGES, MAPS, TABLES, Results
from .arrays import limits_of, value_stats
from .layout import Geometry, positive

__all__ = ["Context"]

#: The files a panel is drawn from (all optional; page 4 lists the missing ones), named by
#: :mod:`microfacet.io.results`.
DRAWN_FILES = ((IMAGES["all_in_focus"],)
               + tuple(MAPS[n][0] for n in ("height_um", "mask", "thickness_nm", "tilt_deg",
                                            "tilt_sigma_deg", "delta_e", "tilt_height_deg"))
               + tuple(TABLES[n][0] for n in ("thickness_pdf", "ndf_pdf", "thickness_roi")))
#: The density tables and their grid column.
_GRIDS = {"thickness_pdf": "thickness_nm", "ndf_pdf": "tilt_deg"}


class Context:
    """A results folder opened for the report.

    Parameters
    ----------
    res : Results

    Attributes
    ----------
    res : Results
    thick : ThicknessMixture or None
        The fitted thickness mixture (None: no fit).
    ndf : NDFMixture or None
        The fitted NDF lobes (None: no fit).
    geom : Geometry
        Map extents (and scale bars) in µm when ``inputs.pixel_size_um`` is recorded, else in
        pixels.
    mask : ndarray of bool or None
        ``mask.npy`` (True = masked).
    inputs : dict
        ``summary["inputs"]`` (empty if absent).
    stack : str or None
        The stack analysed, as recorded.

    Raises
    ------
    InputError
        A mixture in ``summary.json`` or ``mask.npy`` is malformed.
    """

    def __init__(self, res: Results):
        self.res = res
        self.thick = res.thickness_mixture()
        self.ndf = res.ndf_mixture()
        inputs = res.get("inputs")
        self.inputs = inputs if isinstance(inputs, dict) else {}
        self.stack = (self.inputs.get("stack") or self.inputs.get("stack_path")
                      or self.inputs.get("path"))
        self.geom = Geometry(self.inputs.get("pixel_size_um"))
        self.mask = res.map("mask")
        self._numbers: dict = {}

    def cached(self, key, compute):
        """``compute()``, computed once per ``key`` (a hashable) for this folder: what more
        than one panel, page or rendering (the PDF and the PNG child) uses."""
        if key not in self._numbers:
            self._numbers[key] = compute()
        return self._numbers[key]

    def no_value(self, name):
        """The share of the pixels of map ``name`` without a finite value (None: no map)."""
        def compute():
            a = self.res.map(name)
            if a is None:
                return None
            return 1.0 - np.count_nonzero(np.isfinite(a)) / max(a.size, 1)
        return self.cached(("no_value", name), compute)

    def percentiles(self, names, q=(1.0, 99.0)):
        """``((percentiles q), min, max)`` of the finite values of the maps ``names`` (one
        name or several, taken together), or None if there are none (see
        :func:`~microfacet.report.arrays.value_stats`)."""
        names = (names,) if isinstance(names, str) else tuple(names)
        q = tuple(float(v) for v in q)

        def compute():
            maps = [a for a in (self.res.map(n) for n in names) if a is not None]
            return value_stats(maps, list(q))
        return self.cached(("percentiles", names, q), compute)

    def limits(self, names, lo=1.0, hi=99.0, *, floor=None):
        """Colour limits ``(vmin, vmax, extend)`` of the maps ``names`` taken together, as
        :func:`~microfacet.report.arrays.colour_limits`."""
        return limits_of(self.percentiles(names, (lo, hi)), lo, floor=floor)

    def identification(self, key) -> tuple[bool, str]:
        """``(identified, reason)`` of the ``"thickness"`` or ``"ndf"`` distribution as
        ``summary.json`` records it (identified when the key is absent: older results)."""
        ident = self.res.get(key, "mixture", "identified")
        if key == "ndf" and self.res.get("ndf", "identified") is not None:
            ident = self.res.get("ndf", "identified")
        reason = (self.res.get(key, "reason") if key == "ndf" else None) \
            or self.res.get(key, "mixture", "reason") or ""
        return ident is not False, str(reason)

    @classmethod
    def open(cls, results_dir, *, maps=None) -> "Context":
        """The context of the results folder ``results_dir`` with the ``maps`` given in
        memory (raises as :class:`Results`)."""
        return cls(Results(results_dir, maps=maps))

    def max_tilt(self):
        """The largest measurable tilt (asin(NA)/2), degrees, or None."""
        v = positive(self.res.get("ndf", "max_tilt_deg"))
        if v is None:
            na = positive(self.inputs.get("numerical_aperture"))
            if na is not None and na <= 1:
                v = math.degrees(math.asin(na)) / 2.0
        return v

    def optics(self, key):
        """``film``, ``substrate`` or ``illuminant`` as recorded (``inputs``, or the top
        level of a version-1 summary), or None."""
        return self.res.optics().get(key)

    def density_table(self, name):
        """``thickness_pdf`` or ``ndf_pdf`` as a dict of columns, or None if the file is
        absent or has no rows.

        Raises
        ------
        InputError
            The file is malformed, or its grid is not strictly increasing (at least two
            finite values): its bins could not be drawn.
        """
        t = self.res.table(name)
        if t is None or t[_GRIDS[name]].size == 0:
            return None
        x = t[_GRIDS[name]]
        if x.size < 2 or not np.all(np.isfinite(x)) or np.any(np.diff(x) <= 0):
            raise InputError(f"{one_line(self.res.path / TABLES[name][0])}: column "
                             f"{_GRIDS[name]} must be a strictly increasing grid of at least "
                             f"two numbers")
        return t

    def check_tables(self):
        """Read every table now, so that a malformed one fails before anything is drawn."""
        for name in _GRIDS:
            self.density_table(name)
        self.res.table("thickness_roi")

    def missing_files(self):
        """File names of :data:`DRAWN_FILES` that are not in the folder."""
        return [f for f in DRAWN_FILES if not (self.res.path / f).is_file()]
