"""ROI thickness and exposure (microfacet.analysis.roi) on images rendered from the model
(independent of the synth)."""

from types import SimpleNamespace

import numpy as np
import pytest

from microfacet import colour as color
from microfacet.analysis.options import RoiOptions
from microfacet.analysis.roi import (
    block_exposure_reading,
    fit_roi_thickness,
    nearest_roi_index,
    roi_grid,
)
from microfacet.colour.model import FilmColourModel
from microfacet.colour.table import build_colour_table


@pytest.fixture(scope="module")
def table():
    return build_colour_table(thickness_range_nm=(0, 400), theta_range_deg=(0, 27))


@pytest.fixture(scope="module")
def model(table):
    return FilmColourModel(table)


def _render(table, thickness, tilt, exposure):
    xyz = table.xyz_at(tilt, thickness) * exposure
    return color.xyz_to_lab(xyz, white=table.white_xyz).astype(np.float32)


def _colour(lab):
    """The ColourImage fields the ROI stage reads: Lab and an empty mask."""
    return SimpleNamespace(lab=lab, mask=SimpleNamespace(mask=np.zeros(lab.shape[:2], bool)))


def test_roi_grid_tiles_cover_the_image():
    rows, cols, (h, w) = roi_grid((600, 300), size_px=255)
    assert rows[-1] + h == 600 and cols[-1] + w == 300
    rows, cols, (h, w) = roi_grid((100, 90), size_px=255)
    assert rows == [0] and cols == [0] and (h, w) == (100, 90)  # ROI larger than the image
    ri, ci = nearest_roi_index((600, 300), *roi_grid((600, 300), size_px=255))
    assert ri[0] == 0 and ri[-1] == 1 and (ci == 0).all()
    with pytest.raises(ValueError, match="stride_px"):
        roi_grid((100, 100), size_px=50, stride_px=60)


@pytest.mark.slow
@pytest.mark.parametrize("exposure", [0.7, 1.0, 1.4])
def test_recovers_roi_thickness_and_exposure(table, model, exposure):
    rng = np.random.default_rng(1)
    H, W = 64, 128
    d = np.where(np.arange(W)[None, :] < 64, 118.0, 146.0) + np.zeros((H, 1))
    tilt = rng.uniform(0, 20, (H, W))
    lab = _render(table, d, tilt, exposure)
    lab += rng.normal(0, 0.3, lab.shape).astype(np.float32)
    rois = roi_grid((H, W), size_px=64)
    fit = fit_roi_thickness(lab, tilt, np.zeros((H, W), bool), model, RoiOptions(), rois=rois)
    assert fit.exposure == pytest.approx(exposure, rel=0.02)
    np.testing.assert_allclose(fit.thickness_nm, [118.0, 146.0], atol=0.3)
    assert np.all(fit.mean_delta_e < 1.0)
    assert np.all(fit.ambiguity_delta_e > 1.0)  # another order is clearly worse
    assert fit.exposure_estimated
    # the blocks' reading agrees: one reading
    assert block_exposure_reading(_colour(lab), tilt, model, RoiOptions(),
                                  exposure=fit.exposure) is None


@pytest.mark.slow
@pytest.mark.parametrize("exposure", [0.6, 0.9])
def test_a_second_exposure_reading_lets_each_population_keep_its_order(table, model, exposure):
    """One ROI holding two populations in different orders (38 and 150 nm), the
    generalization sweep's failure: no ±35 nm band holds both, so the band's reading is
    pulled far off; the blocks' reading (each block at its own order) finds the exposure."""
    rng = np.random.default_rng(2)
    H = W = 96
    yy, xx = np.mgrid[:H, :W]
    d = np.where((yy // 24 + xx // 24) % 3 == 0, 150.0, 38.0)    # 38 nm the majority
    tilt = rng.uniform(0, 20, (H, W))
    lab = _render(table, d, tilt, exposure) + rng.normal(0, 1.0, (H, W, 3)).astype(np.float32)
    fit = fit_roi_thickness(lab, tilt, np.zeros((H, W), bool), model, RoiOptions(),
                            rois=roi_grid((H, W), size_px=96))
    assert abs(fit.exposure / exposure - 1.0) > 0.05
    second = block_exposure_reading(_colour(lab), tilt, model, RoiOptions(),
                                    exposure=fit.exposure)
    assert second == pytest.approx(exposure, rel=0.03)


@pytest.mark.slow
def test_masked_roi_is_nan_and_given_exposure_is_used(table, model):
    H, W = 32, 64
    lab = _render(table, np.full((H, W), 60.0), np.full((H, W), 5.0), 1.0)
    mask = np.zeros((H, W), bool)
    mask[:, 32:] = True
    fit = fit_roi_thickness(lab, np.full((H, W), 5.0), mask, model.with_exposure(3.0),
                            RoiOptions(), rois=roi_grid((H, W), size_px=32), exposure=1.0)
    assert fit.thickness_nm[0] == pytest.approx(60.0, abs=0.2)
    assert np.isnan(fit.thickness_nm[1]) and fit.n_pixels[1] == 0
    assert not fit.exposure_estimated and fit.exposure == 1.0   # not the model's 3.0


def test_the_exposure_scan_finds_a_basin_narrower_than_its_step():
    """Two basins of the exposure's misfit, as on a one-colour scene read at 86 nm or at 394
    nm (the generalization sweep's seed-4 g014): the deeper one (0.61 ΔE00 at exposure
    0.944) lies between two scan nodes that read 1.8, the shallower one (0.85 at 1.587)
    on a node. Refining only the best node returned 1.587; every local minimum is refined."""
    import math

    from microfacet.analysis.roi import EXPOSURE_SCAN, _scan_exposure

    lo, hi, count = EXPOSURE_SCAN
    nodes = np.exp(np.linspace(math.log(lo), math.log(hi), count))
    assert np.min(np.abs(np.log(nodes / 0.944))) > 0.05          # between two nodes
    assert np.min(np.abs(np.log(nodes / 1.587))) < 0.001         # on a node

    def misfit(log_e):
        return min(0.61 + 20.0 * abs(log_e - math.log(0.944)),
                   0.85 + 20.0 * abs(log_e - math.log(1.587)))

    assert _scan_exposure(misfit) == pytest.approx(0.944, rel=0.005)
    # one basin: found by its own refinement; at the scan's end: the end
    assert _scan_exposure(lambda x: abs(x - math.log(1.3))) == pytest.approx(1.3, rel=0.005)
    assert _scan_exposure(lambda x: -x) == pytest.approx(hi, rel=0.005)
    # NaN where the model has no colour (very low exposures here): ignored, not returned
    assert _scan_exposure(lambda x: math.nan if x < math.log(0.3) else misfit(x)) \
        == pytest.approx(0.944, rel=0.005)
