"""Synthetic microscope focus stacks of anodized titanium, with ground truth.

The image model is the one of the stack format (``docs/stack-format.md``): coaxial light,
camera on the optical axis; a flat facet whose normal is tilted by θ from the axis is seen at
incidence θ, so its colour is the thin-film reflectance R(λ; θ, d) of its oxide thickness d
on titanium under the illuminant, times the exposure, in sRGB. Facets tilted past
asin(NA)/2 send the reflection outside the objective and are dark; overexposed channels clip.

Scene (seed §3.2-3.3, Fig. 13)
-------------------------------
* **Surface**: macro waviness (roll-dull structure; a sum of random Fourier modes with
  wavelengths of tens of µm) carrying planar microfacets 1-3 µm across (Voronoi cells).
  Each facet is the plane through the macro surface at its seed point, with the macro slope
  plus its own slope, whose tilt follows a mixture of zero-mean lobes (tilt = |N(0, σ²)|
  in each slope direction... see :class:`TiltLobe`) and uniform azimuth. The true tilt of a
  pixel is the tilt of its facet plane.
* **Oxide thickness**: regions (Voronoi cells tens of µm across) whose thickness is drawn
  from a Gaussian mixture (the seed's ND sample: three populations between 100 and 160 nm),
  plus a smooth fine variation inside regions (and, in the ``grainy`` preset, a per-facet
  offset).
* **Grooves**: the height steps between facets have walls steeper than the acceptance
  angle; they image as dark lines whose width follows the step height.
* **Focus stack**: slice k at stage height z_k shows every pixel blurred by a Gaussian of
  σ = sqrt(σ_diff² + (½ |z_k − h| tan(asin NA))²) (geometric defocus disc of radius
  |Δz| tan α, σ ≈ radius / 2; diffraction σ_diff = 0.21 λ/NA at 550 nm), evaluated by
  blending a precomputed ladder of blurred images (memory independent of the slice count).
* **Sensor**: shot noise (Gaussian approximation, ``full_well_e`` electrons at signal 1),
  read noise, clipping, sRGB encoding, 8- or 16-bit PNG slices.

Everything is drawn from one ``numpy.random.Generator`` seeded with ``seed``; the same
parameters and seed give the same bytes.
"""

from __future__ import annotations

import dataclasses
import json
import logging
import math
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..colour.srgb import srgb_encode
from ..core.lazy import load
from ..io.images import write_image
from ..io.limits import check_memory
from ..io.outdir import atomic_output_dir
from ..io.stack import write_stack_json
from ..optics.constants import DEFAULT_FILM, DEFAULT_SUBSTRATE
from .scene import render_scene

cv2 = load("cv2")

__all__ = [
    "apply_sensor",
    "PRESETS",
    "SynthParams",
    "SynthResult",
    "ThicknessComponent",
    "TiltLobe",
    "generate_stack",
    "preset",
    "render_scene",
]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class TiltLobe:
    """A zero-mean lobe of facet tilts: slopes (tan θ) in x and y are N(0, tan(sd_deg)²).

    The tilt θ then has a Rayleigh-distributed tangent (a Beckmann-like lobe whose slope
    standard deviation per axis is tan(sd_deg)); its mode in slope space is 0°.
    """

    weight: float
    sd_deg: float


@dataclass(frozen=True)
class ThicknessComponent:
    """One population of oxide thickness: N(mean_nm, sd_nm²) with a mixture weight."""

    weight: float
    mean_nm: float
    sd_nm: float


@dataclass(frozen=True)
class SynthParams:
    """Every parameter of a synthetic stack (all lengths in µm unless the name says nm).

    Attributes
    ----------
    height_px, width_px : int
        Image size.
    n_slices : int
        Focal planes.
    pixel_size_um : float
        Lateral pixel size on the sample (the seed's microscope: 347.8 µm / 1600 px ≈ 0.217).
    numerical_aperture : float
        Objective NA; facets tilted past asin(NA)/2 are dark.
    facet_size_um : float
        Mean facet diameter (Voronoi cells), 1-3 µm in the seed.
    tilt_lobes : tuple of TiltLobe
        Mixture of zero-mean facet-slope lobes.
    waviness_amplitude_um, waviness_wavelength_um : float
        RMS height and typical wavelength of the macro (roll-dull) waviness.
    thickness : tuple of ThicknessComponent
        Gaussian mixture of region thicknesses.
    region_size_um : float
        Mean diameter of the thickness regions.
    thickness_fine_sd_nm, thickness_fine_scale_um : float
        Smooth thickness variation inside regions (SD and correlation length).
    thickness_facet_sd_nm : float
        Per-facet thickness offset (SD; 0 in most presets): anodic growth can depend on
        the grain underneath. It mimics tilt in colour (10° ≈ 0.3 nm), which is why the
        ``grainy`` preset has it: the hard case where tilt cannot come from colour.
    groove_wall_deg : float
        Slope of the walls of the height steps between facets. Walls steeper than
        asin(NA)/2 reflect outside the objective, so a step of height Δh images as a dark
        groove of projected width Δh / tan(groove_wall_deg) (pixel coverage blended); 0
        disables grooves. They give the images the texture focus needs.
    exposure : float
        Model linear sRGB → image linear sRGB.
    dark_level : float
        Linear signal of facets outside the objective's acceptance (relative to white).
    full_well_e : float or None
        Electrons at signal 1 (shot noise); None for no shot noise.
    read_noise : float
        Read-noise SD in linear signal units.
    bit_depth : {8, 16}
    z_margin_um : float
        Extra focus range below the lowest and above the highest point.
    write_exposure : bool
        Write ``exposure`` into stack.json (else the analyser must estimate it).
    film, substrate, illuminant : str
    seed : int
    """

    height_px: int = 256
    width_px: int = 256
    n_slices: int = 24
    pixel_size_um: float = 0.216
    numerical_aperture: float = 0.8
    facet_size_um: float = 2.0
    tilt_lobes: tuple = (TiltLobe(1.0, 4.0),)
    waviness_amplitude_um: float = 0.5
    waviness_wavelength_um: float = 40.0
    thickness: tuple = (ThicknessComponent(1.0, 51.0, 1.0),)
    region_size_um: float = 25.0
    thickness_fine_sd_nm: float = 0.3
    thickness_facet_sd_nm: float = 0.0
    groove_wall_deg: float = 45.0
    thickness_fine_scale_um: float = 3.0
    exposure: float = 1.0
    dark_level: float = 0.02
    full_well_e: float | None = 8000.0
    read_noise: float = 0.002
    bit_depth: int = 8
    z_margin_um: float = 1.0
    write_exposure: bool = False
    film: str = DEFAULT_FILM
    substrate: str = DEFAULT_SUBSTRATE
    illuminant: str = "D65"
    seed: int = 0
    preset: str = "custom"

    @property
    def max_tilt_deg(self) -> float:
        """Largest facet tilt whose reflection enters the objective: asin(NA)/2."""
        return math.degrees(math.asin(self.numerical_aperture)) / 2.0

    def validate(self) -> None:
        """Raise ValueError naming the first parameter out of range."""
        checks = [
            ("height_px", self.height_px >= 16), ("width_px", self.width_px >= 16),
            ("n_slices", 1 <= self.n_slices <= MAX_SLICES),
            ("pixel_size_um", self.pixel_size_um > 0),
            ("numerical_aperture", 0 < self.numerical_aperture < 1),
            ("facet_size_um", self.facet_size_um > 0),
            ("tilt_lobes", len(self.tilt_lobes) > 0
             and all(lb.weight > 0 and 0 <= lb.sd_deg < 60 for lb in self.tilt_lobes)),
            ("thickness", len(self.thickness) > 0
             and all(c.weight > 0 and c.mean_nm >= 0 and c.sd_nm >= 0 for c in self.thickness)),
            ("region_size_um", self.region_size_um > 0),
            ("thickness_facet_sd_nm", self.thickness_facet_sd_nm >= 0),
            ("groove_wall_deg", 0 <= self.groove_wall_deg < 90),
            ("thickness_fine_sd_nm", self.thickness_fine_sd_nm >= 0),
            ("exposure", self.exposure > 0), ("bit_depth", self.bit_depth in (8, 16)),
            ("read_noise", self.read_noise >= 0),
            ("full_well_e", self.full_well_e is None or self.full_well_e > 0),
            ("z_margin_um", self.z_margin_um >= 0),
        ]
        for name, ok in checks:
            if not ok:
                raise ValueError(f"{name}: out of range ({getattr(self, name)!r})")

    def to_json(self) -> dict:
        d = dataclasses.asdict(self)
        d["max_tilt_deg"] = self.max_tilt_deg
        return d


#: Most slices a synthetic stack may have.
MAX_SLICES = 10_000
#: Peak memory of :func:`generate_stack` ≈ base + per pixel × H × W (the blur ladder of ~12
#: float32 RGB copies dominates), set just above what ``/usr/bin/time -f %M microfacet synth``
#: measured: 248 and 513 MB at 0.26 and 1.05 MP (≈ 160 MB + 335 B/px).
MEMORY_BASE_BYTES = 180 << 20
MEMORY_BYTES_PER_PIXEL = 360


def _p(name, **kw):
    return SynthParams(preset=name, **kw)


#: Named presets (see README): each a starting point; ``dataclasses.replace`` changes any field.
PRESETS: dict[str, SynthParams] = {
    # Cold-rolled SD sheet: smooth, one blue film (the seed's sample 2, ~51 nm).
    "sd": _p("sd", tilt_lobes=(TiltLobe(1.0, 3.0),), waviness_amplitude_um=0.3,
             thickness=(ThicknessComponent(1.0, 51.0, 0.8),)),
    # Roll-dull ND sheet: rough, two tilt lobes (narrow + wide, both mode 0°),
    # three thickness populations between 100 and 160 nm (seed Figs. 18-19).
    "nd": _p("nd", tilt_lobes=(TiltLobe(0.6, 3.0), TiltLobe(0.4, 9.0)),
             waviness_amplitude_um=1.2, waviness_wavelength_um=70.0,
             thickness=(ThicknessComponent(0.3, 112.0, 3.0), ThicknessComponent(0.45, 130.0, 3.0),
                        ThicknessComponent(0.25, 149.0, 3.0)),
             region_size_um=18.0),
    # Second-order film (> 200 nm): colours repeat, thickness is ambiguous.
    "thick": _p("thick", tilt_lobes=(TiltLobe(0.6, 3.0), TiltLobe(0.4, 8.0)),
                thickness=(ThicknessComponent(1.0, 235.0, 2.0),)),
    # Steep facets near the NA cut-off (asin(0.8)/2 = 26.6°): many dark pixels.
    "steep": _p("steep", tilt_lobes=(TiltLobe(1.0, 16.0),), waviness_amplitude_um=1.0,
                waviness_wavelength_um=60.0,
                thickness=(ThicknessComponent(1.0, 130.0, 2.0),)),
    # Very thin film (< 20 nm): pale, low saturation, little colour information.
    "thin": _p("thin", thickness=(ThicknessComponent(1.0, 14.0, 1.0),)),
    # Per-facet thickness offsets (1.5 nm): colour cannot separate tilt from thickness.
    "grainy": _p("grainy", tilt_lobes=(TiltLobe(0.6, 3.0), TiltLobe(0.4, 9.0)),
                 thickness=(ThicknessComponent(1.0, 130.0, 3.0),), thickness_facet_sd_nm=1.5),
    # Heavy shot and read noise.
    "noisy": _p("noisy", tilt_lobes=(TiltLobe(0.6, 3.0), TiltLobe(0.4, 9.0)),
                thickness=(ThicknessComponent(1.0, 130.0, 3.0),), full_well_e=150.0,
                read_noise=0.02),
    # Over-exposure: the gold (120 nm) regions clip, the magenta (145 nm) ones do not.
    "overexposed": _p("overexposed", thickness=(ThicknessComponent(0.5, 120.0, 3.0),
                                                ThicknessComponent(0.5, 145.0, 3.0)),
                      exposure=1.5),
    # 16-bit slices.
    "16bit": _p("16bit", tilt_lobes=(TiltLobe(0.6, 3.0), TiltLobe(0.4, 9.0)),
                thickness=(ThicknessComponent(0.5, 120.0, 3.0),
                           ThicknessComponent(0.5, 140.0, 3.0)),
                bit_depth=16),
}


def preset(name: str, **overrides) -> SynthParams:
    """Parameters of a named preset, with field overrides (e.g. ``seed=3, n_slices=40``)."""
    if name not in PRESETS:
        raise ValueError(f"preset: unknown preset {name!r}; known: {', '.join(PRESETS)}")
    fields = {f.name for f in dataclasses.fields(SynthParams)}
    for k in overrides:
        if k not in fields:
            raise ValueError(f"{k}: not a synthetic-stack parameter")
    p = dataclasses.replace(PRESETS[name], **overrides)
    p.validate()
    return p


# ------------------------------------------------------------------------------- stack


def _blur_ladder(img, sigmas):
    """``img`` blurred with each σ in increasing ``sigmas`` (px), built incrementally."""
    out = np.empty((len(sigmas),) + img.shape, dtype=np.float32)
    cur, cur_s = img.astype(np.float32), 0.0
    for i, s in enumerate(sigmas):
        ds = math.sqrt(max(s * s - cur_s * cur_s, 0.0))
        if ds > 1e-3:
            cur = cv2.GaussianBlur(cur, (0, 0), sigmaX=ds, borderType=cv2.BORDER_REFLECT)
        cur_s = s
        out[i] = cur
    return out


def defocus_sigma_px(dz_um, p: SynthParams):
    """Gaussian blur SD in pixels at defocus ``dz_um`` (see the module docstring)."""
    tan_a = math.tan(math.asin(p.numerical_aperture))
    diff = 0.21 * 0.55 / p.numerical_aperture / p.pixel_size_um
    geo = 0.5 * np.abs(dz_um) * tan_a / p.pixel_size_um
    return np.sqrt(diff * diff + geo * geo)


def slice_positions_um(p: SynthParams, height_um) -> np.ndarray:
    """Uniform stage heights covering the surface with ``z_margin_um`` either side."""
    lo = float(np.nanmin(height_um)) - p.z_margin_um
    hi = float(np.nanmax(height_um)) + p.z_margin_um
    if p.n_slices == 1:
        return np.array([0.5 * (lo + hi)])
    return np.linspace(lo, hi, p.n_slices)


@dataclass
class SynthResult:
    """What :func:`generate_stack` wrote."""

    path: Path
    params: SynthParams
    z_um: np.ndarray
    timings_s: dict = field(default_factory=dict)


def generate_stack(out, params: SynthParams, *, overwrite=False, progress=None) -> SynthResult:
    """Write a synthetic stack (stack format ``microfacet-stack/1``) with ground truth.

    Parameters
    ----------
    out : path-like
        Output folder; written atomically (appears whole or not at all).
    params : SynthParams
    overwrite : bool
        Replace an existing folder.
    progress : callable, optional
        Called as ``progress(done, total)`` after each slice.

    Returns
    -------
    SynthResult

    Notes
    -----
    Layout: ``stack.json``, ``slices/000.png`` …, ``truth/height_um.npy``,
    ``truth/tilt_deg.npy``, ``truth/azimuth_deg.npy``, ``truth/thickness_nm.npy``,
    ``truth/visible.npy``, ``truth/clipped.npy``, ``truth/region_id.npy``,
    ``truth/groove.npy`` (fraction of each pixel covered by a dark step wall),
    ``truth/all_in_focus.png`` (noise-free sharp image) and ``truth/params.json``.
    Memory: a ladder of ~12 blurred copies of the image, independent of the slice count.

    Examples
    --------
    >>> from microfacet.forward.synth import generate_stack, preset
    >>> r = generate_stack("/tmp/nd-demo", preset("nd", seed=1), overwrite=True)  # doctest: +SKIP
    """
    p = params
    p.validate()
    check_memory(MEMORY_BASE_BYTES + MEMORY_BYTES_PER_PIXEL * p.height_px * p.width_px,
                 f"a synthetic stack of {p.width_px}x{p.height_px} pixels", param="height_px")
    t0 = time.perf_counter()
    scene = render_scene(p)
    t_scene = time.perf_counter() - t0
    z = slice_positions_um(p, scene.height_um)

    sig_max = float(defocus_sigma_px(np.max(np.abs(z[:, None] - np.array(
        [scene.height_um.min(), scene.height_um.max()])[None, :])), p))
    sig_min = float(defocus_sigma_px(0.0, p))
    n_lv = max(2, int(math.ceil(math.log(max(sig_max / sig_min, 1.0001), math.sqrt(2)))) + 1)
    sigmas = sig_min * math.sqrt(2) ** np.arange(n_lv)
    log_s = np.log(sigmas)
    ladder = _blur_ladder(scene.linear_rgb, sigmas)
    rng_noise = np.random.default_rng([p.seed, 1])
    rows, cols = np.indices(scene.height_um.shape)
    dtype = np.uint8 if p.bit_depth == 8 else np.uint16
    clipped = np.any(scene.linear_rgb >= 1.0, axis=-1)
    names = [f"slices/{k:03d}.png" for k in range(p.n_slices)]

    with atomic_output_dir(out, kind="synthetic stack", overwrite=overwrite,
                           expected_bytes=p.height_px * p.width_px * (3 * p.n_slices + 40)
                           ) as tmp:
        (tmp / "slices").mkdir()
        (tmp / "truth").mkdir()
        for k, zk in enumerate(z):
            s = defocus_sigma_px(zk - scene.height_um.astype(np.float64), p)
            u = np.clip((np.log(s) - log_s[0]) / (log_s[1] - log_s[0]), 0, n_lv - 1 - 1e-9)
            i0 = u.astype(np.intp)
            f = (u - i0).astype(np.float32)[..., None]
            img = ladder[i0, rows, cols] * (1 - f) + ladder[i0 + 1, rows, cols] * f
            img = apply_sensor(img, p, rng_noise)
            code = srgb_encode(img, dtype=dtype)
            write_image(tmp / names[k], code)
            if progress is not None:
                progress(k + 1, p.n_slices)
        t_slices = time.perf_counter() - t0 - t_scene
        truth = tmp / "truth"
        np.save(truth / "height_um.npy", scene.height_um)
        np.save(truth / "tilt_deg.npy", scene.tilt_deg)
        np.save(truth / "azimuth_deg.npy", scene.azimuth_deg)
        np.save(truth / "thickness_nm.npy", scene.thickness_nm)
        np.save(truth / "visible.npy", scene.visible)
        np.save(truth / "clipped.npy", clipped)
        np.save(truth / "region_id.npy", scene.region_id)
        np.save(truth / "groove.npy", scene.groove)
        sharp = srgb_encode(np.clip(scene.linear_rgb, 0, 1), dtype=np.uint8)
        write_image(truth / "all_in_focus.png", sharp)
        truth_meta = {
            "format": "microfacet-synth-truth/1",
            "params": p.to_json(),
            "z_um": [float(v) for v in z],
            "regions": [{"thickness_nm": float(t), "component": int(c)}
                        for t, c in zip(scene.region_thickness_nm, scene.region_component)],
            "visible_fraction": float(scene.visible.mean()),
            "clipped_fraction": float(clipped.mean()),
        }
        (truth / "params.json").write_text(json.dumps(truth_meta, indent=1))
        optional = {"illumination": {"geometry": "coaxial",
                                     "numerical_aperture": p.numerical_aperture},
                    "film": p.film, "substrate": p.substrate, "illuminant": p.illuminant,
                    "color_space": "sRGB", "synthetic": {"preset": p.preset, "seed": p.seed}}
        if p.write_exposure:
            optional["exposure"] = p.exposure
        write_stack_json(tmp, pixel_size_um=p.pixel_size_um, slices=names,
                         z_um=[float(v) for v in z], **optional)
    timings = {"scene": t_scene, "slices": t_slices, "total": time.perf_counter() - t0}
    log.info("synthetic stack %s: %d slices %dx%d in %.2f s", out, p.n_slices, p.height_px,
             p.width_px, timings["total"])
    return SynthResult(Path(out), p, z, timings)


def apply_sensor(img, p, rng):
    """Shot and read noise (Gaussian approximations) and clipping of a linear image.

    Parameters
    ----------
    img : ndarray of float32 (H, W, 3)
        Linear RGB, 1 = full well.
    p : SynthParams
        ``full_well_e`` (shot noise, electrons at full scale) and ``read_noise`` (fraction
        of full scale).
    rng : numpy.random.Generator

    Returns
    -------
    ndarray of float32 (H, W, 3), in [0, 1]
    """
    img = np.clip(img, 0.0, None)
    var = np.zeros_like(img)
    if p.full_well_e:
        var += img / np.float32(p.full_well_e)
    if p.read_noise:
        var += np.float32(p.read_noise ** 2)
    if p.full_well_e or p.read_noise:
        img = img + np.sqrt(var) * rng.standard_normal(img.shape, dtype=np.float32)
    return np.clip(img, 0.0, 1.0)
