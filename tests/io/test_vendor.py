"""Vendor z-stack files (microfacet.io.vendor): a Zeiss .czi written with Zeiss' own library
(pylibCZIrw), a Leica .lif and a Nikon .nd2 written here by the formats' layouts (read back by
liffile and nd2, independent readers) are read as stacks with their pixel size, z step,
channel order and bit depth from the file, one series of several chosen by `series`, and
analyse like the same slices in a stack folder."""

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


def _write_lif(path, planes, *, scale_um=(0.216, 0.216, 0.498), more=()):
    """Planes (Z, H, W, 3) RGB or (Z, H, W) grey as a LIF (version 2) of one z-stack image
    (and one more image per array in ``more``): the XML header in UTF-16 and the memory
    blocks, BGR interleaved with channel tags 3, 2, 1 as LAS X stores colour, dimensions X, Y,
    Z with their lengths in metres."""
    elements, blocks = [], [("MemBlock_0", b"")]
    for i, arr in enumerate([np.asarray(planes), *map(np.asarray, more)], start=1):
        xml, data = _lif_image(arr, scale_um, f"zstack{i}", i)
        elements.append(xml)
        blocks.append((f"MemBlock_{i}", data))
    xml = ('<LMSDataContainerHeader Version="2"><Element Name="project" UniqueID="0"><Data>'
           '<Experiment/></Data><Memory Size="0" MemoryBlockID="MemBlock_0"/><Children>'
           f'{"".join(elements)}</Children></Element></LMSDataContainerHeader>')
    xb = xml.encode("utf-16-le")
    out = bytearray(struct.pack("<IIBI", 0x70, len(xb) + 5, 0x2A, len(xml)) + xb)
    for mid, block in blocks:
        out += struct.pack("<IIBQBI", 0x70, 0, 0x2A, len(block), 0x2A, len(mid))
        out += mid.encode("utf-16-le") + block
    path.write_bytes(bytes(out))
    return path


def _lif_image(planes, scale_um, name: str, uid: int) -> tuple[str, bytes]:
    """The XML element of one LIF z-stack image and its memory block's bytes."""
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
    return (f'<Element Name="{name}" UniqueID="{uid}"><Data><Image><ImageDescription>'
            f'<Channels>{chans}</Channels><Dimensions>{dims}</Dimensions></ImageDescription>'
            f'</Image></Data><Memory Size="{len(data)}" MemoryBlockID="MemBlock_{uid}"/>'
            '<Children/></Element>'), data


def _lite_variant(name: str, value) -> bytes:
    """One record of Nikon's "lite variant" metadata encoding (ND2 version 3): a type byte,
    the name's length and UTF-16 name, then the value; a level (dict) holds its item count,
    its byte length and its children, followed by one 8-byte offset per child."""
    head = lambda kind: bytes([kind, len(name) + 1]) + (name + "\0").encode("utf-16-le")  # noqa: E731
    if isinstance(value, dict):
        kids, h = b"".join(_lite_variant(k, v) for k, v in value.items()), head(11)
        return (h + struct.pack("<IQ", len(value), len(h) + 12 + len(kids)) + kids
                + bytes(8 * len(value)))
    if isinstance(value, bool):
        return head(1) + struct.pack("<B", value)
    if isinstance(value, int):
        return head(3) + struct.pack("<I", value)
    if isinstance(value, float):
        return head(6) + struct.pack("<d", value)
    return head(8) + (value + "\0").encode("utf-16-le")


def _write_nd2(path, planes, *, scale_um=(0.216, 0.216, 0.498), positions=1):
    """Planes (Z, H, W, 3) RGB or (Z, H, W) grey as an ND2 (version 3) z-stack, repeated at
    ``positions`` XY positions (plane values + 1 at each next one): chunks of magic
    0x0ABECEDA with the attributes, picture metadata (calibration) and experiment (an XY loop
    around a Z loop with its step) as lite variants, each frame 4096 bytes after its chunk's
    start behind an 8-byte time stamp, and the chunk map at the end."""
    planes = np.asarray(planes)
    z, h, w = planes.shape[:3]
    comp, bits = (planes.shape[3] if planes.ndim == 4 else 1), 8 * planes.dtype.itemsize
    out, cmap = bytearray(), {}

    def chunk(name: str, data: bytes, name_len: int | None = None):
        cmap[name] = (len(out), len(data))
        nb = name.encode()
        out.extend(struct.pack("<IIQ", 0x0ABECEDA, name_len or len(nb), len(data))
                   + nb.ljust(name_len or len(nb), b"\0") + data)

    chunk("ND2 FILE SIGNATURE CHUNK NAME01!", b"Ver3.0".ljust(64, b"\0"))
    chunk("ImageAttributesLV!", _lite_variant("SLxImageAttributes", {
        "uiWidth": w, "uiWidthBytes": w * comp * bits // 8, "uiHeight": h, "uiComp": comp,
        "uiBpcInMemory": bits, "uiBpcSignificant": bits,
        "uiSequenceCount": z * positions, "eCompression": 2}))
    plane = {"uiCompCount": comp, "sDescription": "RGB" if comp == 3 else "Mono",
             "pFluorescentProbe": {"m_sName": ""}}
    chunk("ImageMetadataSeqLV|0!", _lite_variant("SLxPictureMetadata", {
        "bCalibrated": scale_um is not None,
        "dCalibration": float(scale_um[1]) if scale_um else 1.0,
        "sPicturePlanes": {"uiCount": 1, "sPlaneNew": {"a0": plane}}}))
    step = float(scale_um[2]) if scale_um else 0.0
    zloop = {"eType": 4, "uLoopPars": {"uiCount": z, "dZStep": step, "dZLow": 0.0,
                                       "dZHigh": (z - 1) * step, "iType": 0}}
    exp = zloop if positions == 1 else {"eType": 2, "uLoopPars": {"Points": {
        f"a{i}": {"dPosX": 100.0 * i, "dPosY": 0.0} for i in range(positions)}},
        "ppNextLevelEx": {"a0": zloop}}
    chunk("ImageMetadataLV!", _lite_variant("SLxExperiment", exp))
    for p in range(positions):
        for k in range(z):
            frame = np.ascontiguousarray(planes[k] + p).tobytes()
            chunk(f"ImageDataSeq|{p * z + k}!", struct.pack("<d", k) + frame, 4072)
    chunk("CustomData|AcqTimesCache!", np.arange(z * positions, dtype=np.float64).tobytes())
    sig = b"ND2 CHUNK MAP SIGNATURE 0000001!"
    body = b"".join(n.encode() + struct.pack("<QQ", *v) for n, v in cmap.items()
                    if not n.startswith("ND2"))
    where = len(out)
    chunk("ND2 FILEMAP SIGNATURE NAME 0001!", body + sig + bytes(16))
    path.write_bytes(bytes(out) + sig + struct.pack("<Q", where))
    return path


_WRITERS = {"czi": _write_czi, "lif": _write_lif, "nd2": _write_nd2}
_READERS = {"czi": "pylibCZIrw.czi", "lif": "liffile", "nd2": "nd2"}


@pytest.fixture(scope="module", params=list(_WRITERS))
def vendor_file(request, tmp_path_factory):
    """The fixture's slices (in z order, RGB) as a vendor z-stack file."""
    pytest.importorskip(_READERS[request.param])
    st = read_stack(FIXTURE)
    planes = np.stack([st.read_slice(int(i), np.uint8) for i in st.z_order])
    step = float(np.median(np.diff(np.sort(st.z_um))))
    path = tmp_path_factory.mktemp(request.param) / f"nd.{request.param}"
    return _WRITERS[request.param](path, planes, scale_um=(0.216, 0.216, step)), st, step


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


@pytest.mark.parametrize("kind", list(_WRITERS))
def test_sixteen_bit_grey_and_non_square_pixels(tmp_path, kind):
    """16-bit grey planes; the pixel's y and x sizes apart where the format has both (an
    ND2 calibration is one number: square pixels)."""
    pytest.importorskip(_READERS[kind])
    rng = np.random.default_rng(0)
    planes = rng.integers(0, 65535, size=(3, 12, 9), dtype=np.uint16)
    c = read_stack(_WRITERS[kind](tmp_path / f"g.{kind}", planes, scale_um=(0.2, 0.3, 0.5)))
    yx = (0.3, 0.3) if kind == "nd2" else (0.3, 0.2)
    assert (c.dtype, c.channels, c.pixel_size_yx_um) == (np.uint16, 1, pytest.approx(yx))
    np.testing.assert_allclose(np.diff(c.z_um), 0.5, rtol=1e-9)
    np.testing.assert_array_equal(c.read_slice(2, np.uint16), planes[2])


def _two_series(path, kind, planes):
    """A file of two z-stacks: the planes, and the planes + 1 (CZI scenes at two places, LIF
    images, ND2 XY positions)."""
    if kind == "nd2":
        return _write_nd2(path, planes, positions=2)
    if kind == "lif":
        return _write_lif(path, planes, more=[planes + 1])
    with pyczi.create_czi(str(path), exist_ok=True) as w:
        for scene in (0, 1):
            for z, img in enumerate(planes + scene):
                w.write(data=np.ascontiguousarray(img[..., None]), plane={"Z": z, "C": 0,
                                                                          "T": 0},
                        scene=scene, location=(100 * scene, 0))
        w.write_metadata(document_name="t", channel_names={0: "c"}, scale_x=0.2e-6,
                         scale_y=0.2e-6, scale_z=0.5e-6)
    return path


@pytest.mark.parametrize("kind", list(_WRITERS))
def test_series_chooses_one_z_stack_of_several(tmp_path, kind):
    pytest.importorskip(_READERS[kind])
    planes = np.random.default_rng(1).integers(0, 250, size=(3, 6, 5), dtype=np.uint8)
    path = _two_series(tmp_path / f"two.{kind}", kind, planes)
    for series in (0, 1):
        c = read_stack(path, series=series)
        assert (c.n_slices, c.shape, c.series) == (3, (6, 5), series)
        for k in range(3):
            np.testing.assert_array_equal(c.read_slice(k, np.uint8), planes[k] + series)
    with pytest.raises(InputError, match=r"series 2 does not exist: the file holds 2 .*"
                                         r"\(series 0 to 1\)") as e:
        read_stack(path, series=2)
    assert e.value.param == "series" and path.name in str(e.value)


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


def test_series_from_stack_json(tmp_path):
    """stack.json's `series` picks the z-stack; the caller's wins over it; a TIFF has one
    series; a series is a whole number."""
    import json
    planes = np.random.default_rng(2).integers(0, 250, size=(3, 6, 5), dtype=np.uint8)
    _two_series(tmp_path / "two.czi", "czi", planes)
    (tmp_path / "stack.json").write_text(json.dumps(
        {"format": "microfacet-stack/1", "tiff": "two.czi", "series": 1}))
    assert read_stack(tmp_path).read_slice(0, np.uint8)[0, 0] == planes[0, 0, 0] + 1
    assert read_stack(tmp_path, series=0).read_slice(0, np.uint8)[0, 0] == planes[0, 0, 0]
    with pytest.raises(InputError, match="whole number") as e:
        read_stack(tmp_path / "two.czi", series=0.5)
    assert e.value.param == "series"
    (tmp_path / "stack.json").write_text(json.dumps(
        {"format": "microfacet-stack/1", "tiff": "two.czi", "series": 1.5}))
    with pytest.raises(InputError, match=r"key 'series': must be a whole number"):
        read_stack(tmp_path)
    import tifffile
    tifffile.imwrite(tmp_path / "s.tif", planes, photometric="minisblack")
    (tmp_path / "stack.json").write_text(json.dumps(
        {"format": "microfacet-stack/1", "tiff": "s.tif", "series": 1, "pixel_size_um": 0.2,
         "z_step_um": 0.5}))
    with pytest.raises(InputError, match="a TIFF holds one series"):
        read_stack(tmp_path)


@pytest.mark.slow
def test_series_and_pixel_size_on_the_command_line(tmp_path):
    """--series picks the z-stack and --pixel-size-um wins over the file's value."""
    import json

    from microfacet.cli import main
    planes = np.random.default_rng(2).integers(0, 250, size=(3, 6, 5), dtype=np.uint8)
    _two_series(tmp_path / "two.czi", "czi", planes)
    out = tmp_path / "h"
    assert main(["height", str(tmp_path / "two.czi"), "--series", "1", "--out", str(out),
                 "--pixel-size-um", "0.4"]) == 0
    assert json.loads((out / "height.json").read_text())["pixel_size_um"] == 0.4
    assert main(["height", str(tmp_path / "two.czi"), "--series", "2", "--out",
                 str(tmp_path / "h2")]) == 2              # the option reaches the reader
    assert not (tmp_path / "h2").exists()


@pytest.mark.parametrize("name", ["bad.czi", "bad.lif", "bad.nd2"])
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
