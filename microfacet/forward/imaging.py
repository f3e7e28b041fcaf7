"""The microscope's imaging effects on a synthetic scene: tilt-dependent brightness (how much
of the illumination a tilted facet sends back into the pupil), vignetting, white balance
and lateral drift between slices.

Each is a pure function of the parameters (:class:`~microfacet.forward.synth_params.SynthParams`)
on float32 arrays; :mod:`microfacet.forward.scene` and :mod:`microfacet.forward.synth` apply
them. Docs: docs/synthetic-stacks.md.
"""

from __future__ import annotations

import functools
import math

import numpy as np

from ..core.lazy import load

cv2 = load("cv2")

__all__ = ["pupil_fraction", "pupil_limit_deg", "vignetting_factor"]

#: Tilt grid of the tabulated pupil fraction (degrees).
_THETA_STEP_DEG = 0.1
#: Illumination directions sampled per pupil diameter.
_PUPIL_SAMPLES = 101


@functools.lru_cache(maxsize=16)
def _pupil_table(numerical_aperture: float, fill: float) -> np.ndarray:
    """Fraction of the illumination cone reflected back into the pupil on a tilt grid."""
    na, sig = numerical_aperture, fill * numerical_aperture
    g = np.linspace(-sig, sig, _PUPIL_SAMPLES)
    sx, sy = np.meshgrid(g, g)
    inside = sx * sx + sy * sy <= sig * sig
    sx, sy = sx[inside], sy[inside]
    cz = np.sqrt(1.0 - sx * sx - sy * sy)        # incoming ray u = (sx, sy, -cz), downward
    theta = np.deg2rad(np.arange(0.0, 90.0 + _THETA_STEP_DEG / 2, _THETA_STEP_DEG))
    out = np.zeros(theta.size)
    # Past (asin NA + asin σNA)/2 every reflected ray leaves the pupil.
    last = math.degrees(math.asin(na) + math.asin(sig)) / 2.0 + 2 * _THETA_STEP_DEG
    n = min(theta.size, int(last / _THETA_STEP_DEG) + 1)
    for lo in range(0, n, 128):                   # chunks keep memory small
        t = theta[lo:lo + 128, None]
        st, ct = np.sin(t), np.cos(t)             # facet normal n = (sin t, 0, cos t)
        un = sx * st - cz * ct                    # u . n
        rx = sx - 2.0 * un * st
        rz = -cz - 2.0 * un * ct                  # reflected r = u - 2 (u . n) n
        ok = (rz > 0) & (rx * rx + sy * sy <= na * na)
        out[lo:min(lo + 128, n)] = ok.mean(axis=1)[:min(128, n - lo)]
    return np.minimum.accumulate(out)            # monotone (sampling noise removed)


def pupil_fraction(tilt_deg, *, numerical_aperture: float, fill: float) -> np.ndarray:
    """Brightness of a mirror facet tilted by ``tilt_deg`` under coaxial Köhler light.

    The illumination fills a cone of sine radius ``fill`` × NA (uniform in the pupil); the
    facet reflects each ray about its normal, and the objective collects the rays whose
    direction lies within its NA. The collected fraction is 1 at zero tilt and falls
    smoothly to 0; with ``fill`` = 0 (axial light) it is the hard cut of the default model,
    1 up to asin(NA)/2 and 0 beyond.

    Parameters
    ----------
    tilt_deg : array_like
        Facet tilt from the optical axis, degrees.
    numerical_aperture : float
        Objective NA, 0 < NA < 1.
    fill : float
        Illumination NA as a fraction of the objective's, 0 ≤ fill ≤ 1.

    Returns
    -------
    numpy.ndarray of float32, the shape of ``tilt_deg``, in [0, 1]

    Raises
    ------
    ValueError
        ``numerical_aperture`` or ``fill`` out of range.

    Examples
    --------
    >>> f = pupil_fraction([0.0, 10.0, 20.0, 30.0, 60.0], numerical_aperture=0.8, fill=1.0)
    >>> [round(float(v), 2) for v in f]
    [1.0, 0.81, 0.58, 0.35, 0.0]
    >>> pupil_fraction([26.0, 27.0], numerical_aperture=0.8, fill=0.0).tolist()
    [1.0, 0.0]
    """
    if not 0 < numerical_aperture < 1:
        raise ValueError(f"numerical_aperture: out of range ({numerical_aperture!r})")
    if not 0 <= fill <= 1:
        raise ValueError(f"fill: out of range ({fill!r})")
    t = np.asarray(tilt_deg, dtype=np.float64)
    if fill == 0:
        return (t <= math.degrees(math.asin(numerical_aperture)) / 2.0).astype(np.float32)
    table = _pupil_table(float(numerical_aperture), float(fill))
    u = np.clip(t / _THETA_STEP_DEG, 0, table.size - 1)
    return np.interp(u, np.arange(table.size), table).astype(np.float32)


def pupil_limit_deg(*, numerical_aperture: float, fill: float) -> float:
    """Smallest tilt at which :func:`pupil_fraction` reaches 0 (degrees).

    >>> round(pupil_limit_deg(numerical_aperture=0.8, fill=0.0), 2)
    26.57
    """
    if fill == 0:
        return math.degrees(math.asin(numerical_aperture)) / 2.0
    table = _pupil_table(float(numerical_aperture), float(fill))
    zero = np.flatnonzero(table <= 0)
    return float(zero[0] * _THETA_STEP_DEG) if zero.size else 90.0


def vignetting_factor(shape, *, corner_loss: float) -> np.ndarray:
    """Illumination relative to the centre: ``(1 − corner_loss)^((r / r_corner)²)``.

    ``r`` is the distance from the image centre and ``r_corner`` that of the corner pixel
    centres, so the corners get exactly ``1 − corner_loss``.

    Parameters
    ----------
    shape : (int, int)
        Image height and width in pixels.
    corner_loss : float
        Fraction of the light lost at the corners, 0 ≤ corner_loss < 1.

    Returns
    -------
    numpy.ndarray of float32 (H, W)

    Examples
    --------
    >>> v = vignetting_factor((5, 5), corner_loss=0.3)
    >>> float(v[2, 2]), round(float(v[0, 0]), 6), round(float(v[4, 4]), 6)
    (1.0, 0.7, 0.7)
    """
    if not 0 <= corner_loss < 1:
        raise ValueError(f"corner_loss: out of range ({corner_loss!r})")
    h, w = shape
    yy = (np.arange(h, dtype=np.float64) - (h - 1) / 2.0)[:, None]
    xx = (np.arange(w, dtype=np.float64) - (w - 1) / 2.0)[None, :]
    r2 = (yy * yy + xx * xx) / max((h - 1) ** 2 / 4.0 + (w - 1) ** 2 / 4.0, 1e-12)
    return np.power(1.0 - corner_loss, r2).astype(np.float32)


def apply_white_balance(rgb, gains) -> np.ndarray:
    """Linear RGB (…, 3) times per-channel ``gains`` (R, G, B), float32.

    >>> [round(float(v), 3) for v in apply_white_balance(np.ones(3, np.float32), (1.1, 1, 0.9))]
    [1.1, 1.0, 0.9]
    """
    g = np.asarray(gains, dtype=np.float32)
    if g.shape != (3,) or not np.all(g > 0):
        raise ValueError(f"gains: expected three positive numbers, got {gains!r}")
    return np.asarray(rgb, dtype=np.float32) * g


def drift_offsets_px(rng, n_slices: int, *, step_px: float) -> np.ndarray:
    """Random-walk lateral offsets (dy, dx) of each slice, in pixels, with zero mean.

    Each step between consecutive slices is N(0, step_px²) per axis; the walk is shifted
    so that the offsets average to zero (the truth frame is the slices' mean position).

    Returns
    -------
    numpy.ndarray of float64 (n_slices, 2)

    Examples
    --------
    >>> d = drift_offsets_px(np.random.default_rng(0), 5, step_px=0.3)
    >>> d.shape, bool(np.allclose(d.mean(axis=0), 0.0))
    ((5, 2), True)
    """
    if step_px < 0:
        raise ValueError(f"step_px: must be >= 0, got {step_px!r}")
    steps = rng.standard_normal((n_slices, 2)) * step_px
    steps[0] = 0.0
    walk = np.cumsum(steps, axis=0)
    return walk - walk.mean(axis=0)


def shift_image(img, dy_px: float, dx_px: float) -> np.ndarray:
    """``img`` moved by (dy, dx) pixels: out[y, x] = img[y − dy, x − dx] (bicubic,
    borders reflected), float32."""
    m = np.array([[1.0, 0.0, dx_px], [0.0, 1.0, dy_px]], dtype=np.float64)
    h, w = img.shape[:2]
    return cv2.warpAffine(np.ascontiguousarray(img, dtype=np.float32), m, (w, h),
                          flags=cv2.INTER_CUBIC, borderMode=cv2.BORDER_REFLECT)
