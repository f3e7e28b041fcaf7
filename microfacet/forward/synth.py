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

Imaging variations (:class:`~microfacet.forward.synth_params.SynthParams`, all off by
default): other facet shapes, rounded facets, terraces, pits, scratches, a measured height
map instead of facets, stains, dust (:mod:`~microfacet.forward.relief`), tilt-dependent
brightness, vignetting, white balance, drift between slices
(:mod:`~microfacet.forward.imaging`), JPEG slices, other optical constants.
docs/synthetic-stacks.md lists them.

The default scene is drawn from one ``numpy.random.Generator`` seeded with ``seed``, the
noise and each variation from their own (``[seed, k]``); the same parameters and seed give
the same bytes.
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
from .imaging import drift_offsets_px, shift_image
from .relief import FEATURE_CODES
from .scene import STREAMS, render_scene
from .synth_params import (
    MAX_SLICES,
    SynthParams,
    ThicknessComponent,
    TiltLobe,
    parse_variation,
)

cv2 = load("cv2")

__all__ = ["MAX_SLICES", "PRESETS", "SynthResult", "generate_stack", "parse_variation", "preset"]

log = logging.getLogger(__name__)

#: Peak memory of :func:`generate_stack` ≈ base + per pixel × H × W (the blur ladder of ~12
#: float32 RGB copies dominates), set just above what ``/usr/bin/time -f %M microfacet synth``
#: measured: 248 and 513 MB at 0.26 and 1.05 MP (≈ 160 MB + 335 B/px).
MEMORY_BASE_BYTES = 180 << 20
MEMORY_BYTES_PER_PIXEL = 360
#: Files of ``truth/`` (besides ``params.json``).
TRUTH_ARRAYS = ("height_um", "tilt_deg", "azimuth_deg", "thickness_nm", "visible", "clipped",
                "region_id", "groove", "facet_id", "feature")


def _p(name, **kw):
    return SynthParams(preset=name, **kw)


#: Named presets (README, docs/synthetic-stacks.md): each a starting point;
#: ``preset(name, **overrides)`` or ``dataclasses.replace`` changes any field.
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
    """Parameters of a named preset, with field overrides (e.g. ``seed=3, n_slices=40``).

    Raises
    ------
    ValueError
        An unknown preset (``preset``), an unknown field, or a value out of range (naming
        the field).
    """
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
    Layout: ``stack.json``, ``slices/000.png`` … (``.jpg`` with ``jpeg_quality``),
    ``truth/height_um.npy``, ``truth/tilt_deg.npy``, ``truth/azimuth_deg.npy``,
    ``truth/thickness_nm.npy``, ``truth/visible.npy``, ``truth/clipped.npy``,
    ``truth/region_id.npy``, ``truth/groove.npy`` (fraction of each pixel covered by a dark
    step wall), ``truth/facet_id.npy`` (int32 facet cell), ``truth/feature.npy`` (uint8:
    0 facet, 1 pit, 2 scratch, 3 dust, 4 stain), ``truth/all_in_focus.png`` (the noise-free sharp
    image with every deterministic imaging effect: brightness, grooves, dust, vignetting,
    white balance, clipping; no noise, blur, drift or JPEG) and ``truth/params.json``
    (:func:`_truth_summary`). With drift, the truth is in the frame of the slices' mean
    position. Memory: a ladder of ~12 blurred copies of the image, independent of the
    slice count.

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
    names = [f"slices/{k:03d}{p.slice_suffix}" for k in range(p.n_slices)]
    drift = np.zeros((p.n_slices, 2))
    if p.drift_px_per_slice > 0:
        drift = drift_offsets_px(np.random.default_rng([p.seed, STREAMS["drift"]]), p.n_slices,
                                 step_px=p.drift_px_per_slice)
    encode = () if p.jpeg_quality is None else (cv2.IMWRITE_JPEG_QUALITY, p.jpeg_quality)

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
            if p.drift_px_per_slice > 0:
                img = shift_image(img, *drift[k])
            img = apply_sensor(img, p, rng_noise)
            code = srgb_encode(img, dtype=dtype)
            write_image(tmp / names[k], code, params=encode)
            if progress is not None:
                progress(k + 1, p.n_slices)
        t_slices = time.perf_counter() - t0 - t_scene
        truth = tmp / "truth"
        arrays = {"height_um": scene.height_um, "tilt_deg": scene.tilt_deg,
                  "azimuth_deg": scene.azimuth_deg, "thickness_nm": scene.thickness_nm,
                  "visible": scene.visible, "clipped": clipped, "region_id": scene.region_id,
                  "groove": scene.groove, "facet_id": scene.facet_id, "feature": scene.feature}
        for name in TRUTH_ARRAYS:
            np.save(truth / f"{name}.npy", arrays[name])
        sharp = srgb_encode(np.clip(scene.linear_rgb, 0, 1), dtype=np.uint8)
        write_image(truth / "all_in_focus.png", sharp)
        truth_meta = {"format": "microfacet-synth-truth/1", "params": p.to_json(),
                      "z_um": [float(v) for v in z], **_truth_summary(scene, p, clipped=clipped),
                      "drift_px": drift.round(6).tolist()}
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


def _truth_summary(scene, p, *, clipped) -> dict:
    """What ``truth/params.json`` records about a scene besides its parameters.

    Keys: ``regions`` (per thickness region: ``id``, ``component``, ``thickness_nm`` drawn
    for the region, ``mean_thickness_nm`` over its pixels, ``area_fraction``),
    ``populations`` (the mixture components with at least one region: ``component``,
    ``mean_nm``, ``sd_nm``, ``n_regions``, ``area_fraction`` — their weights by area —
    and ``mean_thickness_nm``), ``lobes`` (the true tilt lobes, weights normalised),
    ``visibility_limit_deg`` (asin(NA)/2), ``visible_fraction``, ``clipped_fraction``,
    ``groove_fraction`` (pixels with a groove wall), ``feature_codes`` and
    ``feature_fractions``, ``variations`` (the imaging variations switched on) and
    ``slice_format``. With ``relief_file``: ``lobes`` is empty (the tilts are the measured
    surface's, ``tilt_deg.npy``) and ``relief`` records the map
    (:func:`~microfacet.forward.relief.measured_relief`).
    """
    rid = scene.region_id.ravel()
    nr = scene.region_thickness_nm.size
    area = np.bincount(rid, minlength=nr).astype(np.float64)
    mean_d = np.bincount(rid, scene.thickness_nm.ravel().astype(np.float64),
                         minlength=nr) / np.maximum(area, 1)
    frac = area / rid.size
    comp = np.asarray(scene.region_component)
    regions = [{"thickness_nm": float(t), "component": int(c), "id": i,
                "mean_thickness_nm": float(mean_d[i]), "area_fraction": float(frac[i])}
               for i, (t, c) in enumerate(zip(scene.region_thickness_nm, comp))]
    pops = []
    for k, c in enumerate(p.thickness):
        mine = comp == k
        if mine.any():
            a = float(frac[mine].sum())
            pops.append({"component": k, "mean_nm": c.mean_nm, "sd_nm": c.sd_nm,
                         "n_regions": int(mine.sum()), "area_fraction": a,
                         "mean_thickness_nm": float((mean_d * frac)[mine].sum() / a)})
    wsum = sum(lb.weight for lb in p.tilt_lobes)
    feature = scene.feature if scene.feature is not None else np.zeros(rid.size, np.uint8)
    counts = np.bincount(feature.ravel(), minlength=len(FEATURE_CODES)) / rid.size
    lobes = [] if p.measured else [{"weight": lb.weight / wsum, "sd_deg": lb.sd_deg}
                                   for lb in p.tilt_lobes]
    variations = {k: list(v) if isinstance(v, tuple) else v
                  for k, v in p.variations_on().items()}
    extra = {}
    if p.measured:
        variations["relief_file"] = Path(p.relief_file).name
        extra["relief"] = scene.relief
    return {"regions": regions, "populations": pops, "lobes": lobes,
            "visibility_limit_deg": p.max_tilt_deg,
            "visible_fraction": float(scene.visible.mean()),
            "clipped_fraction": float(clipped.mean()),
            "groove_fraction": float(np.mean(scene.groove > 0)),
            "feature_codes": dict(FEATURE_CODES),
            "feature_fractions": {n: float(counts[c]) for n, c in FEATURE_CODES.items()},
            "variations": variations, "slice_format": p.slice_suffix[1:], **extra}


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
