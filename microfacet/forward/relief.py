"""Relief of a synthetic surface beyond planar Voronoi facets: elongated and wide-size-spread
facet cells, rounded (dome) facets, terraces, etch pits, scratches, a measured height map in
place of the facets (:func:`measured_relief`) — and, on top, stains that darken the film and
dust.

Each function draws from the ``numpy.random.Generator`` it is given (the scene gives every
variation its own stream, so switching one on does not move the others) and works on
float64 µm coordinates; features are carved in crops around each one, so the cost grows with
their area, not with the image. Docs: docs/synthetic-stacks.md.
"""

from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..core.lazy import load

cv2 = load("cv2")
spatial = load("scipy.spatial")
ndimage = load("scipy.ndimage")
instruments = load("microfacet.io.instruments")

__all__ = ["Carving", "FEATURE_CODES", "carve_pits", "carve_scratches", "dome_relief", "dust_layer",
           "measured_relief", "shaped_cells", "stain_layer", "terrace_offsets_um"]

#: Codes of ``truth/feature.npy``.
FEATURE_CODES = {"facet": 0, "pit": 1, "scratch": 2, "dust": 3, "stain": 4}


def smooth_field(rng, shape, scale_px):
    """Zero-mean, unit-SD Gaussian random field with correlation length ``scale_px``."""
    f = rng.standard_normal(shape).astype(np.float32)
    f = cv2.GaussianBlur(f, (0, 0), sigmaX=max(scale_px, 0.5), borderType=cv2.BORDER_REFLECT)
    sd = float(f.std())
    return (f / sd if sd > 0 else f).astype(np.float64)


def _axes(p):
    """Unit vectors (x, y) along and across the rolling direction."""
    a = math.radians(p.rolling_direction_deg)
    return (math.cos(a), math.sin(a)), (-math.sin(a), math.cos(a))


def shaped_cells(rng, shape, p):
    """Facet cells other than isotropic Poisson-Voronoi: elongated and/or of varied size.

    Seeds are drawn with a density ∝ exp(−2 s G) (G a smooth unit random field with a
    correlation length of 5 facets, s = ``facet_size_spread``, so the local cell diameter
    ∝ exp(s G)), and each pixel goes to the nearest seed in coordinates scaled by
    1/√aspect along and √aspect across the rolling direction (cells ``facet_aspect`` times
    longer than wide, with the mean area of ``facet_size_um`` discs).

    Returns
    -------
    labels : ndarray of int64 (H, W)
    ys, xs : ndarray of int (n,)
        Seed pixels, unique, in raster order.
    """
    h, w = shape
    cell_px = p.facet_size_um / p.pixel_size_um
    n = max(1, int(round(h * w / (math.pi * (cell_px / 2) ** 2))))
    if p.facet_size_spread > 0:
        g = np.clip(smooth_field(rng, shape, 5.0 * cell_px), -2.0, 2.0)
        dens = np.exp(-2.0 * p.facet_size_spread * g).ravel()
        flat = rng.choice(h * w, size=n, p=dens / dens.sum())
    else:
        flat = rng.integers(0, h, n) * w + rng.integers(0, w, n)
    flat = np.unique(flat)
    ys, xs = flat // w, flat % w
    (ax, ay), (cx, cy) = _axes(p)
    k = math.sqrt(p.facet_aspect)

    def warp(y, x):
        return np.stack([(x * ax + y * ay) / k, (x * cx + y * cy) * k], axis=-1)

    tree = spatial.cKDTree(warp(ys.astype(np.float64), xs.astype(np.float64)))
    labels = np.empty(h * w, dtype=np.int64)
    rows = max(1, (1 << 18) // w)
    xx = np.arange(w, dtype=np.float64)
    for r0 in range(0, h, rows):       # row blocks keep the query's memory small
        yy = np.arange(r0, min(h, r0 + rows), dtype=np.float64)
        pts = warp(np.repeat(yy, w), np.tile(xx, yy.size))
        labels[r0 * w:r0 * w + pts.shape[0]] = tree.query(pts, workers=-1)[1]
    return labels.reshape(shape), ys, xs


def dome_relief(yy_um, xx_um, facet, cy_um, cx_um, p):
    """Height and slope of rounded facets: a paraboloid cap per facet (0 at its seed).

    The cap's extra slope is tan(``facet_dome_deg``) at the mean cell radius, in the same
    stretched coordinates as the cells (so elongated cells get elongated caps).

    Returns
    -------
    dz_um, dgy, dgx : ndarray of float64 (H, W)
    """
    r_um = 0.5 * p.facet_size_um / math.tan(math.radians(p.facet_dome_deg))  # curvature radius
    (ax, ay), (cx, cy) = _axes(p)
    a = p.facet_aspect
    dy, dx = yy_um - cy_um[facet], xx_um - cx_um[facet]
    u = dx * ax + dy * ay          # along
    v = dx * cx + dy * cy          # across
    dz = -(u * u / a + v * v * a) / (2.0 * r_um)
    du, dv = -u / (a * r_um), -v * a / r_um
    return dz, du * ay + dv * cy, du * ax + dv * cx


def terrace_offsets_um(rng, shape, fy, fx, p):
    """Per-facet height offsets: 0, 1 or 2 × ``terrace_step_um`` by terrace (Voronoi cells
    of ``terrace_size_um``; a facet belongs to the terrace of its seed)."""
    h, w = shape
    cell_px = p.terrace_size_um / p.pixel_size_um
    n = max(1, int(round(h * w / (math.pi * (cell_px / 2) ** 2))))
    ty, tx = rng.uniform(0, h, n), rng.uniform(0, w, n)
    level = rng.integers(0, 3, n)
    tree = spatial.cKDTree(np.stack([ty, tx], axis=-1))
    which = tree.query(np.stack([fy, fx], axis=-1).astype(np.float64))[1]
    return level[which] * p.terrace_step_um


@dataclass
class Carving:
    """Depressions carved into the facet surface: depth (≤ 0, µm), its slope and which
    feature made it (:data:`FEATURE_CODES`)."""

    dz_um: np.ndarray
    dgy: np.ndarray
    dgx: np.ndarray
    feature: np.ndarray

    @classmethod
    def empty(cls, shape):
        return cls(np.zeros(shape), np.zeros(shape), np.zeros(shape),
                   np.zeros(shape, dtype=np.uint8))

    def add(self, box, dz, gy, gx, code):
        """Keep, per pixel of ``box`` (a pair of slices), the deeper of the two surfaces."""
        deeper = dz < self.dz_um[box]
        for arr, new in ((self.dz_um, dz), (self.dgy, gy), (self.dgx, gx)):
            arr[box] = np.where(deeper, new, arr[box])
        self.feature[box] = np.where(deeper, code, self.feature[box])


def _count(rng, density_per_mm2, shape, p):
    area_mm2 = shape[0] * shape[1] * (p.pixel_size_um * 1e-3) ** 2
    return int(rng.poisson(density_per_mm2 * area_mm2))


def _box(shape, y0, y1, x0, x1):
    """Pixel slices covering [y0, y1] × [x0, x1] (pixel units), clipped; None if empty."""
    r0, r1 = max(0, int(math.floor(y0))), min(shape[0], int(math.ceil(y1)) + 1)
    c0, c1 = max(0, int(math.floor(x0))), min(shape[1], int(math.ceil(x1)) + 1)
    if r0 >= r1 or c0 >= c1:
        return None
    return slice(r0, r1), slice(c0, c1)


def _grid_um(box, px):
    ys = np.arange(box[0].start, box[0].stop, dtype=np.float64)[:, None] * px
    xs = np.arange(box[1].start, box[1].stop, dtype=np.float64)[None, :] * px
    return ys, xs


def carve_pits(rng, shape, p, carving):
    """Etch pits: flat floor (radius R/2, depth (R/2) tan wall) and a conical wall to the rim
    at radius R; ``carving`` is updated in place. Returns the number of pits."""
    px = p.pixel_size_um
    n = _count(rng, p.pit_density_per_mm2, shape, p)
    cy, cx = rng.uniform(0, shape[0], n) * px, rng.uniform(0, shape[1], n) * px
    rad = p.pit_radius_um * np.exp(0.3 * rng.standard_normal(n))
    slope = math.tan(math.radians(p.pit_wall_deg))
    for y0, x0, r in zip(cy, cx, rad):
        box = _box(shape, (y0 - r) / px, (y0 + r) / px, (x0 - r) / px, (x0 + r) / px)
        if box is None:
            continue
        ys, xs = _grid_um(box, px)
        dy, dx = ys - y0, xs - x0
        d = np.hypot(dy, dx)
        floor = 0.5 * r
        depth = floor * slope
        wall = (d > floor) & (d < r)
        dz = np.where(d <= floor, -depth, np.where(wall, -slope * (r - d), 0.0))
        k = np.where(wall, slope / np.maximum(d, 1e-12), 0.0)   # radial slope, rising out
        carving.add(box, dz, k * dy, k * dx, FEATURE_CODES["pit"])
    return n


def carve_scratches(rng, shape, p, carving):
    """Scratches: V-shaped trenches (half-width w/2, depth (w/2) tan wall) along segments
    around the rolling direction; ``carving`` is updated in place. Returns their number."""
    px = p.pixel_size_um
    n = _count(rng, p.scratch_density_per_mm2, shape, p)
    cy, cx = rng.uniform(0, shape[0], n) * px, rng.uniform(0, shape[1], n) * px
    ang = np.deg2rad(p.rolling_direction_deg
                     + rng.uniform(-p.scratch_spread_deg, p.scratch_spread_deg, n))
    length = np.clip(rng.exponential(p.scratch_length_um, n), 2 * p.scratch_width_um,
                     4 * p.scratch_length_um)
    half = 0.5 * p.scratch_width_um * np.exp(0.2 * rng.standard_normal(n))
    slope = math.tan(math.radians(p.scratch_wall_deg))
    for y0, x0, a, ln, hw in zip(cy, cx, ang, length, half):
        ux, uy = math.cos(a), math.sin(a)
        ay_, ax_ = y0 - 0.5 * ln * uy, x0 - 0.5 * ln * ux     # start point
        by_, bx_ = y0 + 0.5 * ln * uy, x0 + 0.5 * ln * ux     # end point
        box = _box(shape, (min(ay_, by_) - hw) / px, (max(ay_, by_) + hw) / px,
                   (min(ax_, bx_) - hw) / px, (max(ax_, bx_) + hw) / px)
        if box is None:
            continue
        ys, xs = _grid_um(box, px)
        t = np.clip((xs - ax_) * ux + (ys - ay_) * uy, 0.0, ln)
        dy, dx = ys - (ay_ + t * uy), xs - (ax_ + t * ux)       # from the nearest axis point
        d = np.hypot(dy, dx)
        inside = d < hw
        dz = np.where(inside, -slope * (hw - d), 0.0)
        k = np.where(inside, slope / np.maximum(d, 1e-12), 0.0)
        carving.add(box, dz, k * dy, k * dx, FEATURE_CODES["scratch"])
    return n


def _ellipse_layer(shape, px, cy, cx, ra, rb, phi, value):
    """Anti-aliased elliptical coverage of particles and the value of the topmost one.

    Parameters
    ----------
    shape : (int, int)
    px : float
        Pixel size (µm).
    cy, cx, ra, rb, phi, value : ndarray (n,)
        Centres (µm), semi-axes (µm), orientation (rad) and a value per particle.

    Returns
    -------
    coverage, level : ndarray of float32 (H, W)
        Coverage 0-1 (a one-pixel linear ramp across each outline; where particles
        overlap, the larger coverage) and the value of the particle that gives it.
    """
    cov = np.zeros(shape, dtype=np.float32)
    level = np.zeros(shape, dtype=np.float32)
    for y0, x0, a, b, f, g in zip(cy, cx, ra, rb, phi, value):
        box = _box(shape, (y0 - a) / px - 1, (y0 + a) / px + 1, (x0 - a) / px - 1,
                   (x0 + a) / px + 1)
        if box is None:
            continue
        ys, xs = _grid_um(box, px)
        u = (xs - x0) * math.cos(f) + (ys - y0) * math.sin(f)
        v = -(xs - x0) * math.sin(f) + (ys - y0) * math.cos(f)
        rho = np.sqrt((u / a) ** 2 + (v / b) ** 2)
        c = np.clip((1.0 - rho) * b / px + 0.5, 0.0, 1.0).astype(np.float32)
        more = c > cov[box]
        cov[box] = np.where(more, c, cov[box])
        level[box] = np.where(more, np.float32(g), level[box])
    return cov, level


def dust_layer(rng, shape, p):
    """Dust flakes: coverage (0-1, anti-aliased ellipses) and their grey linear reflectance.

    Returns
    -------
    coverage, grey : ndarray of float32 (H, W)
    n : int
        Number of particles.
    """
    ell = _random_ellipses(rng, shape, p, p.dust_density_per_mm2, p.dust_radius_um)
    n = ell[0].size
    bright = rng.random(n) < p.dust_bright_fraction
    grey = np.where(bright, rng.uniform(0.5, 0.9, n), rng.uniform(0.02, 0.08, n))
    cov, level = _ellipse_layer(shape, p.pixel_size_um, *ell, grey)
    return cov, level, n


def _random_ellipses(rng, shape, p, density_per_mm2, radius_um):
    """Poisson-many ellipses: centres (µm) uniform over the image, semi-axes log-normal
    around ``radius_um`` (SD 0.4 in log) with an aspect uniform in 0.5-1, orientation
    uniform; ``(cy, cx, ra, rb, phi)``."""
    px = p.pixel_size_um
    n = _count(rng, density_per_mm2, shape, p)
    cy, cx = rng.uniform(0, shape[0], n) * px, rng.uniform(0, shape[1], n) * px
    ra = radius_um * np.exp(0.4 * rng.standard_normal(n))
    rb = ra * rng.uniform(0.5, 1.0, n)
    return cy, cx, ra, rb, rng.uniform(0, math.pi, n)


def stain_layer(rng, shape, p):
    """Stains: patches of the film that reflect less (contamination, residue, a locally
    altered oxide surface) without changing its height.

    Anti-aliased ellipses like dust (radius log-normal around ``stain_radius_um``, SD 0.4 in
    log, aspect 0.5-1), each with a reflectance factor uniform in
    [``stain_reflectance_min``, ``stain_reflectance_max``] that multiplies the film's linear
    RGB (dark, keeping its hue).

    Returns
    -------
    coverage, factor : ndarray of float32 (H, W)
        Coverage 0-1 and the factor of the stain covering each pixel (0 where none).
    n : int
        Number of stains.
    """
    ell = _random_ellipses(rng, shape, p, p.stain_density_per_mm2, p.stain_radius_um)
    n = ell[0].size
    factor = rng.uniform(p.stain_reflectance_min, p.stain_reflectance_max, n)
    cov, level = _ellipse_layer(shape, p.pixel_size_um, *ell, factor)
    return cov, level, n


#: Largest fraction of undefined (NaN) points of a measured height map that is filled in.
MAX_RELIEF_NAN_FRACTION = 0.2
#: Fewest points per axis of a measured height map.
MIN_RELIEF_PX = 8


def _relief_error(path, why):
    return ValueError(f"relief_file: {Path(path).name}: {why}")


def measured_relief(rng, shape, p):
    """The height of a measured surface (``p.relief_file``), resampled to the scene's pixels
    with every slope preserved.

    The map (any format of :func:`microfacet.io.instruments.read_height_map`; it must give
    its pixel size) is turned by a random multiple of 90° and optionally mirrored, then a
    random window of it is resampled (cubic spline) to H × W. The lateral magnification f (one µm
    of the source becomes f µm of the scene) is the smallest that makes every source pixel at
    least one scene pixel and lets the window fit in the map:
    ``f = max(p/min(sy, sx), H p/((h−1) sy), W p/((w−1) sx))`` (``p`` the scene's, ``sy``,
    ``sx`` the source's pixel size, h × w its points); heights are multiplied by f too, so
    every slope dh/dx (µm/µm) is the source's. Undefined points (NaN, at most
    :data:`MAX_RELIEF_NAN_FRACTION`) take the nearest defined height.

    Parameters
    ----------
    rng : numpy.random.Generator
        Draws the orientation and the window.
    shape : (int, int)
    p : SynthParams

    Returns
    -------
    height_um : ndarray of float64 (H, W)
        Zero median.
    info : dict
        What ``truth/params.json`` records (key ``relief``): ``file`` (the name, no folder),
        ``sha256`` (first 16 hex digits of the file's bytes), ``source`` (format and
        instrument), ``source_shape_px`` and ``source_pixel_size_um`` ((y, x) as read),
        ``rot90`` (k of ``numpy.rot90``, applied after ``flip_lr``), ``flip_lr``,
        ``magnification`` (f), ``zoom_px`` (scene pixels per source pixel, (y, x)),
        ``window_origin_px`` and ``window_shape_px`` (in the turned map, (y, x), source
        pixels), ``nan_filled_fraction``.

    Raises
    ------
    ValueError
        Naming ``relief_file``: unreadable, without a pixel size, too small, or with too
        many undefined points.
    """
    path = Path(p.relief_file)
    try:
        m = instruments.read_height_map(path)
    except ValueError as exc:
        raise ValueError(f"relief_file: {exc}") from None
    if m.pixel_size_um is None:
        raise _relief_error(path, "the file gives no pixel size (a measured map needs one)")
    h = np.asarray(m.height_um, dtype=np.float64)
    if min(h.shape) < MIN_RELIEF_PX:
        raise _relief_error(path, f"a height map of {h.shape[0]}x{h.shape[1]} points is too "
                                  f"small (at least {MIN_RELIEF_PX} per axis)")
    bad = ~np.isfinite(h)
    nan_frac = float(bad.mean())
    if nan_frac > MAX_RELIEF_NAN_FRACTION:
        raise _relief_error(path, f"{100 * nan_frac:.0f} % of the points are undefined (at "
                                  f"most {100 * MAX_RELIEF_NAN_FRACTION:.0f} % are filled in)")
    if bad.any():
        _, (iy, ix) = ndimage.distance_transform_edt(bad, return_indices=True)
        h = h[iy, ix]
    sy, sx = m.pixel_size_um
    flip = bool(rng.integers(0, 2))
    k = int(rng.integers(0, 4))
    if flip:
        h = h[:, ::-1]
    h = np.rot90(h, k)
    if k % 2:
        sy, sx = sx, sy
    H, W = shape
    px = p.pixel_size_um
    f = max(px / min(sy, sx), H * px / ((h.shape[0] - 1) * sy),
            W * px / ((h.shape[1] - 1) * sx))
    # Scene pixel (i, j) is source point (y0 + i·zy⁻¹, x0 + j·zx⁻¹), zy = f sy / p.
    zy, zx = f * sy / px, f * sx / px
    ext_y, ext_x = (H - 1) / zy, (W - 1) / zx
    y0 = float(rng.uniform(0.0, max(h.shape[0] - 1 - ext_y, 0.0)))
    x0 = float(rng.uniform(0.0, max(h.shape[1] - 1 - ext_x, 0.0)))
    r0, c0 = int(math.floor(y0)), int(math.floor(x0))
    r1 = min(h.shape[0], int(math.ceil(y0 + ext_y)) + 3)
    c1 = min(h.shape[1], int(math.ceil(x0 + ext_x)) + 3)
    r0, c0 = max(0, r0 - 2), max(0, c0 - 2)
    crop = h[r0:r1, c0:c1]
    crop = crop - float(np.median(crop))
    yy = (y0 - r0) + np.arange(H, dtype=np.float64) / zy
    xx = (x0 - c0) + np.arange(W, dtype=np.float64) / zx
    # Cubic spline at exact positions (OpenCV's warps round them to 1/32 px, which shows in
    # the slopes of a magnified map).
    spline = ndimage.spline_filter(crop, order=3, mode="nearest")
    out = ndimage.map_coordinates(spline, np.stack(np.meshgrid(yy, xx, indexing="ij")),
                                  order=3, mode="nearest", prefilter=False)
    out = out * f
    out -= float(np.median(out))
    digest = hashlib.sha256(path.read_bytes()).hexdigest()[:16]
    info = {"file": path.name, "sha256": digest, "source": m.source,
            "source_shape_px": [int(v) for v in m.height_um.shape],
            "source_pixel_size_um": [float(v) for v in m.pixel_size_um],
            "flip_lr": flip, "rot90": k, "magnification": float(f),
            "zoom_px": [float(zy), float(zx)], "window_origin_px": [y0, x0],
            "window_shape_px": [float(ext_y + 1), float(ext_x + 1)],
            "nan_filled_fraction": nan_frac}
    return out, info
