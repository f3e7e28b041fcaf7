"""The measured thin-film microfacet BSDF as a Mitsuba 3 plugin (spectral variants).

It is :meth:`microfacet.forward.material.Material.brdf` — the film average ⟨R⟩(θ_d, λ)
looked up bilinearly in the exported table, times ``D G₂ / (4 cos θ_i cos θ_o)`` of the
Beckmann lobe mixture with its own height-correlated Smith term — written with Dr.Jit so that
it runs vectorized in the ``llvm_ad_spectral`` variant and per sample in ``scalar_spectral``.

Sampling: a lobe is chosen, then a normal from that lobe's *visible* normals (Heitz &
d'Eon 2014, Mitsuba's own Beckmann sampler), with lobe probabilities
``w_k (1 + Λ_k(ω_i)) / (1 + Λ(ω_i))`` so that the mixture samples exactly the mixture's
visible-normal density ``G₁(ω_i) ⟨ω_i·m⟩ D(m) / cos θ_i``; ``pdf`` evaluates that density in
closed form with the exact Λ (``erf``), not Mitsuba's rational G₁ approximation, and a χ²
test against Mitsuba's sampler passes at grazing incidence (tests/render/test_bsdf.py).
Sampling all normals (density ``D(m) cos θ_m``) was tried and dropped: it wastes the
samples whose facets face away at grazing incidence and failed the same χ² test there.

The material is one-sided (front side, like Mitsuba's ``roughconductor``): wrap it in
``twosided`` for sheets seen from both sides. Only unpolarized spectral variants carry
wavelengths (``*_spectral``); RGB and polarized variants are refused.

Usage::

    import mitsuba as mi
    mi.set_variant("llvm_ad_spectral")
    from microfacet.render import bsdf
    bsdf.register()
    material = mi.load_dict({"type": "microfacet_thinfilm", "filename": "material.npz"})
    # or straight from an analysis: {"type": "microfacet_thinfilm", "results": "out/nd"}

In scalar variants Python runs once per sample and, since Dr.Jit's ``select`` evaluates both
branches, every division here is guarded against a zero denominator.

References
----------
.. [1] B. Walter et al., "Microfacet models for refraction through rough surfaces", EGSR 2007.
.. [2] E. Heitz, E. d'Eon, "Importance sampling microfacet-based BSDFs using the distribution
   of visible normals", Computer Graphics Forum 33(4) (2014) 103-112.
"""

from __future__ import annotations

import math
from functools import lru_cache

from ..core.errors import InputError
from ..core.lazy import load
from ..forward.material import Material

mi = load("mitsuba", keep=False)
dr = load("drjit", keep=False)

__all__ = ["PLUGIN", "bsdf_class", "register"]

#: The plugin name registered with Mitsuba.
PLUGIN = "microfacet_thinfilm"
_SQRT_PI = math.sqrt(math.pi)
_RAD2DEG = 180.0 / math.pi
_TINY = 1e-12


def check_variant(variant: str) -> None:
    """InputError naming ``variant`` unless it is an unpolarized spectral variant."""
    if not variant.endswith("_spectral"):
        raise InputError(f"{variant!r} has no wavelengths; the thin-film BSDF needs an "
                         "unpolarized spectral variant (llvm_ad_spectral or scalar_spectral)",
                         param="variant")


def smith_lambda(alpha: float, cos_theta):
    """Smith's Λ of one Beckmann lobe (exact, with ``erf``) for directions with ``cos_theta``."""
    sin_theta = dr.safe_sqrt(1.0 - cos_theta * cos_theta)
    a = cos_theta / dr.maximum(alpha * sin_theta, _TINY)
    lam = (dr.erf(a) - 1.0) * 0.5 + dr.exp(-a * a) / (2.0 * _SQRT_PI * dr.maximum(a, _TINY))
    return dr.select((sin_theta > 0) & (cos_theta > 0), dr.maximum(lam, 0.0), 0.0)


class ThinFilmModel:
    """The BSDF's methods (Mitsuba's ``BSDF`` interface); :func:`bsdf_class` mixes them into
    the variant's ``mi.BSDF``. Properties: ``filename``, a material file, or ``results``, an
    analysis results folder (tabulated when the plugin is loaded, ~1 s)."""

    def __init__(self, props):
        mi.BSDF.__init__(self, props)
        # a name relative to a scene file: Mitsuba's file resolver holds the file's folder
        if "filename" in props:
            self.filename = str(mi.file_resolver().resolve(str(props["filename"])))
            material = Material.read(self.filename)
        elif "results" in props:
            self.filename = str(mi.file_resolver().resolve(str(props["results"])))
            material = Material.from_results(self.filename)
        else:
            raise InputError(f"the {PLUGIN} BSDF needs a 'filename' property (a material "
                             "file written by `microfacet export-brdf`) or a 'results' "
                             "property (an analysis results folder)", param="filename")
        ndf = material.ndf
        self.weights = [float(w) for w in ndf.weights]
        self.alphas = [float(a) for a in ndf.beckmann_alpha]
        self.lobes = [mi.MicrofacetDistribution(mi.MicrofacetType.Beckmann, a, True)
                      for a in self.alphas]
        th, wl = material.theta_d_deg, material.wavelength_nm
        self.theta_step, self.n_theta = float(th[1] - th[0]), int(th.size)
        self.wl0, self.wl_step, self.n_wl = float(wl[0]), float(wl[1] - wl[0]), int(wl.size)
        table = mi.TensorXf(material.film_average.reshape(th.size, wl.size, 1))
        self.table = mi.Texture2f(table, filter_mode=dr.FilterMode.Linear,
                                  wrap_mode=dr.WrapMode.Clamp)
        self.m_flags = mi.BSDFFlags.GlossyReflection | mi.BSDFFlags.FrontSide
        self.m_components = [self.m_flags]

    # -- the model's parts --------------------------------------------------------
    def lambdas(self, cos_theta):
        return [smith_lambda(a, cos_theta) for a in self.alphas]

    def ndf(self, m):
        d = 0.0
        for w, lobe in zip(self.weights, self.lobes):
            d = d + w * lobe.eval(m)
        return d

    def film(self, cos_theta_d, wavelengths):
        theta = dr.acos(dr.clip(cos_theta_d, -1.0, 1.0)) * _RAD2DEG
        v = (theta / self.theta_step + 0.5) / self.n_theta
        out = mi.Spectrum(0.0)
        for k in range(len(wavelengths)):
            u = ((wavelengths[k] - self.wl0) / self.wl_step + 0.5) / self.n_wl
            out[k] = self.table.eval(mi.Point2f(u, v))[0]
        return out

    def lobe_probabilities(self, lam_i):
        total = 1.0 + sum(w * lam for w, lam in zip(self.weights, lam_i))
        return [w * (1.0 + lam) / total for w, lam in zip(self.weights, lam_i)]

    def normal_pdf(self, wi, m, lam_i):
        """Visible-normal density of m (per solid angle of m) seen from wi."""
        ci = mi.Frame3f.cos_theta(wi)
        g1 = 1.0 / (1.0 + sum(w * lam for w, lam in zip(self.weights, lam_i)))
        return g1 * dr.maximum(dr.dot(wi, m), 0.0) * self.ndf(m) / dr.maximum(ci, _TINY)

    def value(self, si, wo, active):
        """f · cos θ_o and the half vector, zero where inactive."""
        wi = si.wi
        ci, co = mi.Frame3f.cos_theta(wi), mi.Frame3f.cos_theta(wo)
        active = active & (ci > 0) & (co > 0)
        h = dr.normalize(wi + wo)
        lam = [wl + wo_ for wl, wo_ in zip(self.lambdas(ci), self.lambdas(co))]
        g2 = 1.0 / (1.0 + sum(w * x for w, x in zip(self.weights, lam)))
        f = self.film(dr.dot(wi, h), si.wavelengths) * (
            self.ndf(h) * g2 / (4.0 * dr.maximum(ci, _TINY)))
        return dr.select(active, f, 0.0), h, active

    # -- Mitsuba's interface ------------------------------------------------------
    def eval(self, ctx, si, wo, active=True):
        active = active & ctx.is_enabled(mi.BSDFFlags.GlossyReflection)
        return self.value(si, wo, active)[0]

    def pdf(self, ctx, si, wo, active=True):
        wi = si.wi
        ci, co = mi.Frame3f.cos_theta(wi), mi.Frame3f.cos_theta(wo)
        active = active & (ci > 0) & (co > 0) & ctx.is_enabled(
            mi.BSDFFlags.GlossyReflection)
        h = dr.normalize(wi + wo)
        p = self.normal_pdf(wi, h, self.lambdas(ci)) / (
            4.0 * dr.maximum(dr.dot(wo, h), _TINY))
        return dr.select(active, p, 0.0)

    def eval_pdf(self, ctx, si, wo, active=True):
        return self.eval(ctx, si, wo, active), self.pdf(ctx, si, wo, active)

    def sample(self, ctx, si, sample1, sample2, active=True):
        wi = si.wi
        ci = mi.Frame3f.cos_theta(wi)
        active = active & (ci > 0) & ctx.is_enabled(mi.BSDFFlags.GlossyReflection)
        lam_i = self.lambdas(ci)
        probs = self.lobe_probabilities(lam_i)
        m, _ = self.lobes[0].sample(wi, sample2)
        cum = probs[0]
        for k in range(1, len(self.lobes)):
            mk, _ = self.lobes[k].sample(wi, sample2)
            m = dr.select(sample1 >= cum, mk, m)
            cum = cum + probs[k]
        wo = mi.reflect(wi, m)
        bs = dr.zeros(mi.BSDFSample3f)
        bs.wo = wo
        bs.eta = 1.0
        bs.sampled_type = mi.UInt32(+mi.BSDFFlags.GlossyReflection)
        bs.sampled_component = mi.UInt32(0)
        f, h, ok = self.value(si, wo, active & (dr.dot(wi, m) > 0))
        pdf = self.normal_pdf(wi, h, lam_i) / (4.0 * dr.maximum(dr.dot(wo, h), _TINY))
        ok = ok & (pdf > 0)
        bs.pdf = dr.select(ok, pdf, 0.0)
        return bs, dr.select(ok, f / dr.maximum(pdf, _TINY), 0.0)

    def traverse(self, callback):
        pass

    def parameters_changed(self, keys):
        pass

    def to_string(self):
        return (f"ThinFilmMicrofacetBSDF[filename={self.filename!r}, lobes="
                f"{list(zip(self.weights, self.alphas))}]")


@lru_cache(maxsize=None)
def bsdf_class(variant: str):
    """The BSDF class for ``variant`` (Mitsuba classes are per variant; set it first)."""
    check_variant(variant)
    # nanobind classes take one base: the model's methods are copied into the subclass
    methods = {k: v for k, v in vars(ThinFilmModel).items()
               if k not in ("__dict__", "__weakref__")}
    return type("ThinFilmMicrofacetBSDF", (mi.BSDF,), methods)


def register() -> None:
    """Register :data:`PLUGIN` with Mitsuba for the variant that is set (idempotent)."""
    variant = mi.variant()
    if variant is None:
        raise InputError("set a Mitsuba variant first (mi.set_variant)", param="variant")
    cls = bsdf_class(variant)
    mi.register_bsdf(PLUGIN, lambda props: cls(props))
