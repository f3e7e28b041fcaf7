"""Reflectance of ambient / one film / semi-infinite substrate (Airy's formula).

Seed eqs. (2)-(4): for incidence angle θ₀ in the ambient (index n₀, lossless), the film
(index n₁ = n + ik, thickness d) and the substrate (n₂), with complex Snell's law
``n_j cos θ_j = sqrt(n_j² − n₀² sin² θ₀)``,

    r = (r₀₁ + r₁₂ e^{2iβ}) / (1 + r₀₁ r₁₂ e^{2iβ}),   β = 2π d n₁ cos θ₁ / λ,

with the Fresnel coefficients of each interface for s and p polarisation. All multiple
reflections inside the film are included. R = |r|², unpolarised R = (R_s + R_p) / 2.

Numerical care
--------------
* The square root for ``n_j cos θ_j`` is taken on the branch with Im ≥ 0 (a wave that
  decays into an absorbing medium; for a lossless medium beyond the critical angle, the
  evanescent branch), and Re ≥ 0 where Im = 0. This holds for any k ≥ 0 and any θ₀ < 90°,
  which is where a real-part-only Snell's law (as in colour-science 0.4.7's
  ``thin_film_tmm``) goes wrong for metals at oblique incidence.
* ``|r|²`` is evaluated as ``(|a|² + |b|²|z|² + 2 Re(a̅ b z)) / (1 + |c|²|z|² + 2 Re(c z))``
  with ``z = e^{2iβ}``: the Fresnel products depend only on (λ, θ, indices) and are
  computed once, so the work that scales with the number of thicknesses is real arithmetic
  on ``z``. ``|z| = e^{−2 Im β}`` underflows to 0 for thick absorbing films (the
  substrate is then hidden), which is the right limit, not a NaN.
* NaN in any input gives NaN in the output at that position (masked pixels propagate).

References
----------
.. [1] N. Nagata, M. Kamei, K. Takahashi, K. Tobitani, T. Akagi, S. Yamamura, "Simulation
   Technology for Titanium Oxide Layer Interference Color", Technical Report (the seed paper),
   §2.4, eqs. (2)-(4).
.. [2] M. Born, E. Wolf, *Principles of Optics*, 7th ed., Cambridge University Press (1999),
   doi:10.1017/CBO9781139644181, §1.6 and §14.4.
.. [3] S. J. Byrnes, "Multilayer optical calculations", arXiv:1603.02720 (2016) (the conventions
   of ``tmm``, which the tests use as the independent reference).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..core.threads import thread_map
from .constants import optical_constants

__all__ = ["fresnel_reflectance", "reflectance", "reflectance_period_nm"]

_POLARIZATIONS = ("s", "p", "unpolarized")


def normal_wavevector(n, n0_sin_theta):
    """``n cos θ`` in a medium of index ``n`` for the in-plane invariant ``n₀ sin θ₀``.

    Parameters
    ----------
    n : array_like of complex
        Refractive index ``n + ik`` (k ≥ 0).
    n0_sin_theta : array_like of float
        Snell invariant ``n₀ sin θ₀`` of the incident wave; broadcasts against ``n``.

    Returns
    -------
    ndarray of complex128
        ``sqrt(n² − (n₀ sin θ₀)²)`` on the branch with Im ≥ 0, and Re ≥ 0 where Im = 0
        (forward-decaying or forward-propagating wave).

    Examples
    --------
    >>> complex(normal_wavevector(2.0, 0.0))
    (2+0j)
    """
    n = np.asarray(n, dtype=np.complex128)
    # (n - b)(n + b) rather than n² - b²: no cancellation near the critical angle.
    q = np.sqrt((n - n0_sin_theta) * (n + n0_sin_theta))
    # The principal root has Re >= 0; with n = n' + ik (n' > 0, k >= 0) the radicand has
    # Im >= 0, so Im(q) >= 0 except for a radicand on the negative real axis carrying a
    # signed -0.0 imaginary part. Flip those onto the decaying branch.
    flip = (q.imag < 0) | ((q.imag == 0) & (q.real < 0))
    if np.any(flip):
        q = np.where(flip, -q, q)
    return q


def _interface(qi, qj, ni2, nj2, polarization):
    """Fresnel amplitude reflection coefficient from medium i into medium j."""
    if polarization == "s":
        return (qi - qj) / (qi + qj)
    # p polarisation (tmm convention): (n_j² q_i − n_i² q_j) / (n_j² q_i + n_i² q_j)
    a = nj2 * qi
    b = ni2 * qj
    return (a - b) / (a + b)


def fresnel_reflectance(theta_deg, n1, n2, *, polarization="unpolarized"):
    """Reflectance of a single interface from medium ``n1`` (lossless) into ``n2``.

    Parameters
    ----------
    theta_deg : array_like
        Angle of incidence in medium ``n1``, degrees, 0 ≤ θ < 90.
    n1 : array_like of float
        Index of the incident medium (real, > 0).
    n2 : array_like of complex
        Index of the second medium, ``n + ik`` with k ≥ 0.
    polarization : {"s", "p", "unpolarized"}

    Returns
    -------
    ndarray of float64
        Broadcast shape of the inputs.

    Examples
    --------
    >>> round(float(fresnel_reflectance(0.0, 1.0, 1.5)), 4)
    0.04
    """
    _check_polarization(polarization)
    theta = _check_theta(theta_deg)
    n1 = np.asarray(n1, dtype=np.complex128)
    _check_index(n2, "n2")
    n2 = np.asarray(n2, dtype=np.complex128)
    rad = np.deg2rad(theta)
    beta = n1.real * np.sin(rad)
    q1 = (n1.real * np.cos(rad)).astype(np.complex128)
    q2 = normal_wavevector(n2, beta)
    out = []
    for pol in ("s", "p") if polarization == "unpolarized" else (polarization,):
        r = _interface(q1, q2, n1 * n1, n2 * n2, pol)
        out.append(np.abs(r) ** 2)
    return out[0] if len(out) == 1 else 0.5 * (out[0] + out[1])


@dataclass(frozen=True)
class FresnelProducts:
    """Thickness-independent factors of Airy's formula for one polarisation.

    ``R(d) = (a2 + b2 |z|² + 2 Re(ab z)) / (1 + c2 |z|² + 2 Re(c z))`` with
    ``z = exp(4πi d q₁ / λ)``, ``a = r₀₁``, ``b = r₁₂``, ``c = r₀₁ r₁₂``,
    ``a2 = |a|²``, ``b2 = |b|²``, ``ab = conj(a) b``, ``c2 = |c|²``.
    """

    a2: np.ndarray
    b2: np.ndarray
    ab: np.ndarray
    c: np.ndarray
    c2: np.ndarray

    @classmethod
    def from_coefficients(cls, r01, r12):
        c = r01 * r12
        return cls(
            a2=np.abs(r01) ** 2,
            b2=np.abs(r12) ** 2,
            ab=np.conj(r01) * r12,
            c=c,
            c2=np.abs(c) ** 2,
        )


def reflectance(
    wavelength_nm,
    theta_deg,
    thickness_nm,
    n_film,
    n_substrate,
    *,
    n_ambient=1.0,
    polarization="unpolarized",
    dtype=np.float64,
):
    """Coherent reflectance of ambient / film / substrate (Airy's formula, seed eqs. 2-4).

    Parameters
    ----------
    wavelength_nm : array_like
        Vacuum wavelength in nm, > 0.
    theta_deg : array_like
        Angle of incidence in the ambient, degrees, 0 ≤ θ < 90. In the half-vector
        model this is θ_d, half the angle between light and view (seed eq. 5).
    thickness_nm : array_like
        Film thickness in nm, ≥ 0 (0 gives the bare ambient / substrate interface).
    n_film, n_substrate : array_like of complex, or str
        Refractive index ``n + ik`` (Re > 0, k ≥ 0), broadcasting against the other
        arguments (typically shaped like ``wavelength_nm``), or the name of a bundled
        optical-constant set (:func:`microfacet.optics.known_sets`), interpolated at
        ``wavelength_nm``.
    n_ambient : float, optional
        Index of the (lossless) ambient medium; 1.0 (air) by default.
    polarization : {"unpolarized", "s", "p"}
        ``"unpolarized"`` is the mean of s and p.
    dtype : {numpy.float64, numpy.float32}
        Result dtype. The computation is always done in float64.

    Returns
    -------
    ndarray
        Reflectance in [0, 1], with the broadcast shape of all array arguments.

    Raises
    ------
    ValueError
        Naming the argument, for a finite value out of range (θ ≥ 90°, negative thickness,
        k < 0, ...), an infinite value, or an unknown polarization. NaN is not an error:
        it propagates to the result.

    Examples
    --------
    A 51 nm anodic film on titanium, at normal incidence, across the visible:

    >>> import numpy as np
    >>> from microfacet.optics.thinfilm import reflectance
    >>> wl = np.array([450.0, 550.0, 650.0])
    >>> R = reflectance(wl, 0.0, 51.0, "TiO2_Jolivet2023_amorphous", "Ti_JohnsonChristy1974")
    >>> bool(R[0] > R[2])   # blue
    True
    """
    _check_polarization(polarization)
    if np.dtype(dtype) not in (np.dtype(np.float64), np.dtype(np.float32)):
        raise ValueError(f"dtype: must be float64 or float32, got {np.dtype(dtype)}")
    wl = _check_nonneg(wavelength_nm, "wavelength_nm", strictly_positive=True)
    theta = _check_theta(theta_deg)
    d = _check_nonneg(thickness_nm, "thickness_nm")
    n0 = np.asarray(n_ambient, dtype=np.complex128)
    if np.any(n0.imag != 0) or np.any(~(n0.real > 0) & ~np.isnan(n0.real)):
        raise ValueError("n_ambient: must be real and > 0 (a lossless ambient medium)")
    n1 = _resolve(n_film, wl, "n_film")
    n2 = _resolve(n_substrate, wl, "n_substrate")

    with np.errstate(invalid="ignore"):  # NaN inputs (masked pixels) propagate quietly
        return _airy(wl, theta, d, n0, n1, n2, polarization, dtype)


def _airy(wl, theta, d, n0, n1, n2, polarization, dtype):
    rad = np.deg2rad(theta)
    beta = n0.real * np.sin(rad)  # Snell invariant n0 sin(theta0)
    q0 = (n0.real * np.cos(rad)).astype(np.complex128)  # exact for the lossless ambient
    q1 = normal_wavevector(n1, beta)
    q2 = normal_wavevector(n2, beta)
    # z = exp(2i * 2*pi*d*q1/lambda) is the only factor that depends on d.
    k1 = (4.0 * np.pi) * q1 / wl
    absorbing = bool(np.any(k1.imag != 0))

    n02, n12, n22 = n0 * n0, n1 * n1, n2 * n2
    pols = ("s", "p") if polarization == "unpolarized" else (polarization,)
    terms = []  # per polarisation: thickness-independent factors, (λ, θ)-shaped
    for pol in pols:
        f = FresnelProducts.from_coefficients(
            _interface(q0, q1, n02, n12, pol), _interface(q1, q2, n12, n22, pol)
        )
        if absorbing:
            terms.append((f.a2, f.b2, 2 * f.ab.real, -2 * f.ab.imag,
                          1.0 + 0 * f.c2, f.c2, 2 * f.c.real, -2 * f.c.imag))
        else:  # |z| = 1: fold |z|² into the constants
            terms.append((f.a2 + f.b2, None, 2 * f.ab.real, -2 * f.ab.imag,
                          1.0 + f.c2, None, 2 * f.c.real, -2 * f.c.imag))
    scale = 0.5 if len(pols) == 2 else 1.0

    operands = [k1.real, k1.imag, d] + [t for group in terms for t in group if t is not None]
    shape = np.broadcast_shapes(*(np.shape(o) for o in operands))
    out = np.empty(shape, dtype=dtype)
    views = [np.broadcast_to(o, shape) for o in operands]

    def block(blk):
        kr, ki, dd, *rest = (v[blk] for v in views)
        psi = kr * dd
        zr, zi = _sincos(psi)
        if absorbing:
            mag = np.exp(-(ki * dd))
            zr *= mag
            zi *= mag
            zz = mag * mag
        acc = None
        it = iter(rest)
        for _ in pols:
            if absorbing:
                a, b, pr, pi, one, c2, cr, ci = (next(it) for _ in range(8))
                num = a + b * zz + pr * zr + pi * zi
                den = one + c2 * zz + cr * zr + ci * zi
            else:
                a, pr, pi, one, cr, ci = (next(it) for _ in range(6))
                num = a + pr * zr + pi * zi
                den = one + cr * zr + ci * zi
            r = num / den
            acc = r if acc is None else acc + r
        if scale != 1.0:
            acc *= scale
        out[blk] = acc

    _run_blocks(block, shape)
    return out[()]


def _run_blocks(fn, shape):
    """Call ``fn(block_index)`` over the blocks of ``shape``, in threads when it pays (4
    blocks or more: :func:`microfacet.core.threads.thread_map`)."""
    blocks = list(_blocks(shape))
    if len(blocks) < 4:
        for blk in blocks:
            fn(blk)
        return
    thread_map(fn, blocks)


_BLOCK_ELEMENTS = 1 << 15


def _blocks(shape, target=_BLOCK_ELEMENTS):
    """Index tuples that tile ``shape`` in blocks of about ``target`` elements (C order)."""
    if not shape:
        yield ()
        return
    trailing = 1
    a = len(shape)
    while a > 0 and trailing * shape[a - 1] <= target:
        trailing *= shape[a - 1]
        a -= 1
    if a == 0:
        yield (slice(None),)
        return
    step = max(1, target // trailing)
    for lead in np.ndindex(*shape[: a - 1]):
        for i in range(0, shape[a - 1], step):
            yield lead + (slice(i, i + step),)


# sin and cos of float64 arguments, exact to a few ulp of the argument, ~3x faster than
# numpy's scalar libm calls: reduce psi = m * (2*pi/K) + r with |r| <= pi/K (Cody-Waite
# with 2*pi as a double-double), take cos and sin of m * 2*pi/K from a table and of r from
# a short Taylor series (|r| < 7.7e-4, truncation error < 1e-21).
_K = 4096
_TWO_PI_HI = 6.283185307179586
_TWO_PI_LO = 2.4492935982947064e-16
_STEP = _TWO_PI_HI / _K
_C1 = float(np.round(_STEP * 2.0**24) / 2.0**24)  # few mantissa bits: m * _C1 is exact
_C2 = (_STEP - _C1) + _TWO_PI_LO / _K
_TABLE_ANGLES = (np.arange(_K) / _K) * (2.0 * np.pi)
_TC = np.cos(_TABLE_ANGLES)
_TS = np.sin(_TABLE_ANGLES)


def _sincos(psi):
    """``(cos(psi), sin(psi))`` for float64 ``psi`` with |psi| < 2e5 (NaN propagates)."""
    m = np.rint(psi * (_K / (2.0 * np.pi)))
    r = psi - m * _C1
    r -= m * _C2
    idx = m.astype(np.int64) & (_K - 1)  # NaN casts to some index; r is NaN there anyway
    r2 = r * r
    cr = 1.0 - r2 * (0.5 - r2 * (1.0 / 24.0))
    sr = r * (1.0 - r2 * ((1.0 / 6.0) - r2 * (1.0 / 120.0)))
    ch = _TC[idx]
    sh = _TS[idx]
    return ch * cr - sh * sr, sh * cr + ch * sr


def reflectance_period_nm(wavelength_nm, theta_deg, n_film, *, n_ambient=1.0):
    """Thickness period ``λ / (2 Re(n₁ cos θ₁))`` of the reflectance of a lossless film.

    Parameters
    ----------
    wavelength_nm, theta_deg : array_like
        Vacuum wavelength (nm) and angle of incidence in the ambient (degrees).
    n_film : array_like of float
        Real film index.

    Returns
    -------
    ndarray
        Period in nm: ``R(d + period) = R(d)`` for a film with k = 0.
    """
    beta = float(n_ambient) * np.sin(np.deg2rad(np.asarray(theta_deg, dtype=np.float64)))
    q1 = normal_wavevector(n_film, beta)
    return np.asarray(wavelength_nm, dtype=np.float64) / (2.0 * q1.real)


# ---------------------------------------------------------------------------- checks


def _check_polarization(polarization):
    if polarization not in _POLARIZATIONS:
        raise ValueError(
            f"polarization: must be one of {', '.join(map(repr, _POLARIZATIONS))}, "
            f"got {polarization!r}"
        )


def _as_float(x, name):
    try:
        arr = np.asarray(x, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name}: not a real number or array ({exc})") from None
    return arr


def _check_theta(theta_deg):
    theta = _as_float(theta_deg, "theta_deg")
    if np.any(np.isinf(theta)) or np.any((theta < 0) | (theta >= 90)):
        raise ValueError("theta_deg: angles of incidence must satisfy 0 <= theta < 90 degrees")
    return theta


def _check_nonneg(x, name, *, strictly_positive=False):
    arr = _as_float(x, name)
    bad = (arr <= 0) if strictly_positive else (arr < 0)
    if np.any(np.isinf(arr)) or np.any(bad):
        what = "> 0" if strictly_positive else ">= 0"
        raise ValueError(f"{name}: values must be finite and {what}")
    return arr


def _check_index(n, name):
    arr = np.asarray(n)
    if arr.dtype.kind not in "iufc":
        raise ValueError(f"{name}: a refractive index must be numeric (n + ik), got {arr.dtype}")
    arr = arr.astype(np.complex128)
    if np.any(np.isinf(arr.real) | np.isinf(arr.imag)):
        raise ValueError(f"{name}: refractive index must be finite")
    if np.any(arr.imag < 0):
        raise ValueError(f"{name}: k (imaginary part) must be >= 0 (absorption)")
    if np.any(arr.real <= 0):
        raise ValueError(f"{name}: real part of the refractive index must be > 0")
    return arr


def _resolve(n, wavelength_nm, name):
    if isinstance(n, str):
        try:
            return optical_constants(n, wavelength_nm)
        except ValueError as exc:
            raise ValueError(f"{name}: {exc}") from None
    return _check_index(n, name)
