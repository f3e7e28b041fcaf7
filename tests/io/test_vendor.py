"""Vendor z-stack files (microfacet.io.vendor): a Zeiss .czi written with Zeiss' own library
(pylibCZIrw) is read as a stack with its pixel size, z step, channel order and bit depth from
the file, and analyses like the same slices in a stack folder."""

from __future__ import annotations

import numpy as np
import pytest

pyczi = pytest.importorskip("pylibCZIrw.czi")

from microfacet.core.errors import InputError  # noqa: E402
from microfacet.io import vendor  # noqa: E402
from microfacet.io.stack import read_stack  # noqa: E402

FIXTURE = "fixtures/stacks/nd-fixture"


def _write_czi(path, planes, *, scale_um=(0.216, 0.216, 0.498)):
    """Planes (Z, H, W, 3) RGB uint8/uint16 or (Z, H, W) grey, written as a CZI z-stack."""
    with pyczi.create_czi(str(path), exist_ok=True) as w:
        for z, img in enumerate(planes):
            data = np.ascontiguousarray(img[..., ::-1] if img.ndim == 3 else img[..., None])
            w.write(data=data, plane={"Z": z, "C": 0, "T": 0})
        if scale_um is not None:
            x, y, zs = scale_um
            w.write_metadata(document_name="t", channel_names={0: "c"}, scale_x=x * 1e-6,
                             scale_y=y * 1e-6, scale_z=zs * 1e-6)
    return path


@pytest.fixture(scope="module")
def fixture_czi(tmp_path_factory):
    st = read_stack(FIXTURE)
    planes = [st.read_slice(int(i), np.uint8) for i in st.z_order]
    step = float(np.median(np.diff(np.sort(st.z_um))))
    path = tmp_path_factory.mktemp("czi") / "nd.czi"
    return _write_czi(path, planes, scale_um=(0.216, 0.216, step)), st, step


def test_the_file_gives_pixel_size_z_step_and_rgb_planes(fixture_czi):
    path, st, step = fixture_czi
    c = read_stack(path)
    assert (c.n_slices, c.shape, c.dtype, c.channels) == (20, (256, 256), np.uint8, 3)
    assert c.pixel_size_yx_um == pytest.approx((0.216, 0.216), rel=1e-9)
    np.testing.assert_allclose(np.diff(c.z_um), step, rtol=1e-9)
    assert "CZI metadata of nd.czi" in c.sources["pixel_size_um"] == c.sources["z_um"]
    for k, i in enumerate(st.z_order):          # BGR in the file, RGB here
        np.testing.assert_array_equal(c.read_slice(k, np.uint8), st.read_slice(int(i),
                                                                                np.uint8))


def test_given_values_win_over_the_file(fixture_czi):
    c = read_stack(fixture_czi[0], pixel_size_um=0.5, z_step_um=1.0)
    assert c.pixel_size_yx_um == (0.5, 0.5) and c.sources["pixel_size_um"] == "given"
    np.testing.assert_allclose(c.z_um, np.arange(20.0))


def test_sixteen_bit_grey_and_non_square_pixels(tmp_path):
    rng = np.random.default_rng(0)
    planes = rng.integers(0, 65535, size=(3, 12, 9), dtype=np.uint16)
    c = read_stack(_write_czi(tmp_path / "g.czi", planes, scale_um=(0.2, 0.3, 0.5)))
    assert (c.dtype, c.channels, c.pixel_size_yx_um) == (np.uint16, 1, pytest.approx((0.3, 0.2)))
    np.testing.assert_array_equal(c.read_slice(2, np.uint16), planes[2])


def test_a_file_without_scaling_asks_for_the_values(tmp_path):
    planes = np.zeros((2, 8, 8, 3), np.uint8)
    path = _write_czi(tmp_path / "n.czi", planes, scale_um=None)
    with pytest.raises(InputError, match="pixel_size_um|pixel size"):
        read_stack(path)
    assert read_stack(path, pixel_size_um=0.3, z_step_um=0.5).n_slices == 2


def test_without_the_extra_the_message_says_what_to_install(tmp_path, monkeypatch):
    class Missing:
        def open_czi(self, *a, **k):
            raise ModuleNotFoundError("No module named 'pylibCZIrw'")
    monkeypatch.setattr(vendor, "pyczi", Missing())
    (tmp_path / "x.czi").write_bytes(b"ZISRAWFILE")
    with pytest.raises(InputError, match=r'microfacet\[microscopes\]'):
        read_stack(tmp_path / "x.czi")


def test_a_damaged_file_is_named(tmp_path):
    (tmp_path / "bad.czi").write_bytes(b"not a czi at all")
    with pytest.raises(InputError, match="bad.czi"):
        read_stack(tmp_path / "bad.czi")


@pytest.mark.slow
def test_it_analyses_like_the_stack_folder(fixture_czi, tmp_path):
    """The Done-when of issue 25 for .czi: the same thickness mixture as the slices in the
    stack folder (the analysis does not depend on where z starts)."""
    from microfacet.analysis.pipeline import analyse_stack
    path, st, _ = fixture_czi
    a = analyse_stack(read_stack(path)).thickness_fit.mixture
    b = analyse_stack(st).thickness_fit.mixture
    assert len(a.components) == len(b.components)
    np.testing.assert_allclose(np.array(a.components), np.array(b.components), atol=0.05)
