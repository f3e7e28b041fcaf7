"""Vendor z-stack files (microfacet.io.vendor): a Zeiss .czi written with Zeiss' own library
(pylibCZIrw) and a Leica .lif written here by the format's layout (read back by liffile, an
independent reader) are read as stacks with their pixel size, z step, channel order and bit
depth from the file, and analyse like the same slices in a stack folder."""

from __future__ import annotations

import struct

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


def _write_lif(path, planes, *, scale_um=(0.216, 0.216, 0.498), name="zstack"):
    """Planes (Z, H, W, 3) RGB or (Z, H, W) grey as a LIF (version 2) of one z-stack image:
    the XML header in UTF-16 and the memory blocks, BGR interleaved with channel tags 3, 2, 1
    as LAS X stores colour, dimensions X, Y, Z with their lengths in metres."""
    planes = np.asarray(planes)
    z, h, w = planes.shape[:3]
    rgb, item = planes.ndim == 4, planes.dtype.itemsize
    nch, res = (3 if rgb else 1), 8 * item
    data = np.ascontiguousarray(planes[..., ::-1] if rgb else planes).tobytes()
    chans = "".join(
        f'<ChannelDescription DataType="0" ChannelTag="{3 - k if rgb else 0}" '
        f'Resolution="{res}" NameOfMeasuredQuantity="" Min="0" Max="{2 ** res - 1}" Unit="" '
        f'LUTName="{"BGR"[k] if rgb else "Gray"}" IsLUTInverted="0" BytesInc="{k * item}" '
        'BitInc="0"/>' for k in range(nch))
    px, (sx, sy, sz) = nch * item, scale_um
    dims = "".join(
        f'<DimensionDescription DimID="{i}" NumberOfElements="{n}" Origin="0" '
        f'Length="{(n - 1) * step * 1e-6!r}" Unit="m" BitInc="0" BytesInc="{inc}"/>'
        for i, n, step, inc in ((1, w, sx, px), (2, h, sy, px * w), (3, z, sz, px * w * h)))
    xml = ('<LMSDataContainerHeader Version="2"><Element Name="project" UniqueID="0"><Data>'
           '<Experiment/></Data><Memory Size="0" MemoryBlockID="MemBlock_0"/><Children>'
           f'<Element Name="{name}" UniqueID="1"><Data><Image><ImageDescription><Channels>'
           f'{chans}</Channels><Dimensions>{dims}</Dimensions></ImageDescription></Image>'
           f'</Data><Memory Size="{len(data)}" MemoryBlockID="MemBlock_1"/><Children/>'
           '</Element></Children></Element></LMSDataContainerHeader>')
    xb = xml.encode("utf-16-le")
    out = bytearray(struct.pack("<IIBI", 0x70, len(xb) + 5, 0x2A, len(xml)) + xb)
    for mid, block in (("MemBlock_0", b""), ("MemBlock_1", data)):
        out += struct.pack("<IIBQBI", 0x70, 0, 0x2A, len(block), 0x2A, len(mid))
        out += mid.encode("utf-16-le") + block
    path.write_bytes(bytes(out))
    return path


@pytest.fixture(scope="module", params=["czi", "lif"])
def vendor_file(request, tmp_path_factory):
    """The fixture's slices (in z order, RGB) as a vendor z-stack file."""
    if request.param == "lif":
        pytest.importorskip("liffile")
    st = read_stack(FIXTURE)
    planes = np.stack([st.read_slice(int(i), np.uint8) for i in st.z_order])
    step = float(np.median(np.diff(np.sort(st.z_um))))
    path = tmp_path_factory.mktemp(request.param) / f"nd.{request.param}"
    write = _write_czi if request.param == "czi" else _write_lif
    return write(path, planes, scale_um=(0.216, 0.216, step)), st, step


def test_the_file_gives_pixel_size_z_step_and_rgb_planes(vendor_file):
    path, st, step = vendor_file
    c = read_stack(path)
    assert (c.n_slices, c.shape, c.dtype, c.channels) == (20, (256, 256), np.uint8, 3)
    assert c.pixel_size_yx_um == pytest.approx((0.216, 0.216), rel=1e-9)
    np.testing.assert_allclose(np.diff(c.z_um), step, rtol=1e-9)
    kind = path.suffix[1:].upper()
    assert f"{kind} metadata of {path.name}" == c.sources["pixel_size_um"] == c.sources["z_um"]
    for k, i in enumerate(st.z_order):          # BGR in the file, RGB here
        np.testing.assert_array_equal(c.read_slice(k, np.uint8), st.read_slice(int(i),
                                                                                np.uint8))


def test_given_values_win_over_the_file(vendor_file):
    c = read_stack(vendor_file[0], pixel_size_um=0.5, z_step_um=1.0)
    assert c.pixel_size_yx_um == (0.5, 0.5) and c.sources["pixel_size_um"] == "given"
    np.testing.assert_allclose(c.z_um, np.arange(20.0))


@pytest.mark.parametrize("kind", ["czi", "lif"])
def test_sixteen_bit_grey_and_non_square_pixels(tmp_path, kind):
    if kind == "lif":
        pytest.importorskip("liffile")
    rng = np.random.default_rng(0)
    planes = rng.integers(0, 65535, size=(3, 12, 9), dtype=np.uint16)
    write = _write_czi if kind == "czi" else _write_lif
    c = read_stack(write(tmp_path / f"g.{kind}", planes, scale_um=(0.2, 0.3, 0.5)))
    assert (c.dtype, c.channels, c.pixel_size_yx_um) == (np.uint16, 1, pytest.approx((0.3, 0.2)))
    np.testing.assert_allclose(np.diff(c.z_um), 0.5, rtol=1e-9)
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


@pytest.mark.parametrize("name", ["bad.czi", "bad.lif"])
def test_a_damaged_file_is_named(tmp_path, name):
    (tmp_path / name).write_bytes(b"not a microscope file at all")
    with pytest.raises(InputError, match=name):
        read_stack(tmp_path / name)


@pytest.mark.slow
def test_it_analyses_like_the_stack_folder(vendor_file):
    """The Done-when of issue 25 for .czi and .lif: the same thickness mixture as the slices
    in the stack folder (the analysis does not depend on where z starts)."""
    from microfacet.analysis.pipeline import analyse_stack
    path, st, _ = vendor_file
    a = analyse_stack(read_stack(path)).thickness_fit.mixture
    b = analyse_stack(st).thickness_fit.mixture
    assert len(a.components) == len(b.components)
    np.testing.assert_allclose(np.array(a.components), np.array(b.components), atol=0.05)
