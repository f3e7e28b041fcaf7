"""The synthetic scene: a surface of planar microfacets on macro waviness, oxide regions,
and the noise-free image the microscope would see (:func:`render_scene`).

See :mod:`microfacet.forward.synth` for the parameters and the stack written from it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..colour.table import build_colour_table
from ..core.lazy import load

cv2 = load("cv2")
ndimage = load("scipy.ndimage")

__all__ = ["Scene", "render_scene"]




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
    linear_rgb: np.ndarray           # H×W×3 sharp image, linear, exposure applied, unclipped


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


def _smooth_field(rng, shape, scale_px):
    """Zero-mean, unit-SD Gaussian random field with correlation length ``scale_px``."""
    f = rng.standard_normal(shape).astype(np.float32)
    f = cv2.GaussianBlur(f, (0, 0), sigmaX=max(scale_px, 0.5), borderType=cv2.BORDER_REFLECT)
    sd = float(f.std())
    return (f / sd if sd > 0 else f).astype(np.float64)


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
    """
    p.validate()
    rng = np.random.default_rng(p.seed)
    shape = (p.height_px, p.width_px)
    px = p.pixel_size_um
    yy, xx = np.mgrid[0:shape[0], 0:shape[1]].astype(np.float64) * px

    # Surface: macro waviness + planar facets through it.
    macro, mgy, mgx = _waviness(rng, p, yy, xx)
    facet, fy, fx = _voronoi(rng, shape, p.facet_size_um / px)
    nf = fy.size
    w = np.array([lb.weight for lb in p.tilt_lobes], dtype=np.float64)
    lobe = rng.choice(len(p.tilt_lobes), size=nf, p=w / w.sum())
    slope_sd = np.tan(np.deg2rad([lb.sd_deg for lb in p.tilt_lobes]))[lobe]
    sy = rng.standard_normal(nf) * slope_sd + mgy[fy, fx]
    sx = rng.standard_normal(nf) * slope_sd + mgx[fy, fx]
    cy, cx = fy * px, fx * px
    height = macro[fy, fx][facet] + sy[facet] * (yy - cy[facet]) + sx[facet] * (xx - cx[facet])
    tilt = np.rad2deg(np.arctan(np.hypot(sy, sx)))[facet]
    # Azimuth of the normal's horizontal component (the surface rises toward +slope, the
    # normal leans the other way): normal ∝ (−sx, −sy, 1).
    azimuth = np.rad2deg(np.arctan2(-sy, -sx))[facet] % 360.0

    # Thickness regions from the mixture, plus smooth fine variation.
    region, _, _ = _voronoi(rng, shape, p.region_size_um / px)
    nr = int(region.max()) + 1
    cw = np.array([c.weight for c in p.thickness], dtype=np.float64)
    comp = rng.choice(len(p.thickness), size=nr, p=cw / cw.sum())
    means = np.array([c.mean_nm for c in p.thickness])[comp]
    sds = np.array([c.sd_nm for c in p.thickness])[comp]
    region_d = np.maximum(means + sds * rng.standard_normal(nr), 0.0)
    fine = _smooth_field(rng, shape, p.thickness_fine_scale_um / px) * p.thickness_fine_sd_nm
    facet_dd = rng.standard_normal(nf) * p.thickness_facet_sd_nm
    thickness = np.maximum(region_d[region] + fine + facet_dd[facet], 0.0)

    visible = tilt <= p.max_tilt_deg
    if table is None:
        table = _table_for(p, thickness)
    rgb = table.linear_rgb_at(np.where(visible, tilt, 0.0), thickness).astype(np.float64)
    rgb *= p.exposure
    rgb[~visible] = p.dark_level * p.exposure
    groove = _groove_coverage(facet, height, p)
    rgb = rgb * (1.0 - groove[..., None]) + groove[..., None] * p.dark_level * p.exposure
    return Scene(height.astype(np.float32), tilt.astype(np.float32), azimuth.astype(np.float32),
                 thickness.astype(np.float32), visible, facet.astype(np.int32),
                 region.astype(np.int32), region_d, comp, groove.astype(np.float32),
                 rgb.astype(np.float32))


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
    return build_colour_table(thickness_range_nm=(lo, hi),
                              theta_range_deg=(0.0, p.max_tilt_deg + 0.5),
                              film=p.film, substrate=p.substrate, illuminant=p.illuminant)


