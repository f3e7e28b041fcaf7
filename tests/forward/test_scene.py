"""The synthetic scene (microfacet.forward.scene): thickness regions follow the mixture,
facet tilts the lobes and the acceptance angle; each imaging variation changes what it
should and nothing else; stains; measured geometry (``relief_file``); the textureless
facets world."""

import dataclasses
from pathlib import Path

import numpy as np
import pytest
from scipy import ndimage

from microfacet.forward.imaging import pupil_fraction
from microfacet.forward.relief import FEATURE_CODES
from microfacet.forward.scene import render_scene
from microfacet.forward.synth import preset
from microfacet.io.x3p import write_x3p

HEIGHTS = Path(__file__).resolve().parents[2] / "fixtures" / "instrument-heights"


@pytest.mark.slow
def test_thickness_regions_follow_the_mixture_and_tilts_the_lobes():
    p = preset("nd", seed=2, height_px=512, width_px=512)
    s = render_scene(p)
    means = np.array([c.mean_nm for c in p.thickness])
    comp_of_region = s.region_component
    # Each region's thickness lies within 4 SD of its component mean.
    sd = np.array([c.sd_nm for c in p.thickness])[comp_of_region]
    assert np.all(np.abs(s.region_thickness_nm - means[comp_of_region]) < 4 * sd + 1e-9)
    # The steepest visible facets are below the NA limit; beyond it pixels are marked dark.
    assert s.tilt_deg[s.visible].max() <= p.max_tilt_deg
    assert not s.visible[s.tilt_deg > p.max_tilt_deg].any()


# ----------------------------------------------- each variation changes what it should, only

FIELDS = ("height_um", "tilt_deg", "azimuth_deg", "thickness_nm", "visible", "facet_id",
          "region_id", "region_thickness_nm", "region_component", "groove", "linear_rgb",
          "feature", "dust", "stain")
SURFACE = {"height_um", "tilt_deg", "azimuth_deg", "visible"}

# variation -> (fields that must change, fields that may change as a consequence)
CASES = {
    "groove_wall_deg": (0.0, {"groove", "linear_rgb"}, set()),
    "facet_aspect": (3.0, {"height_um", "tilt_deg", "facet_id", "groove", "linear_rgb"},
                     SURFACE),
    "facet_size_spread": (0.6, {"height_um", "tilt_deg", "facet_id", "groove", "linear_rgb"},
                          SURFACE),
    "facet_dome_deg": (6.0, {"height_um", "tilt_deg", "azimuth_deg", "linear_rgb"},
                       SURFACE | {"groove"}),
    "terrace_step_um": (1.0, {"height_um", "groove", "linear_rgb"}, set()),
    "pit_density_per_mm2": (4000.0, {"height_um", "tilt_deg", "feature", "linear_rgb"},
                            SURFACE),
    "scratch_density_per_mm2": (3000.0, {"height_um", "tilt_deg", "feature", "linear_rgb"},
                                SURFACE),
    "dust_density_per_mm2": (6000.0, {"dust", "feature", "linear_rgb"}, set()),
    "stain_density_per_mm2": (6000.0, {"stain", "feature", "linear_rgb"}, set()),
    "illumination_fill": (0.8, {"linear_rgb"}, set()),
    "vignetting_corner_loss": (0.4, {"linear_rgb"}, set()),
    "white_balance_gains": ((1.1, 1.0, 0.9), {"linear_rgb"}, set()),
    "film": ("TiO2_Jolivet2023_anatase", {"linear_rgb"}, set()),
}


def _same(a, b):
    return a.shape == b.shape and np.array_equal(a, b)


@pytest.fixture(scope="module")
def base_scene():
    return render_scene(preset("nd", seed=3, height_px=128, width_px=128))


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(CASES))
def test_a_variation_changes_what_it_should_and_nothing_else(base_scene, name):
    value, must, may = CASES[name]
    s = render_scene(preset("nd", seed=3, height_px=128, width_px=128, **{name: value}))
    changed = {f for f in FIELDS if not _same(getattr(base_scene, f), getattr(s, f))}
    assert must <= changed, must - changed
    assert changed <= must | may, changed - must - may


def _pair(**kw):
    base = preset("nd", seed=6, height_px=128, width_px=128)
    return render_scene(base), render_scene(dataclasses.replace(base, **kw)), base


@pytest.mark.slow
def test_vignetting_darkens_the_corners_by_the_given_factor():
    a, b, _ = _pair(vignetting_corner_loss=0.35)
    ratio = b.linear_rgb / a.linear_rgb
    assert ratio[0, 0] == pytest.approx([0.65] * 3, rel=1e-5)
    assert ratio[-1, -1] == pytest.approx([0.65] * 3, rel=1e-5)
    assert ratio[63:65, 63:65].min() > 0.999
    diag = ratio[np.arange(64), np.arange(64), 0]   # corner to centre: monotone
    assert np.all(np.diff(diag) > 0)


@pytest.mark.slow
def test_white_balance_scales_each_channel():
    a, b, _ = _pair(white_balance_gains=(1.2, 1.0, 0.8))
    np.testing.assert_allclose(b.linear_rgb / a.linear_rgb,
                               np.broadcast_to([1.2, 1.0, 0.8], a.linear_rgb.shape), rtol=1e-5)


@pytest.mark.slow
def test_tilt_dependent_brightness_scales_the_film_colour_by_the_pupil_fraction():
    a, b, p = _pair(illumination_fill=1.0)
    f = pupil_fraction(a.tilt_deg, numerical_aperture=p.numerical_aperture, fill=1.0)
    ok = a.visible & (a.groove == 0)
    dark = p.dark_level * p.exposure
    expect = f[..., None] * a.linear_rgb + (1 - f[..., None]) * dark
    np.testing.assert_allclose(b.linear_rgb[ok], expect[ok], rtol=2e-3, atol=1e-4)
    # steeper facets are darker
    g = b.linear_rgb[ok].sum(axis=1) / a.linear_rgb[ok].sum(axis=1)
    order = np.argsort(a.tilt_deg[ok])
    assert np.corrcoef(a.tilt_deg[ok][order], g[order])[0, 1] < -0.9


@pytest.mark.slow
def test_pits_are_in_the_height_truth_with_dark_walls_and_a_visible_floor():
    a, b, p = _pair(pit_density_per_mm2=5000.0, pit_radius_um=2.5)
    pit = b.feature == FEATURE_CODES["pit"]
    assert 0.02 < pit.mean() < 0.5
    assert np.all(b.height_um[pit] < a.height_um[pit])
    np.testing.assert_array_equal(b.height_um[~pit], a.height_um[~pit])
    wall = pit & (b.tilt_deg > p.max_tilt_deg)
    assert wall.sum() > 50
    dark = p.dark_level * p.exposure
    assert np.allclose(b.linear_rgb[wall], dark * (1 - a.groove[wall, None])
                       + a.groove[wall, None] * dark)
    # the floor keeps the facet's tilt and so its colour
    floor = pit & (np.abs(b.tilt_deg - a.tilt_deg) < 1e-4)
    assert floor.sum() > 50
    np.testing.assert_array_equal(b.linear_rgb[floor], a.linear_rgb[floor])
    # depth: (R/2) tan(wall) with R log-normal around 2.5 um
    depth = (a.height_um - b.height_um)[pit].max()
    assert 0.5 < depth < 6.0


@pytest.mark.slow
def test_scratches_follow_the_rolling_direction_and_have_dark_walls():
    a, b, p = _pair(scratch_density_per_mm2=4000.0, scratch_spread_deg=0.0,
                    rolling_direction_deg=30.0, scratch_length_um=60.0)
    s = b.feature == FEATURE_CODES["scratch"]
    assert 0.02 < s.mean() < 0.6
    assert np.all(b.height_um[s] < a.height_um[s])
    wall = s & (b.tilt_deg > p.max_tilt_deg)
    assert wall.mean() > 0.5 * s.mean()
    assert b.linear_rgb[wall].max() <= p.dark_level * p.exposure + 1e-6
    # the trenches run along the rolling direction (x toward y): the carved depth slopes
    # across it
    gy = np.gradient(b.height_um - a.height_um, axis=0)[s]
    gx = np.gradient(b.height_um - a.height_um, axis=1)[s]
    across = np.rad2deg(np.arctan2(np.median(np.abs(gy)), np.median(np.abs(gx))))
    assert across == pytest.approx(90 - 30, abs=8)


@pytest.mark.slow
def test_dust_is_grey_on_top_and_not_in_the_height():
    a, b, p = _pair(dust_density_per_mm2=8000.0, dust_radius_um=1.5)
    d = b.dust == 1.0
    assert d.sum() > 100
    rgb = b.linear_rgb[d]
    np.testing.assert_allclose(rgb[:, 0], rgb[:, 1], rtol=1e-5)
    np.testing.assert_allclose(rgb[:, 2], rgb[:, 1], rtol=1e-5)
    assert rgb.min() > 0.019 and rgb.max() < 0.91
    np.testing.assert_array_equal(a.height_um, b.height_um)
    np.testing.assert_array_equal(a.thickness_nm, b.thickness_nm)


def _cell_moments(labels):
    """Per-cell pixel count and coordinate covariance (vectorised with bincount)."""
    yy, xx = np.indices(labels.shape)
    lab = labels.ravel()
    n = np.bincount(lab).astype(float)
    m = {}
    for k, v in (("y", yy.ravel()), ("x", xx.ravel())):
        m[k] = np.bincount(lab, v) / np.maximum(n, 1)
    cyy = np.bincount(lab, (yy.ravel() - m["y"][lab]) ** 2) / np.maximum(n, 1)
    cxx = np.bincount(lab, (xx.ravel() - m["x"][lab]) ** 2) / np.maximum(n, 1)
    cxy = np.bincount(lab, (yy.ravel() - m["y"][lab]) * (xx.ravel() - m["x"][lab])) \
        / np.maximum(n, 1)
    return n, cyy, cxx, cxy


@pytest.mark.slow
@pytest.mark.parametrize("angle", [0.0, 60.0])
def test_elongated_facets_are_longer_along_the_rolling_direction(angle):
    _, b, _ = _pair(facet_aspect=3.0, rolling_direction_deg=angle)
    n, cyy, cxx, cxy = _cell_moments(b.facet_id)
    big = n > 30
    cov = np.array([[cxx[big].mean(), cxy[big].mean()], [cxy[big].mean(), cyy[big].mean()]])
    w, v = np.linalg.eigh(cov)
    main = np.rad2deg(np.arctan2(v[1, 1], v[0, 1])) % 180
    assert min(abs(main - angle), 180 - abs(main - angle)) < 8
    assert np.sqrt(w[1] / w[0]) > 2.0
    a, _, _ = _pair()
    n0, cyy0, cxx0, cxy0 = _cell_moments(a.facet_id)
    w0 = np.linalg.eigvalsh([[cxx0[n0 > 30].mean(), cxy0[n0 > 30].mean()],
                             [cxy0[n0 > 30].mean(), cyy0[n0 > 30].mean()]])
    assert np.sqrt(w0[1] / w0[0]) < 1.3


@pytest.mark.slow
def test_size_spread_widens_the_facet_size_distribution():
    a, b, _ = _pair(facet_size_spread=0.7)
    na, nb = np.bincount(a.facet_id.ravel()), np.bincount(b.facet_id.ravel())
    cv_a, cv_b = na.std() / na.mean(), nb.std() / nb.mean()
    assert cv_b > 1.5 * cv_a


@pytest.mark.slow
def test_rounded_facets_vary_in_tilt_inside_a_facet():
    a, b, _ = _pair(facet_dome_deg=6.0)
    n = np.bincount(a.facet_id.ravel())

    def spread(s):
        lab = s.facet_id.ravel()
        t = s.tilt_deg.ravel().astype(float)
        m = np.bincount(lab, t) / n
        return np.sqrt(np.bincount(lab, (t - m[lab]) ** 2) / n)[n > 30]

    assert np.all(spread(a) < 1e-3)
    assert np.median(spread(b)) > 1.5
    np.testing.assert_array_equal(a.facet_id, b.facet_id)


@pytest.mark.slow
def test_terraces_raise_whole_facets_by_whole_steps():
    a, b, _ = _pair(terrace_step_um=0.8, terrace_size_um=12.0)
    steps = (b.height_um - a.height_um) / 0.8
    np.testing.assert_allclose(steps, np.round(steps), atol=1e-4)
    assert set(np.unique(np.round(steps))) == {0.0, 1.0, 2.0}
    np.testing.assert_array_equal(a.tilt_deg, b.tilt_deg)
    lab = a.facet_id.ravel()
    per = np.round(steps).ravel()
    assert np.all(np.bincount(lab, per) == per[np.unique(lab, return_index=True)[1]]
                  * np.bincount(lab))           # one level per facet
    assert b.groove.sum() > a.groove.sum()      # the terrace edges are dark walls


# ------------------------------------------------------------------------------------ stains


def test_stains_darken_the_film_keep_its_hue_and_leave_the_surface():
    base = preset("nd", seed=6, height_px=64, width_px=64)
    a = render_scene(base)
    b = render_scene(dataclasses.replace(base, stain_density_per_mm2=8000.0,
                                         stain_radius_um=1.5))
    full = b.stain == 1.0
    assert full.sum() > 30
    assert np.all(b.feature[full] == FEATURE_CODES["stain"])
    ratio = b.linear_rgb[full] / a.linear_rgb[full]
    # one factor per pixel for all three channels (the hue kept), in the drawn range
    np.testing.assert_allclose(ratio, ratio[:, :1].repeat(3, axis=1), rtol=1e-5)
    assert ratio.min() >= 0.05 - 1e-6 and ratio.max() <= 0.35 + 1e-6
    untouched = b.stain == 0
    np.testing.assert_array_equal(b.linear_rgb[untouched], a.linear_rgb[untouched])
    partial = (b.stain > 0) & (b.stain < 1)
    assert partial.any()                                  # anti-aliased outlines
    for name in ("height_um", "tilt_deg", "azimuth_deg", "thickness_nm", "visible", "groove"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)


# ----------------------------------------------------------------- measured geometry (relief)


def _source_window_rms_slope(relief, height_um, pixel_size_um):
    """RMS |∇h| of the source map (computed here, numpy central differences) over the
    window the scene shows, in the orientation the scene recorded."""
    h = np.asarray(height_um, dtype=np.float64)
    sy, sx = pixel_size_um
    if relief["flip_lr"]:
        h = h[:, ::-1]
    h = np.rot90(h, relief["rot90"])
    if relief["rot90"] % 2:
        sy, sx = sx, sy
    gy, gx = np.gradient(h, sy, sx)
    (y0, x0), (ny, nx) = relief["window_origin_px"], relief["window_shape_px"]
    win = (slice(int(np.ceil(y0)), int(y0 + ny)), slice(int(np.ceil(x0)), int(x0 + nx)))
    return float(np.sqrt(np.mean(gy[win] ** 2 + gx[win] ** 2)))


def _rms_truth_slope(scene):
    return float(np.sqrt(np.mean(np.tan(np.radians(scene.tilt_deg.astype(np.float64))) ** 2)))


def _smooth_map(shape, seed):
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[0:shape[0], 0:shape[1]].astype(np.float64)
    h = np.zeros(shape)
    for _ in range(6):
        ky, kx = rng.uniform(0.05, 0.25, 2) * rng.choice([-1, 1], 2)
        h += rng.uniform(0.5, 2.0) * np.sin(ky * yy + kx * xx + rng.uniform(0, 6.3))
    return h


def test_measured_relief_keeps_the_slopes_of_the_map(tmp_path):
    """An x3p map with anisotropic pixels: the truth's RMS slope (tan of the tilt) equals
    the source's RMS gradient over the window shown, heights are the map's scaled by the
    recorded magnification, there are no grooves and the Voronoi cells still label it."""
    h = _smooth_map((90, 110), 1)
    write_x3p(tmp_path / "m.x3p", h, (0.5, 0.7))
    p = preset("nd", seed=2, height_px=64, width_px=64, relief_file=str(tmp_path / "m.x3p"))
    s = render_scene(p)
    r = s.relief
    assert r["file"] == "m.x3p" and len(r["sha256"]) == 16
    assert min(r["zoom_px"]) >= 1.0 - 1e-12
    want = _source_window_rms_slope(r, h, (0.5, 0.7))
    assert _rms_truth_slope(s) == pytest.approx(want, rel=0.03)
    assert np.all(s.groove == 0) and s.facet_id.max() > 10
    np.testing.assert_array_equal(s.visible, s.tilt_deg <= p.max_tilt_deg)
    # the tilt is the central-difference gradient of the truth height
    gy, gx = np.gradient(s.height_um.astype(np.float64), p.pixel_size_um)
    np.testing.assert_allclose(np.tan(np.radians(s.tilt_deg)), np.hypot(gy, gx),
                               rtol=1e-4, atol=1e-5)
    # same seed, same scene; the thickness regions are those of the synthetic scene
    t = render_scene(p)
    np.testing.assert_array_equal(s.height_um, t.height_um)
    np.testing.assert_array_equal(s.region_id, render_scene(
        preset("nd", seed=2, height_px=64, width_px=64)).region_id)


@pytest.mark.slow
def test_measured_relief_from_an_alicona_file_keeps_its_rms_slope():
    pytest.importorskip("SurfaceTopography")
    from microfacet.io.instruments import read_height_map

    m = read_height_map(HEIGHTS / "al3d-1.al3d")
    for seed in (1, 2):
        p = preset("nd", seed=seed, height_px=96, width_px=128,
                   relief_file=str(HEIGHTS / "al3d-1.al3d"))
        s = render_scene(p)
        want = _source_window_rms_slope(s.relief, m.height_um, m.pixel_size_um)
        assert 0.15 < want < 0.4
        assert _rms_truth_slope(s) == pytest.approx(want, rel=0.03)


def test_measured_relief_errors_name_relief_file(tmp_path):
    np.save(tmp_path / "h.npy", _smooth_map((40, 40), 2))          # no pixel size
    write_x3p(tmp_path / "tiny.x3p", _smooth_map((5, 40), 3), 0.5)
    holes = _smooth_map((40, 40), 4)
    holes[:, :20] = np.nan
    write_x3p(tmp_path / "holes.x3p", holes, 0.5)
    kw = dict(seed=1, height_px=32, width_px=32)
    for name, why in (("h.npy", "pixel size"), ("tiny.x3p", "too small"),
                      ("holes.x3p", "undefined"), ("nope.x3p", "not found")):
        with pytest.raises(ValueError, match=f"^relief_file: .*{why}"):
            render_scene(preset("nd", **kw, relief_file=str(tmp_path / name)))
    with pytest.raises(ValueError, match="^relief_file: .*terrace_step_um"):
        preset("nd", **kw, relief_file=str(tmp_path / "holes.x3p"), terrace_step_um=1.0)


def test_measured_relief_fills_a_few_undefined_points(tmp_path):
    h = _smooth_map((60, 60), 5)
    h[10:14, 20:25] = np.nan
    write_x3p(tmp_path / "m.x3p", h, 0.3)
    s = render_scene(preset("nd", seed=1, height_px=32, width_px=32,
                            relief_file=str(tmp_path / "m.x3p")))
    assert np.isfinite(s.height_um).all() and np.isfinite(s.tilt_deg).all()
    assert s.relief["nan_filled_fraction"] == pytest.approx(20 / 3600)


# ------------------------------------------------------------ the textureless facets world


def test_facets_without_grooves_have_contrast_only_at_the_sparse_defects():
    """groove_wall_deg = 0, no per-facet thickness offsets, pits: inside a facet and away
    from the defects the image is flat; the contrast lives at the pits."""
    p = preset("nd", seed=3, height_px=128, width_px=128, groove_wall_deg=0.0,
               thickness_facet_sd_nm=0.0, pit_density_per_mm2=1500.0, pit_radius_um=1.5)
    s = render_scene(p)
    assert np.all(s.groove == 0)
    lum = s.linear_rgb.mean(axis=-1).astype(np.float64)
    near = ndimage.binary_dilation(s.feature > 0, iterations=2)
    step = np.abs(np.diff(lum, axis=1))
    same = (s.facet_id[:, 1:] == s.facet_id[:, :-1]) & ~near[:, 1:] & ~near[:, :-1]
    across = (s.facet_id[:, 1:] != s.facet_id[:, :-1]) & ~near[:, 1:] & ~near[:, :-1]
    at_pits = (s.feature[:, 1:] > 0) | (s.feature[:, :-1] > 0)
    assert same.sum() > 5000 and at_pits.sum() > 100
    assert np.percentile(step[same], 99) < 0.002       # facet interiors: no texture
    assert np.median(step[across]) < 0.02               # facet edges: weak (tilt only)
    assert np.percentile(step[at_pits], 90) > 0.1       # the pits carry the contrast
