"""The two distributions: oxide thickness (Gaussian mixture) and facet normals (NDF lobes).

Thickness
    ``g(d) = Σ w_i N(d; μ_i, σ_i²)`` in nm (seed Fig. 18a: three populations).

Normals
    A mixture of zero-mean lobes (seed Fig. 19: a narrow and a wide lobe, both with mode
    0°). Each lobe is **Gaussian in slope space**: the facet slopes
    ``(∂h/∂x, ∂h/∂y)`` are ``N(0, s² I)`` with ``s = tan(sd_deg)``. This is exactly the
    Beckmann NDF with roughness ``α = √2 s``:

        D(θ) = exp(−tan²θ / α²) / (π α² cos⁴θ),   ∫ D(ω) cos θ dω = 1.

    The density of the tilt θ of the *projected* surface (what a per-pixel histogram of a
    microscope image counts, one pixel = one unit of projected area) is

        p(θ) = 2π D(θ) cos θ sin θ = (tan θ / s²) sec² θ exp(−tan² θ / (2 s²)),

    i.e. the slope magnitude tan θ is Rayleigh-distributed with parameter ``s``. The
    sin θ of the solid-angle element is inside p(θ); dividing a tilt histogram by
    ``2π sin θ cos θ`` gives D. Smith's masking function for a mixture of slope
    distributions is linear in the mixture: ``Λ = Σ w_i Λ_i`` with the Beckmann
    ``Λ_i(θ) = (erf(a) − 1)/2 + exp(−a²)/(2 a √π)``, ``a = 1 / (α_i tan θ)``.

Both serialise to the ``summary.json`` form of the results format
(``{"components": [{"weight", "mean_nm", "sd_nm"}]}`` and
``{"form": "gaussian-slope", "components": [{"weight", "mean_deg": 0, "sd_deg"}]}``).
Reading that form (``from_json``, for data from a file) refuses more than
:data:`MAX_COMPONENTS` components before looking at any of them, so a file claiming a
million components costs nothing.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .lazy import load

special = load("scipy.special")

__all__ = ["MAX_COMPONENTS", "NDF_FORM", "NDFMixture", "ThicknessMixture"]

NDF_FORM = "gaussian-slope"
#: Most components a mixture read with ``from_json`` may have. The analysis fits at most 10
#: (``fits.max_components``); a file claiming more is refused before any component is read,
#: because the forward models' cost grows with the component count.
MAX_COMPONENTS = 10
_DEG = math.pi / 180.0
#: Widest lobe :meth:`NDFMixture.scaled` gives (the constructor refuses 89° and more).
_MAX_SD_DEG = 88.9


def _json_components(data, name) -> list:
    """The ``components`` list of a mixture's JSON form, at most :data:`MAX_COMPONENTS` long
    (ValueError naming the mixture)."""
    if not isinstance(data, dict):
        raise ValueError(f"{name}: expected an object with 'components', got "
                         f"{type(data).__name__}")
    if "components" not in data:
        raise ValueError(f"{name}: missing key 'components'")
    comps = data["components"]
    if not isinstance(comps, list):
        raise ValueError(f"{name}: 'components' must be a list, got {type(comps).__name__}")
    if len(comps) > MAX_COMPONENTS:
        raise ValueError(f"{name}: {len(comps):,} components, more than {MAX_COMPONENTS}")
    if not all(isinstance(c, dict) for c in comps):
        raise ValueError(f"{name}: every component must be an object")
    return comps


def _components(items, name, n):
    out = []
    for i, c in enumerate(items):
        c = tuple(float(v) for v in c)
        if len(c) != n:
            raise ValueError(f"{name}: component {i} needs {n} numbers, got {len(c)}")
        if not all(math.isfinite(v) for v in c):
            raise ValueError(f"{name}: component {i} is not finite")
        if c[0] <= 0:
            raise ValueError(f"{name}: component {i} has weight <= 0")
        if c[-1] <= 0:
            raise ValueError(f"{name}: component {i} has sd <= 0")
        out.append(c)
    if not out:
        raise ValueError(f"{name}: at least one component is needed")
    total = sum(c[0] for c in out)
    return tuple((c[0] / total,) + c[1:] for c in out)


@dataclass(frozen=True)
class ThicknessMixture:
    """Gaussian mixture of oxide thickness.

    Parameters
    ----------
    components : sequence of (weight, mean_nm, sd_nm)
        Weights are normalised to sum to 1; sorted by mean.

    Examples
    --------
    >>> g = ThicknessMixture([(0.5, 120.0, 3.0), (0.5, 140.0, 3.0)])
    >>> round(float(g.pdf(120.0)), 4)
    0.0665
    """

    components: tuple

    def __init__(self, components):
        comps = _components(components, "thickness mixture", 3)
        object.__setattr__(self, "components", tuple(sorted(comps, key=lambda c: c[1])))

    @property
    def weights(self):
        return np.array([c[0] for c in self.components])

    @property
    def means_nm(self):
        return np.array([c[1] for c in self.components])

    @property
    def sds_nm(self):
        return np.array([c[2] for c in self.components])

    @property
    def mean_nm(self) -> float:
        """Mean thickness of the whole mixture, nm."""
        return float(np.sum(self.weights * self.means_nm))

    @property
    def sd_nm(self) -> float:
        """Standard deviation of the whole mixture (within and between components), nm."""
        var = np.sum(self.weights * (self.sds_nm ** 2 + (self.means_nm - self.mean_nm) ** 2))
        return float(math.sqrt(var))

    def pdf(self, thickness_nm):
        """Density per nm at ``thickness_nm`` (any shape)."""
        d = np.asarray(thickness_nm, dtype=np.float64)[..., None]
        z = (d - self.means_nm) / self.sds_nm
        return np.sum(self.weights * np.exp(-0.5 * z * z) / (self.sds_nm * math.sqrt(2 * math.pi)),
                      axis=-1)

    def support_nm(self, *, n_sd: float = 4.0):
        """``(low, high)`` thickness range holding all but a negligible mass."""
        return (max(0.0, float(np.min(self.means_nm - n_sd * self.sds_nm))),
                float(np.max(self.means_nm + n_sd * self.sds_nm)))

    def to_json(self) -> dict:
        return {"components": [{"weight": w, "mean_nm": m, "sd_nm": s}
                               for w, m, s in self.components]}

    @classmethod
    def from_json(cls, data) -> "ThicknessMixture":
        """The mixture of its JSON form (at most :data:`MAX_COMPONENTS` components).

        >>> ThicknessMixture.from_json({"components": [{"weight": 1, "mean_nm": 51,
        ...                                             "sd_nm": 2}]}).means_nm.tolist()
        [51.0]
        >>> ThicknessMixture.from_json({"components": [{}] * 10**6})
        Traceback (most recent call last):
        ...
        ValueError: thickness mixture: 1,000,000 components, more than 10
        """
        comps = _json_components(data, "thickness mixture")
        try:
            return cls([(c["weight"], c["mean_nm"], c["sd_nm"]) for c in comps])
        except (KeyError, TypeError) as exc:
            raise ValueError(f"thickness mixture: missing key {exc}") from None


@dataclass(frozen=True)
class NDFMixture:
    """Mixture of zero-mean Gaussian-slope (Beckmann) lobes of facet normals.

    Parameters
    ----------
    components : sequence of (weight, sd_deg)
        ``sd_deg``: the per-axis slope standard deviation as an angle, ``s = tan(sd_deg)``.
        Weights are normalised; sorted by width.

    Examples
    --------
    >>> f = NDFMixture([(0.6, 3.0), (0.4, 9.0)])
    >>> th = np.linspace(0, 89.9, 20000)
    >>> round(float(np.trapezoid(f.tilt_pdf(th), th)), 4)
    1.0
    """

    components: tuple

    def __init__(self, components):
        comps = _components(components, "NDF mixture", 2)
        for w, sd in comps:
            if not sd < 89.0:
                raise ValueError("NDF mixture: sd_deg must be < 89")
        object.__setattr__(self, "components", tuple(sorted(comps, key=lambda c: c[1])))

    @property
    def weights(self):
        return np.array([c[0] for c in self.components])

    @property
    def sds_deg(self):
        return np.array([c[1] for c in self.components])

    @property
    def rms_sd_deg(self) -> float:
        """Weighted rms of the lobes' ``sd_deg``: one roughness angle for the mixture."""
        return float(math.sqrt(np.sum(self.weights * self.sds_deg ** 2)))

    @property
    def slope_sd(self):
        """Per-axis slope standard deviations ``s = tan(sd_deg)``."""
        return np.tan(self.sds_deg * _DEG)

    @property
    def beckmann_alpha(self):
        """Beckmann roughness of each lobe, ``α = √2 s``."""
        return math.sqrt(2.0) * self.slope_sd

    def rms_slope(self, max_tilt_deg=None) -> float:
        """RMS slope magnitude ``E[tan² θ]^½`` (|∇h|, dimensionless) of the facets, or of
        those tilted less than ``max_tilt_deg`` (what an objective of that acceptance sees).

        Per lobe ``tan² θ`` is exponential with mean ``2 s²``; below ``L = tan θ_max`` its
        mean is ``(2 s² (1 − e) − L² e) / (1 − e)`` with ``e = exp(−L² / 2 s²)``, exact.

        >>> f = NDFMixture([(1.0, 10.0)])
        >>> round(f.rms_slope() / (math.sqrt(2.0) * math.tan(math.radians(10.0))), 6)
        1.0
        >>> th = np.linspace(0.0, 20.0, 200001)
        >>> p = f.tilt_pdf(th)
        >>> num = np.trapezoid(p * np.tan(np.radians(th)) ** 2, th)
        >>> round(float(np.sqrt(num / np.trapezoid(p, th))) / f.rms_slope(20.0), 5)
        1.0
        """
        s2 = self.slope_sd ** 2
        w = self.weights
        if max_tilt_deg is None:
            return float(math.sqrt(np.sum(w * 2.0 * s2)))
        L2 = math.tan(float(max_tilt_deg) * _DEG) ** 2
        e = np.exp(-L2 / (2.0 * s2))
        seen = np.sum(w * -np.expm1(-L2 / (2.0 * s2)))
        ms = np.sum(w * (2.0 * s2 * (1.0 - e) - L2 * e))
        return float(math.sqrt(ms / seen)) if seen > 0 else math.nan

    def scaled(self, factor) -> "NDFMixture":
        """The lobes with every facet's slope multiplied by ``factor`` (> 0): ``s → factor·s``
        (``sd_deg`` capped just below 89°).

        >>> NDFMixture([(0.5, 5.0), (0.5, 10.0)]).scaled(2.0).rms_slope() / NDFMixture(
        ...     [(0.5, 5.0), (0.5, 10.0)]).rms_slope()
        2.0
        """
        sd = np.degrees(np.arctan(float(factor) * self.slope_sd))
        return NDFMixture([(w, min(float(s), _MAX_SD_DEG)) for w, s in zip(self.weights, sd)])

    def tilt_pdf(self, theta_deg):
        """Density per degree of the tilt of the projected surface (pixel histograms).

        ``p(θ) = Σ w_i (tan θ / s_i²) sec² θ exp(−tan² θ / 2 s_i²)``, times π/180 per degree.
        """
        th = np.asarray(theta_deg, dtype=np.float64)[..., None] * _DEG
        t = np.tan(th)
        s2 = self.slope_sd ** 2
        with np.errstate(over="ignore", invalid="ignore"):
            p = self.weights * t / s2 / np.cos(th) ** 2 * np.exp(-0.5 * t * t / s2)
        p = np.where(np.isfinite(p), p, 0.0)
        return np.sum(p, axis=-1) * _DEG

    def D(self, theta_deg):
        """Beckmann-mixture NDF per steradian, normalised so ∫ D cos θ dω = 1."""
        th = np.asarray(theta_deg, dtype=np.float64)[..., None] * _DEG
        a2 = self.beckmann_alpha ** 2
        c = np.cos(th)
        with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
            d = self.weights * np.exp(-np.tan(th) ** 2 / a2) / (math.pi * a2 * c ** 4)
        d = np.where(np.isfinite(d) & (c > 0), d, 0.0)
        return np.sum(d, axis=-1)

    def smith_lambda(self, theta_deg):
        """Smith's Λ for a direction at zenith ``theta_deg`` (linear in the mixture)."""
        th = np.asarray(theta_deg, dtype=np.float64)[..., None] * _DEG
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            a = 1.0 / (self.beckmann_alpha * np.tan(th))
            lam = (special.erf(a) - 1.0) / 2.0 + np.exp(-a * a) / (2.0 * a * math.sqrt(math.pi))
        lam = np.where(np.isfinite(a) & (a > 0), lam, 0.0)
        return np.sum(self.weights * np.maximum(lam, 0.0), axis=-1)

    def to_json(self) -> dict:
        return {"form": NDF_FORM,
                "components": [{"weight": w, "mean_deg": 0.0, "sd_deg": s}
                               for w, s in self.components]}

    @classmethod
    def from_json(cls, data) -> "NDFMixture":
        """The lobes of their JSON form (at most :data:`MAX_COMPONENTS` components)."""
        form = data.get("form", NDF_FORM) if isinstance(data, dict) else None
        if form != NDF_FORM:
            raise ValueError(f"NDF mixture: unsupported form {form!r} (expected {NDF_FORM!r})")
        comps = _json_components(data, "NDF mixture")
        try:
            if any(abs(float(c.get("mean_deg", 0.0))) > 1e-9 for c in comps):
                raise ValueError("NDF mixture: lobes must have mean_deg 0")
            return cls([(c["weight"], c["sd_deg"]) for c in comps])
        except (KeyError, TypeError) as exc:
            raise ValueError(f"NDF mixture: missing key {exc}") from None
