"""ISO 25178-2 areal surface-texture parameters of a height map: Sq, Sa, Sdq, Sdr.

ISO 25178-2 defines the field parameters on a *scale-limited surface*: for the S-F surface
the form is removed by an F-operator, for a nominally flat sample the least-squares plane
(``reference="plane"``, the default), and the heights are measured from that plane. On the
definition area A (here: the reliable pixels, NaN heights excluded)

* ``Sq = sqrt(1/A ∬ z² dA)``, root mean square height (µm);
* ``Sa = 1/A ∬ |z| dA``, arithmetic mean height (µm);
* ``Sdq = sqrt(1/A ∬ (∂z/∂x)² + (∂z/∂y)² dA)``, root mean square gradient (µm/µm);
* ``Sdr = 1/A ∬ (sqrt(1 + (∂z/∂x)² + (∂z/∂y)²) − 1) dA × 100 %``, developed interfacial
  area ratio.

The gradient is discretised as SurfaceTopography's ``Topography.rms_gradient()`` does it:
forward differences with each axis' own spacing (non-square pixels in µm), one sample per
grid cell whose corner ``(i, j)`` and its neighbours ``(i, j+1)`` and ``(i+1, j)`` are all
reliable. Sdq and Sdr use the same cells, so a tilted plane gives them exactly. No S- or
L-filter is applied beyond the pixel grid. ``reference="mean"`` removes the mean height
only, which is what SurfaceTopography's ``rms_height_from_area()`` and ``rms_gradient()``
compute on a topography as read (no detrending); SurfaceTopography's ``detrend("height")``
is the least-squares plane.

References
----------
.. [1] ISO 25178-2:2021, Geometrical product specifications (GPS) — Surface texture: Areal —
   Part 2: Terms, definitions and surface texture parameters (§4.1.1 Sq, §4.1.7 Sa, §4.3.1
   Sdq, §4.3.2 Sdr; the S-F surface and the F-operator, §3.1).
.. [2] L. Pastewka et al., SurfaceTopography (MIT), ``Uniform/ScalarParameters.py``:
   ``Sq``, ``rms_gradient``.

Examples
--------
A plane rising 0.3 µm per µm along x and 0.4 along y on 0.5 × 0.25 µm pixels has no
roughness about its least-squares plane, an RMS gradient of 0.5 about its mean, and
``Sdr = (sqrt(1 + 0.3² + 0.4²) − 1) · 100 %``:

>>> import numpy as np
>>> y, x = np.mgrid[0:20, 0:30] * np.array([0.5, 0.25])[:, None, None]
>>> h = 0.4 * y + 0.3 * x
>>> p = areal_parameters(h, pixel_size_um=(0.5, 0.25), reference="mean")
>>> round(p.Sdq, 6), round(p.Sdr_percent, 4), round(((1 + 0.25) ** 0.5 - 1) * 100, 4)
(0.5, 11.8034, 11.8034)
>>> round(areal_parameters(h, pixel_size_um=(0.5, 0.25)).Sq_um, 9)
0.0
>>> areal_parameters(h, pixel_size_um=(0.5, 0.25), reference="median")
Traceback (most recent call last):
...
microfacet.core.errors.InputError: reference: must be 'plane' or 'mean', got 'median'
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..core import threads
from ..core.errors import InputError
from ..core.pixels import pixel_size_yx

__all__ = ["REFERENCES", "ArealParameters", "areal_parameters"]

#: Reference surfaces: the least-squares plane (ISO 25178-2's S-F surface with a plane as
#: F-operator) or the mean height (SurfaceTopography's default).
REFERENCES = {"plane": "least-squares plane", "mean": "mean height"}


@dataclass(frozen=True)
class ArealParameters:
    """Areal parameters of a height map (ISO 25178-2 names, units in the field names).

    Attributes
    ----------
    Sq_um, Sa_um : float
        RMS and arithmetic mean height about the reference, µm.
    Sdq : float
        RMS gradient, µm/µm (NaN without a grid cell of three reliable corners).
    Sdr_percent : float
        Developed interfacial area ratio, % (NaN likewise).
    reference : str
        ``"plane"`` or ``"mean"``.
    plane_slope_yx : tuple of float
        ``(∂z/∂y, ∂z/∂x)`` of the removed plane, µm/µm (``(0, 0)`` for ``"mean"``).
    n_points : int
        Reliable heights in Sq and Sa.
    n_cells : int
        Grid cells in Sdq and Sdr.
    """

    Sq_um: float
    Sa_um: float
    Sdq: float
    Sdr_percent: float
    reference: str
    plane_slope_yx: tuple
    n_points: int
    n_cells: int


def areal_parameters(height_um, *, pixel_size_um, reference: str = "plane",
                     valid=None) -> ArealParameters:
    """Sq, Sa, Sdq and Sdr of ``height_um`` on its reliable pixels (module docstring).

    Parameters
    ----------
    height_um : array_like, shape (H, W)
        Heights in µm, rows = y, columns = x; NaN or ±inf where unreliable.
    pixel_size_um : float or (float, float)
        Pixel size in µm, one number or ``(y, x)``.
    reference : {"plane", "mean"}
        Remove the least-squares plane (ISO 25178-2 S-F surface) or only the mean height
        (SurfaceTopography's ``rms_height_from_area()``, ``rms_gradient()``).
    valid : array_like of bool, shape (H, W), optional
        Pixels that may be used (default: all); non-finite heights never are.

    Returns
    -------
    ArealParameters

    Raises
    ------
    InputError
        Naming the parameter: ``height_um`` not 2-D or with fewer than 3 usable heights
        (a plane needs 3, not on one line), ``pixel_size_um`` not positive, ``valid`` of
        another shape, ``reference`` unknown.
    """
    if reference not in REFERENCES:
        raise InputError(f"must be 'plane' or 'mean', got {reference!r}",
                         param="reference")
    try:
        py, px = pixel_size_yx(pixel_size_um)
    except ValueError as exc:
        raise InputError(str(exc), param="pixel_size_um") from None
    h = np.asarray(height_um)
    if h.dtype.kind not in "biuf":
        h = np.asarray(h, dtype=np.float64)
    if h.ndim != 2:
        raise InputError(f"must be a 2-D map, got shape {h.shape}",
                         param="height_um")
    ok = np.isfinite(h)
    if valid is not None:
        v = np.asarray(valid, dtype=bool)
        if v.shape != h.shape:
            raise InputError(f"has shape {v.shape}, `height_um` {h.shape}",
                             param="valid")
        ok &= v
    n = int(ok.sum())
    if n < 3:
        raise InputError(f"{n} usable heights; the parameters need at least 3", param="height_um")
    z, slope = _residuals(h, ok, py, px, reference)
    # each float64 array let go once its numbers are taken (8 bytes a pixel each)
    zv = z[ok]
    sq, sa = math.sqrt(float(np.mean(zv ** 2))), float(np.mean(np.abs(zv)))
    del zv
    g2 = _cell_gradients_squared(z, ok, py, px)
    del z
    nc = int(g2.size)
    sdq = math.sqrt(float(np.mean(g2))) if nc else math.nan
    if nc:
        g2 += 1.0                                   # √(1 + g²) − 1, in place
        np.sqrt(g2, out=g2)
        g2 -= 1.0
    sdr = float(np.mean(g2)) * 100.0 if nc else math.nan
    return ArealParameters(Sq_um=sq, Sa_um=sa, Sdq=sdq, Sdr_percent=sdr,
                           reference=reference, plane_slope_yx=slope, n_points=n,
                           n_cells=nc)


def _residuals(h, ok, py, px, reference):
    """Heights (float64) minus the reference (NaN off ``ok``) and the removed plane's
    (∂z/∂y, ∂z/∂x); the plane from its normal equations, summed a block of rows at a time
    (an (n, 3) design matrix would hold 24 bytes per pixel)."""
    z = np.array(h, dtype=np.float64)
    if reference == "mean":
        z -= z[ok].mean()
        z[~ok] = np.nan
        return z, (0.0, 0.0)
    n, sr, sc, srr, scc, src = _pixel_moments(ok)
    if (n * srr - sr * sr) * (n * scc - sc * sc) == (n * src - sr * sc) ** 2:
        raise InputError("the usable heights lie on one line: no plane to remove "
                         "(`reference` 'mean' needs none)", param="height_um")
    yc = (np.arange(z.shape[0]) - sr / n) * py
    xc = (np.arange(z.shape[1]) - sc / n) * px
    z_mean = float(np.mean(z[ok]))    # heights about their mean: a stage's offset of
    normal, rhs = np.zeros((3, 3)), np.zeros(3)  # millimetres costs the sums no digits
    for a, b in threads.row_chunks(z.shape):
        r, c = np.nonzero(ok[a:b])
        design = np.stack([np.ones(r.size), yc[a + r], xc[c]])
        normal += design @ design.T
        rhs += design @ (z[a:b][r, c] - z_mean)
    coef = np.linalg.solve(normal, rhs)
    coef[0] += z_mean
    for a, b in threads.row_chunks(z.shape):
        z[a:b] -= coef[0] + coef[1] * yc[a:b, None] + coef[2] * xc[None, :]
    z[~ok] = np.nan
    return z, (float(coef[1]), float(coef[2]))


def _pixel_moments(ok) -> tuple:
    """Count, sums and sums of products of the row and column indices of the pixels of
    ``ok``, exact (Python integers): ``(n, Σr, Σc, Σr², Σc², Σrc)``. The pixels lie on one
    line where the determinant of their scatter is 0."""
    r, c = np.arange(ok.shape[0], dtype=np.int64), np.arange(ok.shape[1], dtype=np.int64)
    rows_n, cols_n = ok.sum(axis=1), ok.sum(axis=0)
    src = sum(int(np.dot(r[a:b], ok[a:b].astype(np.int64) @ c))
              for a, b in threads.row_chunks(ok.shape))
    return (int(rows_n.sum()), int(np.dot(r, rows_n)), int(np.dot(c, cols_n)),
            int(np.dot(r * r, rows_n)), int(np.dot(c * c, cols_n)), src)


def _cell_gradients_squared(z, ok, py, px):
    """|∇z|² of each grid cell whose corner and its +x and +y neighbours are in ``ok``
    (forward differences), in row order, a block of rows at a time."""
    H, W = z.shape
    parts = [np.zeros(0)]
    for a, b in threads.row_chunks((H - 1, W)):
        gx = (z[a:b, 1:] - z[a:b, :-1]) / px
        gy = (z[a + 1:b + 1, :-1] - z[a:b, :-1]) / py
        cell = ok[a:b, :-1] & ok[a:b, 1:] & ok[a + 1:b + 1, :-1]
        parts.append(gx[cell] ** 2 + gy[cell] ** 2)
    return np.concatenate(parts)
