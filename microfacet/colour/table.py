"""Colour table: incidence angle θ × film thickness d → CIE XYZ, CIELAB and linear sRGB.

The colour of a facet seen at incidence θ through an oxide of thickness d is the
thin-film reflectance spectrum R(λ; θ, d) (seed eqs. 2-4) integrated against the colour
matching functions under the illuminant. Every colour-analysis step evaluates it for
millions of (θ, d) pairs, so it is tabulated once, for the range a scene needs, and
interpolated (bilinear in XYZ, which is linear in R, then converted to Lab).

Model only what the scene needs:

* the **spectral step** is the coarsest of 20, 10, 5, 2, 1 nm whose colours stay within
  ``max_spectral_error_de00`` (default 0.05 ΔE00) of a 1 nm evaluation at random (θ, d)
  points of the requested range — thicker films oscillate faster in λ and need finer
  steps;
* the **grid steps** in θ and d are halved from a coarse start until the interpolated
  colours at random off-grid points stay within ``max_interp_error_de00`` (default 0.05)
  of a direct spectral evaluation at the same spectral step.

Both measured errors are stored on the table (``spectral_error_de00``,
``interp_error_de00``), so users can see what they get.

References
----------
.. [1] N. Nagata, M. Kamei, K. Takahashi, K. Tobitani, T. Akagi, S. Yamamura, "Simulation
   Technology for Titanium Oxide Layer Interference Color", Technical Report (the seed paper),
   §2.4 (spectral reflectance to colour) and §3.3.3 (the Lab comparison that the colour analysis
   makes with this table).
.. [2] CIE 015:2018, *Colorimetry*, 4th ed., CIE, Vienna (2018), doi:10.25039/TR.015.2018.
.. [3] G. Sharma, W. Wu, E. N. Dalal, "The CIEDE2000 color-difference formula: implementation
   notes, supplementary test data, and mathematical observations", Color Res. Appl. 30 (2005)
   21-30, doi:10.1002/col.20070.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field

import numpy as np

from ..core.defaults import DEFAULT_ILLUMINANT, DEFAULT_OBSERVER
from ..optics.constants import DEFAULT_FILM, DEFAULT_SUBSTRATE, resolve_index
from ..optics.thinfilm import reflectance
from .colorimetry import spectral_weights, xyz_to_lab
from .difference import delta_e_2000
from .srgb import model_xyz_to_linear_srgb

__all__ = ["ColourTable", "build_colour_table", "choose_spectral_step", "direct_xyz"]

log = logging.getLogger(__name__)

#: Candidate spectral steps, coarsest first; 1 nm is the reference.
SPECTRAL_STEPS_NM = (20.0, 10.0, 5.0, 2.0, 1.0)
#: Visible range integrated (CIE 15 permits 380-780 nm; the CMFs outside it add < 1e-4 to Y).
WAVELENGTH_RANGE_NM = (380.0, 780.0)


def _wavelengths(step_nm):
    lo, hi = WAVELENGTH_RANGE_NM
    n = int(round((hi - lo) / step_nm)) + 1
    return np.linspace(lo, hi, n)


def direct_xyz(theta_deg, thickness_nm, *, spectral_step_nm=1.0, film=DEFAULT_FILM,
               substrate=DEFAULT_SUBSTRATE, illuminant=DEFAULT_ILLUMINANT,
               observer=DEFAULT_OBSERVER, n_ambient=1.0):
    """XYZ (perfect reflector Y = 1) by direct spectral integration, no table.

    Parameters
    ----------
    theta_deg, thickness_nm : array_like
        Incidence angle (degrees) and film thickness (nm); they broadcast.
    spectral_step_nm : float
        Wavelength step over 380-780 nm.

    Returns
    -------
    ndarray, shape broadcast(theta_deg, thickness_nm) + (3,)

    Examples
    --------
    >>> xyz = direct_xyz(0.0, 0.0, spectral_step_nm=5.0)   # bare titanium
    >>> bool(0.5 < xyz[1] < 0.7)
    True
    """
    wl = _wavelengths(spectral_step_nm)
    n1, n2 = resolve_index(film, wl), resolve_index(substrate, wl)
    w = spectral_weights(wl, illuminant=illuminant, observer=observer)
    th = np.asarray(theta_deg, dtype=np.float64)[..., None]
    d = np.asarray(thickness_nm, dtype=np.float64)[..., None]
    R = reflectance(wl, th, d, n1, n2, n_ambient=n_ambient)
    return R @ w


def _white(wl, illuminant, observer):
    return spectral_weights(wl, illuminant=illuminant, observer=observer).sum(axis=0)


def _random_points(rng, theta_range, thickness_range, count):
    th = rng.uniform(*theta_range, count)
    d = rng.uniform(*thickness_range, count)
    return th, d


def choose_spectral_step(*, thickness_range_nm, theta_range_deg=(0.0, 45.0), film=DEFAULT_FILM,
                         substrate=DEFAULT_SUBSTRATE, illuminant=DEFAULT_ILLUMINANT,
                         observer=DEFAULT_OBSERVER, n_ambient=1.0, max_error_de00=0.05,
                         samples=400, seed=0):
    """Coarsest spectral step whose colours stay within ``max_error_de00`` of 1 nm.

    It picks 10 / 5 / 2 nm for films of 0-200 / 0-400 / 0-800 nm, each the cheapest step on
    the measured speed-error front (docs/speed-vs-error.md §1).

    Parameters
    ----------
    thickness_range_nm, theta_range_deg : (float, float)
        The scene's range of film thickness (nm) and incidence angle (degrees).
    max_error_de00 : float
        Largest CIEDE2000 difference allowed at ``samples`` random points of the range.

    Returns
    -------
    step_nm : float
        One of :data:`SPECTRAL_STEPS_NM`.
    error_de00 : float
        The measured maximum ΔE00 of that step against the 1 nm reference.
    errors : dict
        ``{step_nm: max ΔE00}`` for every step tried.
    """
    rng = np.random.default_rng(seed)
    th, d = _random_points(rng, theta_range_deg, thickness_range_nm, samples)
    kw = dict(film=film, substrate=substrate, illuminant=illuminant, observer=observer,
              n_ambient=n_ambient)
    ref_wl = _wavelengths(1.0)
    ref = xyz_to_lab(direct_xyz(th, d, spectral_step_nm=1.0, **kw),
                           white=_white(ref_wl, illuminant, observer))
    errors = {1.0: 0.0}
    for step in SPECTRAL_STEPS_NM[:-1]:
        wl = _wavelengths(step)
        lab = xyz_to_lab(direct_xyz(th, d, spectral_step_nm=step, **kw),
                               white=_white(wl, illuminant, observer))
        err = float(np.max(delta_e_2000(lab, ref)))
        errors[step] = err
        if err <= max_error_de00:
            return step, err, errors
    return 1.0, 0.0, errors


#: Points per chunk of :meth:`ColourTable.xyz_at` (its temporaries: ~200 bytes per point).
_XYZ_CHUNK = 1 << 16


def _unrepeated(a):
    """The smallest array that broadcasts to ``a``: each axis along which ``a`` repeats
    itself (a broadcast view's zero stride) cut to length 1.

    >>> a = np.broadcast_to(np.arange(3.0)[:, None], (3, 4))
    >>> _unrepeated(a).shape, _unrepeated(np.ones((2, 5))).shape
    ((3, 1), (2, 5))
    """
    return a[tuple(slice(0, 1) if st == 0 and n > 1 else slice(None)
                   for st, n in zip(a.strides, a.shape))]


@dataclass
class ColourTable:
    """Tabulated colour of the film over incidence angle and thickness.

    Attributes
    ----------
    theta_deg : ndarray, shape (T,)
        Incidence-angle grid in degrees (facet tilt under coaxial light, θ_d in the
        half-vector model), uniform.
    thickness_nm : ndarray, shape (D,)
        Thickness grid in nm, uniform.
    xyz : ndarray, shape (T, D, 3), float64
        CIE XYZ, perfect reflector Y = 1.
    lab : ndarray, shape (T, D, 3), float32
        CIELAB relative to the illuminant's white.
    white_xyz : ndarray, shape (3,)
        The white the Lab values are relative to (the perfect reflector on this grid).
    spectral_step_nm : float
    spectral_error_de00 : float
        Max ΔE00 of the spectral step against 1 nm at random points (0 for 1 nm).
    interp_error_de00 : float
        Max ΔE00 of table interpolation against direct evaluation at random points.
    film, substrate, illuminant, observer : str
    """

    theta_deg: np.ndarray
    thickness_nm: np.ndarray
    xyz: np.ndarray
    lab: np.ndarray
    white_xyz: np.ndarray
    spectral_step_nm: float
    spectral_error_de00: float
    interp_error_de00: float
    film: str
    substrate: str
    illuminant: str
    observer: str
    n_ambient: float = 1.0
    info: dict = field(default_factory=dict)
    _coef: np.ndarray | None = field(default=None, init=False, repr=False, compare=False)

    @property
    def theta_step_deg(self) -> float:
        return float(self.theta_deg[1] - self.theta_deg[0]) if self.theta_deg.size > 1 else 0.0

    @property
    def thickness_step_nm(self) -> float:
        return (float(self.thickness_nm[1] - self.thickness_nm[0])
                if self.thickness_nm.size > 1 else 0.0)

    def _coords(self, values, grid):
        v = np.asarray(values, dtype=np.float64)
        if grid.size == 1:
            inside = np.abs(v - grid[0]) <= 1e-9
            return np.zeros(v.shape, np.intp), np.zeros(v.shape), inside
        step = grid[1] - grid[0]
        u = (v - grid[0]) / step
        # inside within float32 rounding of the edges: a float32 map clipped to the table's
        # range rounds its edge outward (27.065051 deg is 27.065052 in float32)
        tol = 2.0 * float(np.spacing(np.float32(max(abs(grid[0]), abs(grid[-1]))))) / step
        inside = (u >= -tol) & (u <= grid.size - 1 + tol)
        u = np.clip(np.where(inside, u, 0.0), 0, grid.size - 1)
        i0 = np.minimum(np.floor(u).astype(np.intp), grid.size - 2)
        return i0, u - i0, inside

    def xyz_at(self, theta_deg, thickness_nm):
        """Bilinearly interpolated XYZ; NaN outside the table (and where inputs are NaN).

        Parameters
        ----------
        theta_deg, thickness_nm : array_like
            They broadcast against each other.

        Returns
        -------
        ndarray, shape broadcast + (3,), float64
        """
        th, d = np.broadcast_arrays(np.asarray(theta_deg, np.float64),
                                    np.asarray(thickness_nm, np.float64))
        th_c, d_c = _unrepeated(th), _unrepeated(d)
        if (th.ndim == 2 and th_c.shape[1] == 1 and d_c.shape[0] == 1
                and th.shape[0] >= self.theta_deg.size > 1 and self.thickness_nm.size > 1):
            return self._xyz_outer(th_c, d_c)
        if th.size <= _XYZ_CHUNK:
            return self._xyz_at(th, d)
        # in chunks: the temporaries (~200 bytes per point) stay bounded; blocks of leading
        # rows where a row fits (each keeps the inputs' repeated axes, computed once)
        out = np.empty(th.shape + (3,))
        row = th.size // th.shape[0]
        if row <= _XYZ_CHUNK:
            k = _XYZ_CHUNK // row
            for a in range(0, th.shape[0], k):
                out[a:a + k] = self._xyz_at(th[a:a + k], d[a:a + k])
            return out
        th_f, d_f, o_f = th.reshape(-1), d.reshape(-1), out.reshape(-1, 3)
        for a in range(0, th.size, _XYZ_CHUNK):
            o_f[a:a + _XYZ_CHUNK] = self._xyz_at(th_f[a:a + _XYZ_CHUNK], d_f[a:a + _XYZ_CHUNK])
        return out

    def _xyz_outer(self, th_col, d_row):
        """:meth:`xyz_at` of a tilt per row (n, 1) and a thickness per column (1, D), to the
        bit: the bilinear terms that depend on the thickness alone (``a + b·fj`` and
        ``c + e·fj`` of each cell) are computed once per table row and column, not once
        per point, then gathered by each point's table row: the same operations in the same
        order, for the table's tens of rows instead of the ROI samples' thousands."""
        with np.errstate(invalid="ignore"):
            i, fi, ok_i = self._coords(th_col, self.theta_deg)
            j, fj, ok_j = self._coords(d_row, self.thickness_nm)
        t = self.xyz
        cell = self._bilinear_coefficients()[
            np.arange(t.shape[0] - 1)[:, None] * (t.shape[1] - 1) + j]   # (T-1, D, 4, 3)
        fj_ = fj[..., None]
        p = cell[..., 0, :] + cell[..., 1, :] * fj_
        q = cell[..., 2, :] + cell[..., 3, :] * fj_
        cell = None
        n, D = th_col.shape[0], d_row.shape[1]
        out = np.empty((n, D, 3))
        k = max(1, _XYZ_CHUNK // D)
        for a in range(0, n, k):
            ii = i[a:a + k, 0]
            o = p[ii] + q[ii] * fi[a:a + k, :, None]
            bad = ~(ok_i[a:a + k] & ok_j)
            out[a:a + k] = np.where(bad[..., None], np.nan, o) if np.any(bad) else o
        return out

    def _xyz_at(self, th, d):
        # the table coordinates of each distinct input value: of the inputs' own arrays,
        # not of their broadcast (a tilt per row and a thickness per column: rows + columns
        # of them, not rows × columns), then broadcast like the inputs
        with np.errstate(invalid="ignore"):
            i, fi, ok_i = self._coords(_unrepeated(th), self.theta_deg)
            j, fj, ok_j = self._coords(_unrepeated(d), self.thickness_nm)
        t = self.xyz
        if self.theta_deg.size == 1 or self.thickness_nm.size == 1:
            if self.theta_deg.size == 1:
                row0 = t[0]
                out = (row0[j] * (1 - fj)[..., None] + row0[np.minimum(j + 1, row0.shape[0] - 1)]
                       * fj[..., None]) if self.thickness_nm.size > 1 else row0[j]
            else:
                col = t[:, 0]
                out = col[i] * (1 - fi)[..., None] + col[i + 1] * fi[..., None]
        else:
            # one gather of the cell's bilinear coefficients (a + b·fj + c·fi + e·fi·fj)
            # instead of four corner gathers: ~3× faster on the large scans of the analysis
            coef = self._bilinear_coefficients()
            cell = coef[i * (t.shape[1] - 1) + j]                   # (..., 4, 3)
            fi_, fj_ = fi[..., None], fj[..., None]
            out = (cell[..., 0, :] + cell[..., 1, :] * fj_
                   + (cell[..., 2, :] + cell[..., 3, :] * fj_) * fi_)
        bad = ~(ok_i & ok_j)
        if np.any(bad):
            out = np.where(bad[..., None], np.nan, out)
        if out.shape[:-1] != th.shape:      # both inputs repeat along an axis
            out = np.broadcast_to(out, th.shape + (3,)).copy()
        return out

    def _bilinear_coefficients(self):
        """Per cell (T−1)·(D−1) × 4 × 3: corner a, ∂/∂fj, ∂/∂fi and the cross term."""
        coef = self._coef
        if coef is None or coef.shape[0] != (self.xyz.shape[0] - 1) * (self.xyz.shape[1] - 1):
            t = self.xyz
            a, b = t[:-1, :-1], t[:-1, 1:]
            c, e = t[1:, :-1], t[1:, 1:]
            coef = np.stack([a, b - a, c - a, e - c - b + a], axis=2).reshape(-1, 4, 3)
            self._coef = coef
        return coef

    def lab_at(self, theta_deg, thickness_nm):
        """Interpolated CIELAB (float32), NaN outside the table; see :meth:`xyz_at`."""
        return xyz_to_lab(self.xyz_at(theta_deg, thickness_nm),
                                white=self.white_xyz).astype(np.float32)

    def linear_rgb_at(self, theta_deg, thickness_nm):
        """Interpolated linear sRGB (float32, not clipped), white-balanced to the illuminant."""
        return model_xyz_to_linear_srgb(
            self.xyz_at(theta_deg, thickness_nm), white=self.white_xyz,
            illuminant=self.illuminant, observer=self.observer)


def build_colour_table(*, thickness_range_nm, theta_range_deg=(0.0, 45.0), film=DEFAULT_FILM,
                       substrate=DEFAULT_SUBSTRATE, illuminant=DEFAULT_ILLUMINANT,
                       observer=DEFAULT_OBSERVER, n_ambient=1.0, spectral_step_nm=None,
                       thickness_step_nm=None, theta_step_deg=None,
                       max_spectral_error_de00=0.05, max_interp_error_de00=0.05,
                       check_samples=2000, seed=0) -> ColourTable:
    """Tabulate the film colour over the (θ, d) range a scene needs.

    The automatic spectral step and grid are the cheapest within 0.1 ΔE00 of direct 1 nm
    evaluation in every measured range (docs/speed-vs-error.md §1-2).

    Parameters
    ----------
    thickness_range_nm : (float, float)
        Film thickness range in nm, ``0 <= lo < hi``.
    theta_range_deg : (float, float)
        Incidence-angle range in degrees, ``0 <= lo < hi < 90``. Under coaxial microscope
        light, facets steeper than asin(NA)/2 are dark, so the microscope needs only
        ``(0, asin(NA)/2)``.
    film, substrate : str
        Optical-constant set names (:func:`microfacet.optics.known_sets`).
    illuminant, observer : str
        Illuminant name (colour-science) and ``"2"`` or ``"10"`` degree observer.
    spectral_step_nm : float, optional
        Fix the spectral step; by default :func:`choose_spectral_step` picks it.
    thickness_step_nm, theta_step_deg : float, optional
        Fix the grid; by default steps are halved from 2 nm and 4° until the measured
        interpolation error is ≤ ``max_interp_error_de00``.
    check_samples : int
        Random off-grid points used to measure the interpolation error.

    Returns
    -------
    ColourTable

    Examples
    --------
    >>> t = build_colour_table(thickness_range_nm=(40, 60), theta_range_deg=(0, 20))
    >>> t.interp_error_de00 <= 0.05
    True
    >>> t.lab_at(0.0, 51.0).shape
    (3,)
    """
    lo_d, hi_d = _check_range(thickness_range_nm, "thickness_range_nm", 0.0, np.inf)
    lo_t, hi_t = _check_range(theta_range_deg, "theta_range_deg", 0.0, 90.0)
    if hi_t >= 90.0:
        raise ValueError("theta_range_deg: the upper limit must be < 90 degrees")
    kw = dict(film=film, substrate=substrate, illuminant=illuminant, observer=observer,
              n_ambient=n_ambient)
    for value in (film, substrate):  # validates names and wavelength coverage now
        resolve_index(value, _wavelengths(1.0))

    if spectral_step_nm is None:
        spectral_step_nm, spectral_err, tried = choose_spectral_step(
            thickness_range_nm=(lo_d, hi_d), theta_range_deg=(lo_t, hi_t),
            max_error_de00=max_spectral_error_de00, seed=seed, **kw)
        log.info("spectral step %.0f nm (max dE00 %.3f vs 1 nm; tried %s)",
                 spectral_step_nm, spectral_err, tried)
    else:
        spectral_step_nm = float(spectral_step_nm)
        if not spectral_step_nm > 0:
            raise ValueError("spectral_step_nm: must be > 0")
        spectral_err = float("nan")
    wl = _wavelengths(spectral_step_nm)
    white = _white(wl, illuminant, observer)

    rng = np.random.default_rng(seed + 1)
    th_chk, d_chk = _random_points(rng, (lo_t, hi_t), (lo_d, hi_d), check_samples)
    ref_lab = xyz_to_lab(direct_xyz(th_chk, d_chk, spectral_step_nm=spectral_step_nm,
                                          **kw), white=white)

    d_step = 2.0 if thickness_step_nm is None else float(thickness_step_nm)
    t_step = 4.0 if theta_step_deg is None else float(theta_step_deg)
    adaptive = thickness_step_nm is None or theta_step_deg is None
    for _ in range(8):
        th_grid = _grid(lo_t, hi_t, t_step)
        d_grid = _grid(lo_d, hi_d, d_step)
        xyz = direct_xyz(th_grid[:, None], d_grid[None, :], spectral_step_nm=spectral_step_nm,
                         **kw)
        table = ColourTable(
            theta_deg=th_grid, thickness_nm=d_grid, xyz=xyz,
            lab=xyz_to_lab(xyz, white=white).astype(np.float32), white_xyz=white,
            spectral_step_nm=spectral_step_nm, spectral_error_de00=spectral_err,
            interp_error_de00=float("nan"), film=str(film), substrate=str(substrate),
            illuminant=illuminant, observer=observer, n_ambient=n_ambient)
        err = delta_e_2000(table.lab_at(th_chk, d_chk).astype(np.float64), ref_lab)
        table.interp_error_de00 = float(np.max(err))
        if not adaptive or table.interp_error_de00 <= max_interp_error_de00:
            break
        # Halve the step of the axis that contributes more error.
        err_d = _axis_error(table, th_chk, d_chk, ref_lab, "thickness", kw, spectral_step_nm,
                            white)
        if thickness_step_nm is None and (theta_step_deg is not None or
                                          err_d >= 0.5 * table.interp_error_de00):
            d_step /= 2
        if theta_step_deg is None and (thickness_step_nm is not None or
                                       err_d < 0.5 * table.interp_error_de00):
            t_step /= 2
    table.info.update(theta_step_deg=table.theta_step_deg,
                      thickness_step_nm=table.thickness_step_nm, check_samples=check_samples)
    log.info("colour table %d x %d (theta step %.3g deg, d step %.3g nm), max interp dE00 %.3f",
             th_grid.size, d_grid.size, table.theta_step_deg, table.thickness_step_nm,
             table.interp_error_de00)
    return table


def _axis_error(table, th, d, ref_lab, axis, kw, step, white):
    """Interpolation error with exact values along the other axis (to pick which to refine)."""
    # Evaluate exactly at the grid theta nearest each check point: the remaining error is
    # the thickness-axis interpolation error (plus a small theta offset, same for both).
    g = table.theta_deg
    th_near = g[np.clip(np.rint((th - g[0]) / max(table.theta_step_deg, 1e-12)), 0,
                        g.size - 1).astype(int)]
    ref = xyz_to_lab(direct_xyz(th_near, d, spectral_step_nm=step, **kw), white=white)
    got = table.lab_at(th_near, d).astype(np.float64)
    return float(np.max(delta_e_2000(got, ref)))


def _grid(lo, hi, step):
    n = max(2, int(np.ceil((hi - lo) / step - 1e-9)) + 1)
    return np.linspace(lo, hi, n)


def _check_range(r, name, lo_ok, hi_ok):
    try:
        lo, hi = (float(v) for v in r)
    except (TypeError, ValueError):
        raise ValueError(f"{name}: expected (low, high), got {r!r}") from None
    if not (np.isfinite(lo) and np.isfinite(hi) and lo_ok <= lo < hi <= hi_ok):
        raise ValueError(f"{name}: need {lo_ok:g} <= low < high, got ({lo:g}, {hi:g})")
    return lo, hi
