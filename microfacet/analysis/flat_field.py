"""The microscope's flat field (vignetting), estimated from the facets' own brightness.

A microscope image is darker towards its edges: the illumination and the objective's pupil
cut off oblique light (vignetting), and the lamp may light the field unevenly. One global
exposure cannot follow that. On three draws of the generalization sweep (docs/accuracy.md),
the scenes with vignetting (10-50 % of the light lost at the corners) had median region
thickness errors of 1.0, 6.8 and 10.5 nm, against 0.5, 0.5 and 1.3 nm without: the corners'
facets were compared with the film at the centre's brightness, and some were read in
another interference order.

The joint stage knows each facet's film colour at its thickness and tilt. The ratio of a
facet's observed luminance Y to the model's at the global exposure is therefore the
illumination at the facet relative to the exposure. :func:`estimate_flat_field` fits a
smooth field to the log ratios of the facets whose colour the film explains (area-weighted,
robust: Tukey's biweight, so dust, stains and mis-read facets do not pull it)::

    ln V(u, v) = c1 u + c2 v + c3 u² + c4 u v + c5 v² [+ c6 r⁴ [+ c7 r⁶]]

with (u, v) the position from the image centre in half-diagonals, so that V = 1 at the
centre and the exposure stays the centre's. Second order holds centred and off-centre
vignetting, an elliptical one and a linear gradient of the lamp; the radial terms r⁴ and r⁶
(r² = u² + v², the even polynomial of lens vignetting [1]) follow a falloff that is not
Gaussian. The number of terms is the scene's: none, 5, 6 or 7, by BIC over the facets'
ratios. A field that nowhere moves the light by more than the facets' own brightness scatter
(the robust SD of their log ratios about it) is not used either: it cannot be told from the
scatter, and on the sweep such fields (1-2 % at the corners) only tipped close model choices
between copies of one scene in different encodings. The caller (:mod:`.pipeline`) also keeps
a field only where the facets refitted under it fit their colours better (median ΔE00), so
it can only follow the evidence.

:func:`flat_fielded` divides the image's linear values by the field: the Lab values and the
pixels far darker than the film (the steep mask, which compares each pixel with the film's
median) are recomputed; the tests for clipping, low saturation and low value stay those of
the recorded values.

References
----------
.. [1] D. B. Goldman, "Vignette and exposure calibration and compensation", IEEE Trans. Pattern
   Anal. Mach. Intell. 32(12) (2010) 2276-2288, doi:10.1109/TPAMI.2010.55 (vignetting as a
   smooth even function of the distance from the centre, estimated with the scene).
.. [2] P. W. Holland, R. E. Welsch, "Robust regression using iteratively reweighted
   least-squares", Commun. Stat. Theory Methods 6(9) (1977) 813-827,
   doi:10.1080/03610927708827533 (the biweight).

Examples
--------
>>> ff = FlatField(coefficients=(0.0, 0.0, -0.5, 0.0, -0.5), applied=True)
>>> v = ff.map((5, 5))
>>> round(float(v[2, 2]), 3), round(float(v[0, 0]), 3), round(ff.corner_loss((5, 5)), 3)
(1.0, 0.607, 0.393)
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from ..colour.colorimetry import lab_to_xyz
from ..colour.transfer import srgb_decode
from ..core.errors import InputError
from .identification import unexplained_facets
from .mask import dark_classes
from .planes import TUKEY_C
from .white_balance import balanced_lab

__all__ = ["MAX_ROUNDS", "ROUND_TOLERANCE", "FlatField", "estimate_flat_field",
           "facet_brightness", "flat_fielded", "reference_flat_field"]

#: The models tried: the number of terms of ln V besides the constant (which the exposure
#: takes), nested (u, v, u², uv, v², r⁴, r⁶).
N_TERMS = (5, 6, 7)
#: Fewest facets with a brightness ratio for a field to be fitted.
MIN_FACETS = 30
#: Fewest usable pixels of a facet for its mean brightness to count.
MIN_FACET_PIXELS = 10
#: IRLS rounds of the biweight (its constant the planes' :data:`~.planes.TUKEY_C`: 95 %
#: efficiency for Gaussian residuals).
ROUNDS = 10
#: Rounds of estimate and refit at most (the facets' thicknesses absorb part of a field not
#: yet corrected, so one round finds 50-90 % of it), and the corner-loss change below which
#: another round is not tried.
MAX_ROUNDS = 3
ROUND_TOLERANCE = 0.01
#: The reference image's field: medians of blocks of this fraction of its diagonal (dust and
#: texture on the target smaller than half a block do not enter), and a 2-D polynomial of
#: this degree fitted to their logs (a smooth field, to the corners).
REFERENCE_BLOCK_FRACTION = 0.05
REFERENCE_DEGREE = 4
#: Largest ln V the field may reach on the image (a factor e⁻² ≈ 0.14 of the centre's light):
#: an estimate deeper than that anywhere on the image is not trusted, and pixels a reference
#: puts below it carry too little light to read (masked, not amplified).
MAX_LOG_LOSS = 2.0


@dataclass(frozen=True)
class FlatField:
    """The flat field the colours were divided by (summary.json ``flat_field``).

    Attributes
    ----------
    coefficients : tuple of 5-7 float or None
        ln V terms (u, v, u², uv, v², r⁴, r⁶: as many as the scene asked for), (u, v) from
        the image centre in half-diagonals; None: not estimated.
    applied : bool
        The colours were divided by the field.
    facets : int
        Facets whose brightness ratio the fit used (inliers of the biweight).
    misfit_sd : float or None
        Robust SD of the facets' ln ratios about the field (of the last round's estimate,
        which is made on colours already corrected by the rounds before).
    bic_gain : float or None
        BIC of a flat field minus that of the fitted one, over the facets (> 0: the data ask
        for the field; the last round's, as ``facets`` and ``misfit_sd``).
    median_delta_e : tuple of 2 float or None
        Median facet ΔE00 without and with the field, where the facets were refitted under it.
    reason : str
        Why it is not applied (empty when applied).
    rounds : int
        Rounds of estimate and refit whose field was kept (each adds to the last).
    source : str
        ``"estimated"`` (from the facets) or ``"flat reference NAME"`` (an image of an even
        target, :func:`reference_flat_field`).
    image : ndarray (H, W) or None
        The reference's field (V per pixel); None for an estimate (``coefficients`` hold it).
    """

    coefficients: tuple | None = None
    applied: bool = False
    facets: int = 0
    misfit_sd: float | None = None
    bic_gain: float | None = None
    median_delta_e: tuple | None = None
    reason: str = ""
    rounds: int = 0
    source: str = "estimated"
    image: np.ndarray | None = dataclasses.field(default=None, repr=False, compare=False)

    def checked(self, shape) -> "FlatField":
        """The field, or with ``reason`` set where it is deeper than :data:`MAX_LOG_LOSS`
        anywhere on an image of ``shape`` (the corners, where r⁴ and r⁶ reach furthest)."""
        deepest = float(self.log_map(shape).min())
        if -deepest > MAX_LOG_LOSS:
            return dataclasses.replace(self, reason=f"the fitted field loses "
                                                    f"{1 - math.exp(deepest):.0%} of the light "
                                                    f"at the image's edge: not trusted")
        return self

    def plus(self, other: "FlatField") -> "FlatField":
        """The field times ``other``'s (ln V added term by term); ``other``'s fit numbers."""
        a = np.zeros(max(N_TERMS))
        b = np.zeros(max(N_TERMS))
        a[:len(self.coefficients)] = self.coefficients
        b[:len(other.coefficients)] = other.coefficients
        n = max(len(self.coefficients), len(other.coefficients))
        return dataclasses.replace(other, coefficients=tuple(float(x) for x in (a + b)[:n]))

    def log_map(self, shape) -> np.ndarray:
        """ln V per pixel, float32 (H, W); zeros without coefficients."""
        h, w = shape
        if self.image is not None:
            return np.log(self.image).astype(np.float32)
        if self.coefficients is None:
            return np.zeros((h, w), np.float32)
        u, v = _centred(np.arange(w, dtype=np.float64)[None, :],
                        np.arange(h, dtype=np.float64)[:, None], shape)
        return _log_field(self.coefficients, u, v).astype(np.float32)

    def map(self, shape) -> np.ndarray:
        """V per pixel (float32, (H, W)): the light relative to the image centre."""
        return np.exp(self.log_map(shape))

    def corner_loss(self, shape) -> float | None:
        """The largest fraction of light lost at the four corners (None: no coefficients)."""
        if self.image is not None:
            corners = np.log(self.image[[0, 0, -1, -1], [0, -1, 0, -1]].astype(np.float32))
        elif self.coefficients is not None:
            h, w = shape
            u, v = _centred(np.array([0.0, w - 1, 0.0, w - 1]),
                            np.array([0.0, 0.0, h - 1, h - 1]), shape)
            corners = _log_field(self.coefficients, u, v).astype(np.float32)
        else:
            return None
        return float(1.0 - math.exp(float(corners.min())))

    def to_json(self, shape) -> dict:
        """summary.json ``flat_field`` (docs/results-format.md); ``shape`` (H, W) of the
        image, for the corner loss."""
        return {"applied": self.applied, "source": self.source,
                "coefficients": None if self.coefficients is None else list(self.coefficients),
                "corner_loss": self.corner_loss(shape), "facets": self.facets,
                "misfit_sd": self.misfit_sd, "bic_gain": self.bic_gain,
                "median_delta_e": None if self.median_delta_e is None
                else list(self.median_delta_e), "rounds": self.rounds, "reason": self.reason}


def _centred(x, y, shape):
    h, w = shape
    r = math.hypot((h - 1) / 2.0, (w - 1) / 2.0) or 1.0
    return (x - (w - 1) / 2.0) / r, (y - (h - 1) / 2.0) / r


def _design(u, v, n_terms) -> np.ndarray:
    """The constant and the first ``n_terms`` of (u, v, u², uv, v², r⁴, r⁶), stacked last."""
    u, v = np.broadcast_arrays(np.asarray(u, np.float64), np.asarray(v, np.float64))
    r2 = u * u + v * v
    cols = [np.ones_like(u), u, v, u * u, u * v, v * v, r2 * r2, r2 * r2 * r2]
    return np.stack(cols[:n_terms + 1], axis=-1)


def _log_field(c, u, v):
    """ln V = Σ c_k · term_k(u, v) over the first ``len(c)`` of (u, v, u², uv, v², r⁴, r⁶)
    (as :func:`_design`), broadcast term by term: an (H, W) map from a row ``u`` and a
    column ``v`` takes a few (H, W) temporaries, not a stack of all the terms."""
    c = list(c)
    out = c[0] * u + c[1] * v + c[2] * (u * u) + c[3] * (u * v) + c[4] * (v * v)
    if len(c) > 5:
        r2 = u * u + v * v
        out = out + c[5] * (r2 * r2)
        if len(c) > 6:
            out = out + c[6] * (r2 * r2 * r2)
    return out


#: Pixels per chunk of the per-pixel luminance (bounded float64 temporaries).
_CHUNK_PX = 1 << 18


def _pixel_luminance(lab_px, idx) -> np.ndarray:
    """:func:`_luminance` of the rows ``idx`` of ``lab_px`` (N, 3), chunk by chunk: float64
    (len(idx),), the same values as at once."""
    out = np.empty(idx.size)
    for a in range(0, idx.size, _CHUNK_PX):
        out[a:a + _CHUNK_PX] = _luminance(lab_px[idx[a:a + _CHUNK_PX]])
    return out


def _facet_centres(labels, S, area):
    """Each facet's mean (u, v) (:func:`_centred`), one coordinate at a time."""
    h, w = labels.shape
    lb = labels.ravel()
    x = np.tile(np.arange(w), h)
    u = _centred(x, 0, labels.shape)[0]
    del x
    uc = np.bincount(lb, weights=u, minlength=S) / np.maximum(area, 1.0)
    del u
    y = np.repeat(np.arange(h), w)
    v = _centred(0, y, labels.shape)[1]
    del y
    return uc, np.bincount(lb, weights=v, minlength=S) / np.maximum(area, 1.0)


def _luminance(lab):
    """Relative luminance Y/Yn of CIELAB rows (N, 3), float64: the Y of
    :func:`~microfacet.colour.colorimetry.lab_to_xyz`, which depends on L* alone."""
    return lab_to_xyz(np.asarray(lab, np.float64))[..., 1]


def _biweight_fit(a, y, w):
    """Robust weighted least squares: (coefficients, residuals, robust scale, final
    weights)."""
    wt = w.copy()
    c = np.zeros(a.shape[1])
    s = float("nan")
    for _ in range(ROUNDS):
        sw = np.sqrt(wt)
        c = np.linalg.lstsq(a * sw[:, None], y * sw, rcond=None)[0]
        r = y - a @ c
        s = 1.4826 * float(np.median(np.abs(r))) + 1e-9
        z = r / (TUKEY_C * s)
        wt = w * np.where(np.abs(z) < 1.0, (1.0 - z * z) ** 2, 0.0)
    return c, y - a @ c, s, wt


def facet_brightness(joint, lab, model, *, unexplained_mads):
    """Each facet's ln(observed Y / model Y) at its thickness and tilt.

    Parameters
    ----------
    joint : JointResult
        The facets: labels (H, W), usable and censored pixels, thickness and tilt per facet.
    lab : ndarray (H, W, 3)
        CIELAB of the image.
    model : FilmColourModel
        At the facets' exposure.
    unexplained_mads : float
        Facets whose ΔE00 is a robust outlier by this many MADs are left out (as the
        thickness mixture leaves them out: ``fits.unexplained_mads``).

    Returns
    -------
    (rho, u, v, n) : 4 ndarrays of shape (S,)
        The log ratio (NaN where a facet has none: censored, unexplained colour, fewer than
        :data:`MIN_FACET_PIXELS` usable pixels), the facet's centre (u, v) in half-diagonals
        from the image centre, and its usable pixel count.
    """
    labels = joint.facets
    S = int(labels.max()) + 1
    lb = labels.ravel()
    lab_px = np.asarray(lab).reshape(-1, 3)
    ok_px = np.flatnonzero(np.asarray(joint.usable, bool).ravel() & np.isfinite(lab_px[:, 0]))
    lb_ok = lb[ok_px]
    n = np.bincount(lb_ok, minlength=S).astype(np.float64)
    y_obs = np.bincount(lb_ok, weights=_pixel_luminance(lab_px, ok_px), minlength=S) \
        / np.maximum(n, 1.0)
    del lb_ok
    ft = joint.thickness
    t_lo, t_hi = model.theta_range_deg
    y_mod = _luminance(model.lab(np.clip(joint.prior_deg, t_lo, t_hi), ft.thickness_nm))
    area = np.bincount(lb, minlength=S).astype(np.float64)
    uc, vc = _facet_centres(labels, S, area)
    cens = np.bincount(lb, weights=np.asarray(joint.censored, np.float64).ravel(),
                       minlength=S) / np.maximum(area, 1.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        rho = np.log(y_obs / y_mod)
    good = (np.isfinite(rho) & (n >= MIN_FACET_PIXELS) & (cens < 0.5)
            & ~unexplained_facets(ft.delta_e, unexplained_mads))
    return np.where(good, rho, np.nan), uc, vc, n


def estimate_flat_field(joint, lab, model, *, unexplained_mads) -> FlatField:
    """The flat field the facets' brightness asks for (module notes); ``applied`` False.

    Parameters
    ----------
    joint : JointResult
        The facets (labels, thickness, tilt, usable and censored pixels).
    lab : ndarray (H, W, 3)
        The image's CIELAB, as the facets were fitted to.
    model : FilmColourModel
        At the facets' exposure.
    unexplained_mads : float
        As :func:`facet_brightness`.

    Returns
    -------
    FlatField
        With ``coefficients`` where at least :data:`MIN_FACETS` facets have a ratio, and
        ``reason`` when the data do not ask for a field (BIC), when it moves the light
        nowhere by more than the facets' brightness scatter, or when it is deeper than
        :data:`MAX_LOG_LOSS` anywhere on the image.
    """
    rho, u, v, n = facet_brightness(joint, lab, model, unexplained_mads=unexplained_mads)
    ok = np.isfinite(rho)
    if ok.sum() < MIN_FACETS:
        return FlatField(facets=int(ok.sum()), reason=f"{int(ok.sum())} facets with a "
                         f"brightness ratio, fewer than {MIN_FACETS}")
    y, w = rho[ok], n[ok]
    fits = {k: _biweight_fit(_design(u[ok], v[ok], k), y, w) for k in N_TERMS}
    # BIC over the facets the richest fit keeps (biweight inliers), against a constant
    inl = fits[N_TERMS[-1]][3] > 0
    n_in = int(inl.sum())

    def bic(k):
        a = _design(u[ok][inl], v[ok][inl], k)
        c = np.linalg.lstsq(a * np.sqrt(w[inl])[:, None], y[inl] * np.sqrt(w[inl]),
                            rcond=None)[0] if k else None
        r = y[inl] - (a @ c if k else np.average(y[inl], weights=w[inl]))
        return n_in * math.log(max(float(np.average(r * r, weights=w[inl])), 1e-30)) \
            + k * math.log(max(n_in, 2))
    scores = {k: bic(k) for k in (0, *N_TERMS)}
    k = min(N_TERMS, key=scores.get)
    c, _, s, wt = fits[k]
    gain = scores[0] - scores[k]
    ff = FlatField(coefficients=tuple(float(x) for x in c[1:]), facets=int((wt > 0).sum()),
                   misfit_sd=float(s), bic_gain=float(gain))
    if gain <= 0:
        return dataclasses.replace(ff, reason="the facets' brightness does not ask for a "
                                              "flat field (BIC)")
    amplitude = float(np.abs(ff.log_map(joint.facets.shape)).max())
    if amplitude < s:
        return dataclasses.replace(ff, reason=f"the field moves the light by at most "
                                              f"{amplitude:.1%}, within the facets' own "
                                              f"brightness scatter ({s:.1%})")
    return ff.checked(joint.facets.shape)


def reference_flat_field(stack, given, shape, *, where_given) -> FlatField | None:
    """The flat field of a reference image (module notes), or None without one: ``given``
    (the option ``optics.flat_reference``, named ``where_given`` in errors), else the file
    stack.json's ``flat_reference`` names.

    The image's linear luminance (grey: its one channel) is taken in blocks of
    :data:`REFERENCE_BLOCK_FRACTION` of the image's diagonal, their medians (so dust,
    texture and noise on the target do not enter) fitted by a smooth 2-D polynomial in log,
    and divided by its value at the centre.

    Raises
    ------
    InputError
        The image is missing, not of the stack's size, or too dark or clipped to measure
        the light (one line naming the file and the key or option).
    """
    ref = stack.read_reference("flat_reference", given, where_given=where_given)
    if ref is None:
        return None
    img, name, where = ref
    if tuple(img.shape[:2]) != tuple(shape):
        raise InputError(f"{where}: a flat reference must have the stack's size "
                         f"{shape[1]} x {shape[0]} px, got {img.shape[1]} x {img.shape[0]}")
    rgb = img if img.ndim == 3 else img[..., None]
    clipped = float(np.mean(rgb.max(axis=-1) >= 0.995))
    lin = (rgb[..., :3] if stack.color_space == "linear-sRGB"
           else srgb_decode(rgb[..., :3])).mean(axis=-1).astype(np.float32)
    level = float(np.median(lin))
    if clipped > 0.01 or level < 0.02:
        what = "clipped" if clipped > 0.01 else "too dark"
        raise InputError(f"{where}: the flat reference is {what} ({100 * clipped:.0f} % of its "
                         f"pixels at the top code, median linear value {level:.3f}): take it "
                         f"with less or more light")
    block = max(4, int(round(REFERENCE_BLOCK_FRACTION * math.hypot(*shape))))
    field = np.exp(_reference_field(lin, block))
    return FlatField(applied=True, source=f"flat reference {name}", image=field)


def _reference_field(lin, block):
    """ln V of a reference's linear luminance ``lin`` (H, W): the medians of ``block`` px
    blocks (dust and texture smaller than half a block do not enter), a 2-D polynomial of
    degree :data:`REFERENCE_DEGREE` in (u, v) fitted to their logs (robust: the biweight
    leaves out blocks that dust covers), 0 at the centre. Returns float32 (H, W)."""
    h, w = lin.shape
    nb_y, nb_x = -(-h // block), -(-w // block)
    pad = np.pad(lin, ((0, nb_y * block - h), (0, nb_x * block - w)), mode="constant",
                 constant_values=np.nan)
    med = np.nanmedian(pad.reshape(nb_y, block, nb_x, block).swapaxes(1, 2)
                       .reshape(nb_y, nb_x, -1), axis=-1)
    cy = (np.arange(nb_y) * block + (np.minimum(block, h - np.arange(nb_y) * block) - 1) / 2.0)
    cx = (np.arange(nb_x) * block + (np.minimum(block, w - np.arange(nb_x) * block) - 1) / 2.0)
    yy, xx = np.meshgrid(cy, cx, indexing="ij")
    u, v = _centred(xx.ravel(), yy.ravel(), (h, w))
    ok = np.isfinite(med.ravel()) & (med.ravel() > 0)

    powers = [(i, d - i) for d in range(REFERENCE_DEGREE + 1) for i in range(d + 1)]
    basis = np.stack([u[ok] ** i * v[ok] ** j for i, j in powers], axis=-1)
    c, _, _, _ = _biweight_fit(basis, np.log(med.ravel()[ok]), np.ones(int(ok.sum())))
    # on every pixel, term by term (each an outer product of a column and a row), 0 at the
    # centre, where only the constant term is left
    pu, pv = _centred(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64), (h, w))
    out = np.zeros((h, w))
    for (i, j), ck in zip(powers, c):
        out += ck * np.outer(pv ** j, pu ** i)
    return (out - c[0]).astype(np.float32)


def flat_fielded(colour, field, *, gains_rgb=(1.0, 1.0, 1.0), illuminant, mask_options):
    """The colours under even light.

    Parameters
    ----------
    colour : ColourImage
        As measured (:func:`~.colour_image.measure_colour`).
    field : ndarray (H, W)
        V per pixel: the light relative to the centre.
    gains_rgb : tuple of 3 float
        The camera's white-balance gains the colours are divided by too.
    illuminant : str
    mask_options : MaskOptions
        The steep mask's thresholds (``mask.steep_*``, ``mask.dark_film_min_px``): it is
        recomputed on the even image.

    Returns
    -------
    ColourImage
        Lab of the linear values divided by ``field`` and ``gains_rgb``; the steep mask
        and the dark features recomputed; pixels with less than e^-:data:`MAX_LOG_LOSS` of
        the centre's light masked as dark (too little light to read); every clipped pixel
        masked (divided by the field their clip level varies across the image); the other
        masks kept. The noise is kept too, though a corner's grows as 1/V.
    """
    enc = np.asarray(colour.encoded, np.float32)
    v = np.asarray(field, np.float32)
    dim = v < math.exp(-MAX_LOG_LOSS)
    lin = srgb_decode(enc) / np.maximum(v, math.exp(-MAX_LOG_LOSS))[..., None]
    lab = balanced_lab(lin, gains_rgb, illuminant=illuminant, linear=True)
    cm = colour.mask.clipped_masked()
    dark = cm.dark | (dim & ~cm.invalid)
    base = cm.low_saturation | dark | cm.clipped | cm.invalid | cm.shadow
    steep = feature = np.zeros_like(cm.steep)
    if mask_options.steep_ratio > 0 and (~base).any():
        steep, feature = dark_classes(np.maximum(lin, 0.0).max(axis=-1), base, cm.invalid,
                                      mask_options)
    mask = dataclasses.replace(cm, mask=base | steep | feature, dark=dark, steep=steep,
                               dark_feature=feature)
    return dataclasses.replace(colour, lab=lab, mask=mask, clip_rgb=None)
