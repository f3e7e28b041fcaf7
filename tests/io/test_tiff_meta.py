"""TIFF physical-size metadata (microfacet.io.tiff_meta): OME, ImageJ, resolution tags, units,
against files written by tifffile with known sizes."""

import numpy as np
import pytest
import tifffile

from microfacet.core.errors import InputError
from microfacet.io.tiff_meta import TiffScale, tiff_scale, unit_um

H, W = 8, 12


def test_tiff_scale_metadata_kinds(tmp_path):
    img = np.zeros((H, W), np.uint8)
    p = tmp_path / "a.tif"
    tifffile.imwrite(p, img, ome=True, metadata={"PhysicalSizeX": 0.5,
                                                 "PhysicalSizeXUnit": "nm"})
    s = tiff_scale(p, "w")
    assert s.pixel_size_yx_um == pytest.approx((5e-4, 5e-4)) and s.z_step_um is None
    tifffile.imwrite(p, img, imagej=True, resolution=(2.0, 4.0),
                     metadata={"unit": "\\u00B5m", "spacing": 3.0})   # as ImageJ writes µm
    s = tiff_scale(p, "w")
    assert s.pixel_size_yx_um == (0.25, 0.5) and s.z_step_um == 3.0
    assert s.source == "ImageJ metadata of a.tif"
    tifffile.imwrite(p, img, imagej=True, resolution=(2.0, 2.0))     # uncalibrated ImageJ
    assert tiff_scale(p, "w").pixel_size_yx_um is None
    tifffile.imwrite(p, img, resolution=(300, 300), resolutionunit="INCH")   # print dpi
    assert tiff_scale(p, "w") == TiffScale(None, None, "metadata of a.tif")
    tifffile.imwrite(p, img, resolution=(40000, 20000), resolutionunit="CENTIMETER")
    assert tiff_scale(p, "w").pixel_size_yx_um == (0.5, 0.25)
    p.write_bytes(b"II*\x00garbage")
    with pytest.raises(InputError, match=r"^w: unreadable TIFF"):
        tiff_scale(p, "w")


def test_units():
    assert unit_um("m") == 1e6 and unit_um("µm") == 1.0 and unit_um("micron") == 1.0
    assert unit_um("Å") == pytest.approx(1e-4) and unit_um("pixel") is None
    assert unit_um("\\u00B5m") == 1.0 and unit_um(None) is None
