"""Instrument height maps (microfacet.io.instruments.read_height_map): a real Alicona ``.al3d``
file against the grid, pixel size, RMS height and RMS gradient its source publishes (computed
here with numpy from our map), float TIFFs with ImageJ / OME / baseline calibration, ``.npy``,
``.x3p``, and the one-line errors (including the missing optional extra)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import tifffile

from microfacet.core.errors import InputError
from microfacet.core.lazy import load
from microfacet.io import instruments
from microfacet.io.instruments import read_height_map
from microfacet.io.tiff_meta import unit_um
from microfacet.io.x3p import write_x3p

FIXTURES = Path(__file__).resolve().parents[2] / "fixtures" / "instrument-heights"
AL3D = FIXTURES / "al3d-1.al3d"


def _rms_gradient(h, pixel_size_um):
    """sqrt(mean((∂h/∂x)² + (∂h/∂y)²)), forward differences on the grid where both exist."""
    h = np.asarray(h, np.float64)
    dy = np.diff(h, axis=0)[:, :-1] / pixel_size_um[0]
    dx = np.diff(h, axis=1)[:-1, :] / pixel_size_um[1]
    return float(np.sqrt(np.mean(dx ** 2 + dy ** 2)))


def test_alicona_al3d_matches_its_published_values():
    pytest.importorskip("SurfaceTopography")
    m = read_height_map(AL3D)
    h = m.height_um
    assert h.dtype == np.float32 and h.shape == (296, 200)          # rows = y, cols = x
    assert np.isfinite(h).all()
    # fixtures/instrument-heights/README.md: 87.6054 × 129.656 µm over 200 × 296 points
    assert m.pixel_size_um == pytest.approx((129.656 / 296, 87.6054 / 200), rel=1e-4)
    rms = np.sqrt(np.mean((h.astype(np.float64) - h.mean(dtype=np.float64)) ** 2))
    assert rms == pytest.approx(7.6883, rel=1e-4)
    assert _rms_gradient(h, m.pixel_size_um) == pytest.approx(0.241553, rel=1e-4)
    assert "al3d" in m.source and "Alicona" in m.source
    # heights ~76 mm from the instrument's reference: the median is taken out for float32
    assert 7e4 < m.offset_um < 8e4 and abs(float(np.median(h))) < 1e-3


@pytest.mark.parametrize("name,shape,size_xy_um,rms_um,rms_gradient,maker", [
    ("plu-1.plu", (576, 768), (1274.88, 956.160), 2.83439, 0.00898358, "Sensofar"),
    ("mnt-1.mnt", (600, 960), (1779.26, 1112.73), 0.0245602, 0.0198990, "mnt"),
])
def test_sensofar_and_mountainsmap_match_their_published_values(name, shape, size_xy_um,
                                                               rms_um, rms_gradient, maker):
    """Grid, physical size, RMS height and RMS gradient from fixtures/instrument-heights/
    README.md (RMS gradient to 2e-5, its six published digits). The .mnt grid is 0.06 %
    non-square: with the x and y spacings swapped its RMS gradient moves by 2e-4."""
    pytest.importorskip("SurfaceTopography")
    m = read_height_map(FIXTURES / name)
    h = m.height_um.astype(np.float64) + m.offset_um
    assert m.height_um.shape == shape and np.isfinite(h).all()
    assert m.pixel_size_um == pytest.approx((size_xy_um[1] / shape[0], size_xy_um[0] / shape[1]),
                                            rel=1e-5)
    assert np.sqrt(np.mean((h - h.mean()) ** 2)) == pytest.approx(rms_um, rel=1e-4)
    assert _rms_gradient(h, m.pixel_size_um) == pytest.approx(rms_gradient, rel=2e-5)
    assert maker in m.source
    if name.endswith(".mnt"):
        swapped = _rms_gradient(h, m.pixel_size_um[::-1])
        assert abs(swapped / rms_gradient - 1) > 1e-4


def test_missing_extra_is_one_line_with_the_pip_command(tmp_path, monkeypatch):
    f = tmp_path / "scan.plu"
    f.write_bytes(b"\0" * 64)
    monkeypatch.setattr(instruments, "SurfaceTopography",
                        load("SurfaceTopography_not_installed_for_this_test"))
    with pytest.raises(InputError) as exc:
        read_height_map(f)
    msg = str(exc.value)
    assert "scan.plu" in msg and 'pip install "microfacet[instruments]"' in msg
    assert "\n" not in msg


def test_unreadable_instrument_file_names_it(tmp_path):
    pytest.importorskip("SurfaceTopography")
    f = tmp_path / "noise.al3d"
    f.write_bytes(np.random.default_rng(0).bytes(300))
    with pytest.raises(InputError, match="noise.al3d: not a height map") as exc:
        read_height_map(f)
    assert "\n" not in str(exc.value)


def test_npy_is_read_in_um_without_pixel_size(tmp_path):
    h = np.array([[0.5, 1.5, np.inf], [np.nan, 2.0, -1.0]])
    np.save(tmp_path / "h.npy", h)
    m = read_height_map(tmp_path / "h.npy")
    assert m.height_um.dtype == np.float32 and m.pixel_size_um is None and m.offset_um == 0
    np.testing.assert_array_equal(m.height_um, np.where(np.isfinite(h), h, np.nan))


def test_imagej_tiff_pixel_size_and_value_unit(tmp_path):
    h = np.arange(12, dtype=np.float32).reshape(3, 4)
    # 2 pixels per nm along x, 4 along y; values in nm
    tifffile.imwrite(tmp_path / "h.tif", h, imagej=True, resolution=(2.0, 4.0),
                     metadata={"unit": "nm", "vunit": "nm", "axes": "YX"})
    m = read_height_map(tmp_path / "h.tif")
    assert m.pixel_size_um == pytest.approx((0.25e-3, 0.5e-3))
    np.testing.assert_allclose(m.height_um, h / 1000.0, rtol=1e-6)
    assert "ImageJ" in m.source


def test_ome_tiff_pixel_size(tmp_path):
    h = np.linspace(-1, 1, 20, dtype=np.float32).reshape(4, 5)
    tifffile.imwrite(tmp_path / "h.ome.tif", h, ome=True, metadata={
        "axes": "YX", "PhysicalSizeX": 0.2, "PhysicalSizeXUnit": "µm",
        "PhysicalSizeY": 300.0, "PhysicalSizeYUnit": "nm"})
    m = read_height_map(tmp_path / "h.ome.tif")
    assert m.pixel_size_um == pytest.approx((0.3, 0.2))
    np.testing.assert_array_equal(m.height_um, h)


def test_baseline_tiff_resolution_in_cm_and_inch(tmp_path):
    h = np.ones((2, 3), np.float64)
    tifffile.imwrite(tmp_path / "cm.tif", h, resolution=(1e4, 5e3), resolutionunit="CENTIMETER")
    assert read_height_map(tmp_path / "cm.tif").pixel_size_um == pytest.approx((2.0, 1.0))
    tifffile.imwrite(tmp_path / "in.tif", h, resolution=(72, 72), resolutionunit="INCH")
    assert read_height_map(tmp_path / "in.tif").pixel_size_um is None   # display DPI
    tifffile.imwrite(tmp_path / "none.tif", h)
    m = read_height_map(tmp_path / "none.tif")
    assert m.pixel_size_um is None and m.height_um.dtype == np.float32


def test_integer_tiff_and_non_length_value_unit_are_refused(tmp_path):
    tifffile.imwrite(tmp_path / "u.tif", np.zeros((2, 2), np.uint16))
    with pytest.raises(InputError, match="u.tif: TIFF samples are uint16"):
        read_height_map(tmp_path / "u.tif")
    tifffile.imwrite(tmp_path / "v.tif", np.zeros((2, 2), np.float32), imagej=True,
                     metadata={"vunit": "degree", "axes": "YX"})
    with pytest.raises(InputError, match="v.tif: ImageJ value unit 'degree'"):
        read_height_map(tmp_path / "v.tif")


def test_x3p_goes_through_our_reader(tmp_path):
    h = np.random.default_rng(1).normal(0, 1, (5, 6))
    write_x3p(tmp_path / "h.x3p", h, (0.5, 0.25))
    m = read_height_map(tmp_path / "h.x3p")
    assert m.height_um.dtype == np.float32 and m.pixel_size_um == (0.5, 0.25)
    np.testing.assert_array_equal(m.height_um, h.astype(np.float32))


def test_missing_file_and_wrong_shapes(tmp_path):
    with pytest.raises(InputError, match="gone.npy: file not found"):
        read_height_map(tmp_path / "gone.npy")
    np.save(tmp_path / "v.npy", np.zeros(4))
    with pytest.raises(InputError, match="v.npy: expected a 2-D height map"):
        read_height_map(tmp_path / "v.npy")
    np.save(tmp_path / "s.npy", np.array(["a"]))
    with pytest.raises(InputError, match="s.npy: .npy must hold a numeric"):
        read_height_map(tmp_path / "s.npy")


def test_unit_table():
    assert unit_um("m") == 1e6 and unit_um("µm") == 1.0 and unit_um("micron") == 1.0
    assert unit_um("Å") == pytest.approx(1e-4) and unit_um("pixel") is None
