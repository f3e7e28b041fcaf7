"""The synthetic scene: a surface of microfacets on macro waviness, oxide regions, and the
noise-free image the microscope would see (:func:`render_scene`).

The facets are planar Voronoi cells by default; the variations of
:class:`~microfacet.forward.synth_params.SynthParams` add other cell shapes, rounded facets,
terraces, pits and scratches, or replace the facets by a measured height map
(:mod:`microfacet.forward.relief`), stains, dust, tilt-dependent brightness, vignetting and
white balance (:mod:`microfacet.forward.imaging`). See
:mod:`microfacet.forward.synth` for the stack written from a scene.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..colour.table import build_colour_table
from ..core.lazy import load
from .imaging import apply_white_balance, pupil_fraction, pupil_limit_deg, vignetting_factor
from .relief import (
    FEATURE_CODES,
    Carving,
    carve_pits,
    carve_scratches,
    dome_relief,
    dust_layer,
    measured_relief,
    shaped_cells,
    smooth_field,
    stain_layer,
    terrace_offsets_um,
)

ndimage = load("scipy.ndimage")

__all__ = ["Scene", "render_scene"]

#: Random streams ``[seed, k]`` of the variations (k = 1 is the sensor noise's).
STREAMS = {"facets": 2, "terraces": 3, "pits": 4, "scratches": 5, "dust": 6, "drift": 7,
           "stains": 8, "relief": 9}


@dataclass
class Scene:
    """Ground truth of one synthetic field (all H×W)."""

    height_um: np.ndarray
    tilt_deg: np.ndarray
    azimuth_deg: np.ndarray
    thickness_nm: np.ndarray
    visible: np.ndarray
    facet_id: np.ndarray
    region_id: np.ndarray
    region_thickness_nm: np.ndarray  # per region, before fine variation
    region_component: np.ndarray     # mixture component of each region
    groove: np.ndarray               # fraction of each pixel covered by a dark step wall
    linear_rgb: np.ndarray           # H×W×3 sharp image, linear, every deterministic imaging
    #                                  effect applied (exposure, brightness, dust, vignetting,
    #                                  white balance), unclipped, float32
    feature: np.ndarray | None = None  # uint8 FEATURE_CODES: facet, pit, scratch, dust, stain
    dust: np.ndarray | None = None     # dust coverage 0-1 (float32)
    stain: np.ndarray | None = None    # stain coverage 0-1 (float32)
    relief: dict | None = None         # the measured map's record (relief_file), else None


def _voronoi(rng, shape, cell_px):
    """Labels of a Voronoi tessellation with mean cell diameter ``cell_px`` and its seeds."""
    h, w = shape
    n = max(1, int(round(h * w / (math.pi * (cell_px / 2) ** 2))))
    ys = rng.integers(0, h, n)
    xs = rng.integers(0, w, n)
    flat = np.unique(ys * w + xs)  # unique, raster order
    ys, xs = flat // w, flat % w
    seeds = np.ones(shape, dtype=bool)
    seeds[ys, xs] = False
    ids = np.full(shape, -1, dtype=np.int64)
    ids[ys, xs] = np.arange(ys.size)
    _, (iy, ix) = ndimage.distance_transform_edt(seeds, return_indices=True)
    return ids[iy, ix], ys, xs


def _waviness(rng, p, yy_um, xx_um):
    """Macro height field and its gradient: random Fourier modes around a wavelength."""
    n_modes = 12
    k0 = 2 * math.pi / p.waviness_wavelength_um
    k = k0 * rng.uniform(0.6, 1.6, n_modes)
    ang = rng.uniform(0, 2 * math.pi, n_modes)
    phase = rng.uniform(0, 2 * math.pi, n_modes)
    amp = p.waviness_amplitude_um * math.sqrt(2.0 / n_modes)
    hgt = np.zeros_like(yy_um)
    gy = np.zeros_like(yy_um)
    gx = np.zeros_like(yy_um)
    for kk, a, ph in zip(k, ang, phase):
        kx, ky = kk * math.cos(a), kk * math.sin(a)
        arg = kx * xx_um + ky * yy_um + ph
        hgt += amp * np.sin(arg)
        c = amp * np.cos(arg)
        gx += c * kx
        gy += c * ky
    return hgt, gy, gx


def render_scene(p, *, table=None) -> Scene:
    """Draw the surface, the thickness field and the sharp colour image (no blur, no noise).

    Parameters
    ----------
    p : SynthParams
    table : ColourTable, optional
        Colour table covering the scene (built when not given).

    Returns
    -------
    Scene

    Notes
    -----
    The default scene draws everything from one stream seeded with ``p.seed``. Each
    variation draws from its own stream (``[seed, k]``), and the alternative facet cells
    consume the default cells' draws first, so switching a variation on changes what it
    should (the facets, a feature, the image) and leaves the other fields as they were.
    """
    p.validate()
    rng = np.random.default_rng(p.seed)
    shape = (p.height_px, p.width_px)
    px = p.pixel_size_um
    yy, xx = np.mgrid[0:shape[0], 0:shape[1]].astype(np.float64) * px

    # Surface: macro waviness + planar facets through it.
    macro, mgy, mgx = _waviness(rng, p, yy, xx)
    w = np.array([lb.weight for lb in p.tilt_lobes], dtype=np.float64)
    if p.default_facets:
        facet, fy, fx = _voronoi(rng, shape, p.facet_size_um / px)
        frng = rng
    else:
        _skip_default_facets(rng, shape, p.facet_size_um / px, w)
        frng = np.random.default_rng([p.seed, STREAMS["facets"]])
        facet, fy, fx = shaped_cells(frng, shape, p)
    nf = fy.size
    lobe = frng.choice(len(p.tilt_lobes), size=nf, p=w / w.sum())
    slope_sd = np.tan(np.deg2rad([lb.sd_deg for lb in p.tilt_lobes]))[lobe]
    sy = frng.standard_normal(nf) * slope_sd + mgy[fy, fx]
    sx = frng.standard_normal(nf) * slope_sd + mgx[fy, fx]
    cy, cx = fy * px, fx * px
    relief = None
    if p.measured:
        # A measured surface replaces facets and waviness (their draws are still made, so
        # the regions below are those of the same seed without it); its slopes are central
        # differences of the resampled map, the facet cells only label it.
        height, relief = measured_relief(np.random.default_rng([p.seed, STREAMS["relief"]]),
                                         shape, p)
        mgy, mgx = np.gradient(height, px)
        sy = sx = None
    else:
        height = (macro[fy, fx][facet] + sy[facet] * (yy - cy[facet])
                  + sx[facet] * (xx - cx[facet]))
    if p.terrace_step_um > 0:
        trng = np.random.default_rng([p.seed, STREAMS["terraces"]])
        height += terrace_offsets_um(trng, shape, fy, fx, p)[facet]
    dgy = dgx = None
    if p.facet_dome_deg > 0:
        dz, dgy, dgx = dome_relief(yy, xx, facet, cy, cx, p)
        height += dz
    groove_height = height
    feature = np.zeros(shape, dtype=np.uint8)
    if p.pit_density_per_mm2 > 0 or p.scratch_density_per_mm2 > 0:
        carving = Carving.empty(shape)
        if p.pit_density_per_mm2 > 0:
            carve_pits(np.random.default_rng([p.seed, STREAMS["pits"]]), shape, p, carving)
        if p.scratch_density_per_mm2 > 0:
            carve_scratches(np.random.default_rng([p.seed, STREAMS["scratches"]]), shape, p,
                            carving)
        height = height + carving.dz_um
        dgy = carving.dgy if dgy is None else dgy + carving.dgy
        dgx = carving.dgx if dgx is None else dgx + carving.dgx
        feature = carving.feature
    if p.measured:
        tilt, azimuth = _tilt_azimuth(mgy if dgy is None else mgy + dgy,
                                      mgx if dgx is None else mgx + dgx)
    elif dgy is None:
        tilt, azimuth = (a[facet] for a in _tilt_azimuth(sy, sx))
    else:
        tilt, azimuth = _tilt_azimuth(sy[facet] + dgy, sx[facet] + dgx)

    # Thickness regions from the mixture, plus smooth fine variation.
    region, _, _ = _voronoi(rng, shape, p.region_size_um / px)
    nr = int(region.max()) + 1
    cw = np.array([c.weight for c in p.thickness], dtype=np.float64)
    comp = rng.choice(len(p.thickness), size=nr, p=cw / cw.sum())
    means = np.array([c.mean_nm for c in p.thickness])[comp]
    sds = np.array([c.sd_nm for c in p.thickness])[comp]
    region_d = np.maximum(means + sds * rng.standard_normal(nr), 0.0)
    fine = smooth_field(rng, shape, p.thickness_fine_scale_um / px) * p.thickness_fine_sd_nm
    facet_dd = frng.standard_normal(nf) * p.thickness_facet_sd_nm
    thickness = np.maximum(region_d[region] + fine + facet_dd[facet], 0.0)

    visible = tilt <= p.max_tilt_deg
    if table is None:
        table = _table_for(p, thickness)
    if p.illumination_fill == 0:
        rgb = table.linear_rgb_at(np.where(visible, tilt, 0.0), thickness).astype(np.float64)
        rgb *= p.exposure
        rgb[~visible] = p.dark_level * p.exposure
    else:
        frac = pupil_fraction(tilt, numerical_aperture=p.numerical_aperture,
                              fill=p.illumination_fill).astype(np.float64)[..., None]
        lit = frac[..., 0] > 0
        rgb = table.linear_rgb_at(np.where(lit, tilt, 0.0), thickness).astype(np.float64)
        rgb = (rgb * frac + (1.0 - frac) * p.dark_level) * p.exposure
    groove = (np.zeros(shape) if p.measured  # a continuous surface: no steps between cells
              else _groove_coverage(facet, groove_height, p))
    rgb = rgb * (1.0 - groove[..., None]) + groove[..., None] * p.dark_level * p.exposure
    rgb, feature, stain, dust = _on_the_film(rgb, feature, p)
    rgb = rgb.astype(np.float32)
    if p.vignetting_corner_loss > 0:
        rgb *= vignetting_factor(shape, corner_loss=p.vignetting_corner_loss)[..., None]
    if tuple(p.white_balance_gains) != (1.0, 1.0, 1.0):
        rgb = apply_white_balance(rgb, p.white_balance_gains)
    return Scene(height.astype(np.float32), tilt.astype(np.float32), azimuth.astype(np.float32),
                 thickness.astype(np.float32), visible, facet.astype(np.int32),
                 region.astype(np.int32), region_d, comp, groove.astype(np.float32),
                 rgb, feature, dust, stain, relief)


def _tilt_azimuth(gy, gx):
    """Tilt (degrees from the axis) and azimuth of the normal's horizontal component (the
    surface rises toward +slope, the normal leans the other way: normal ∝ (−gx, −gy, 1))."""
    return (np.rad2deg(np.arctan(np.hypot(gy, gx))),
            np.rad2deg(np.arctan2(-gy, -gx)) % 360.0)


def _on_the_film(rgb, feature, p):
    """Stains (the film's reflectance × a factor) and dust (grey flakes on top) over the
    linear image: ``(rgb, feature, stain coverage, dust coverage)``."""
    shape = feature.shape
    stain = np.zeros(shape, dtype=np.float32)
    if p.stain_density_per_mm2 > 0:
        stain, factor, _ = stain_layer(np.random.default_rng([p.seed, STREAMS["stains"]]),
                                       shape, p)
        rgb = rgb * (1.0 - stain * (1.0 - factor))[..., None]
        feature = np.where(stain >= 0.5, np.uint8(FEATURE_CODES["stain"]), feature)
    dust = np.zeros(shape, dtype=np.float32)
    if p.dust_density_per_mm2 > 0:
        dust, grey, _ = dust_layer(np.random.default_rng([p.seed, STREAMS["dust"]]), shape, p)
        rgb = rgb * (1.0 - dust[..., None]) + (dust * grey * p.exposure)[..., None]
        feature = np.where(dust >= 0.5, np.uint8(FEATURE_CODES["dust"]), feature)
    return rgb, feature, stain, dust


def _skip_default_facets(rng, shape, cell_px, lobe_weights):
    """Consume the default facets' draws (seeds, lobes, slopes) from the main stream."""
    h, w = shape
    n = max(1, int(round(h * w / (math.pi * (cell_px / 2) ** 2))))
    ys = rng.integers(0, h, n)
    xs = rng.integers(0, w, n)
    nf = np.unique(ys * w + xs).size
    rng.choice(lobe_weights.size, size=nf, p=lobe_weights / lobe_weights.sum())
    rng.standard_normal(nf)
    rng.standard_normal(nf)


def _groove_coverage(facet, height, p):
    """Fraction of each pixel covered by the dark wall of a step to a neighbouring facet."""
    if p.groove_wall_deg <= 0:
        return np.zeros(facet.shape)
    jump = np.zeros(facet.shape)
    for axis in (0, 1):
        a = [slice(None)] * 2
        b = [slice(None)] * 2
        a[axis], b[axis] = slice(1, None), slice(None, -1)
        a, b = tuple(a), tuple(b)
        dh = np.where(facet[a] != facet[b], np.abs(height[a] - height[b]), 0.0)
        jump[a] = np.maximum(jump[a], dh)
        jump[b] = np.maximum(jump[b], dh)
    # The wall's projected width, shared by the two pixels either side of the boundary.
    width_px = jump / math.tan(math.radians(p.groove_wall_deg)) / p.pixel_size_um
    return np.clip(0.5 * width_px, 0.0, 1.0)


def _table_for(p, thickness):
    lo = max(0.0, float(np.floor(thickness.min())) - 1.0)
    hi = float(np.ceil(thickness.max())) + 1.0
    top = p.max_tilt_deg
    if p.illumination_fill > 0:
        top = min(89.0, pupil_limit_deg(numerical_aperture=p.numerical_aperture,
                                        fill=p.illumination_fill))
    return build_colour_table(thickness_range_nm=(lo, hi),
                              theta_range_deg=(0.0, top + 0.5),
                              film=p.film, substrate=p.substrate, illuminant=p.illuminant)
