"""ISO 25178-72 ``.x3p`` files (microfacet.io.x3p): exact round trips, the layout of the
archive checked by hand (zip + XML + numpy), the four data types, invalid points, inline
data, refusals naming the file, and SurfaceTopography's reader as an independent check."""

from __future__ import annotations

import hashlib
import xml.etree.ElementTree as ElementTree
import zipfile

import numpy as np
import pytest

from microfacet.core.errors import InputError
from microfacet.io.x3p import read_x3p, write_x3p

NS = "{http://www.opengps.eu/2008/ISO5436_2}"


def _heights(dtype=np.float64, shape=(7, 11), seed=0):
    rng = np.random.default_rng(seed)
    h = (rng.normal(0, 3, shape) + 50.0).astype(dtype)
    h[1, 2] = np.nan
    h[-1, 0] = np.nan
    return h


@pytest.mark.parametrize("dtype", [np.float64, np.float32])
def test_round_trip_is_exact(tmp_path, dtype):
    h = _heights(dtype)
    write_x3p(tmp_path / "h.x3p", h, (0.7, 0.3))
    m = read_x3p(tmp_path / "h.x3p")
    assert m.height_um.dtype == dtype and m.height_um.shape == h.shape
    np.testing.assert_array_equal(m.height_um, h)          # NaN where NaN, bit-exact else
    assert m.pixel_size_um == (0.7, 0.3)
    assert m.source.startswith("x3p")


def test_archive_layout_read_by_hand(tmp_path):
    """Increments in metres, x fastest in data.bin, MD5s, validity bits: parsed with zipfile,
    ElementTree and numpy, not with the module's reader."""
    h = _heights(np.float64, shape=(3, 5))
    write_x3p(tmp_path / "h.x3p", h, (2.0, 0.5), data_type="D")
    with zipfile.ZipFile(tmp_path / "h.x3p") as zf:
        xml = zf.read("main.xml")
        root = ElementTree.fromstring(xml)
        data = zf.read("bindata/data.bin")
        valid = zf.read("bindata/valid.bin")
        checksum = zf.read("md5checksum.hex").decode()
    assert root.tag == NS + "ISO5436_2"
    r1 = root.find("Record1")
    assert r1.findtext("FeatureType") == "SUR"
    assert float(r1.findtext("Axes/CX/Increment")) == pytest.approx(0.5e-6, rel=1e-15)
    assert float(r1.findtext("Axes/CY/Increment")) == pytest.approx(2.0e-6, rel=1e-15)
    assert r1.findtext("Axes/CZ/DataType") == "D"
    z_scale = float(r1.findtext("Axes/CZ/Increment"))
    r3 = root.find("Record3")
    assert (r3.findtext("MatrixDimension/SizeX"), r3.findtext("MatrixDimension/SizeY")) == \
        ("5", "3")
    raw = np.frombuffer(data, "<f8").reshape(3, 5)             # rows = y, x fastest
    np.testing.assert_allclose(raw * z_scale, h * 1e-6, rtol=1e-15)
    assert r3.findtext("DataLink/MD5ChecksumPointData").lower() == hashlib.md5(data).hexdigest()
    bits = np.unpackbits(np.frombuffer(valid, np.uint8), bitorder="little")[:15]
    np.testing.assert_array_equal(bits.reshape(3, 5).astype(bool), np.isfinite(h))
    assert checksum.split()[0].lower() == hashlib.md5(xml).hexdigest()


@pytest.mark.parametrize("data_type, dtype", [("L", np.int32), ("I", np.int16)])
def test_integer_data_types_quantize_within_one_step(tmp_path, data_type, dtype):
    h = _heights(np.float64)
    write_x3p(tmp_path / "h.x3p", h, 1.0, data_type=data_type)
    m = read_x3p(tmp_path / "h.x3p")
    ok = np.isfinite(h)
    np.testing.assert_array_equal(np.isfinite(m.height_um), ok)
    step = (np.nanmax(h) - np.nanmin(h)) / (np.iinfo(dtype).max - float(np.iinfo(dtype).min))
    assert np.max(np.abs(m.height_um[ok] - h[ok])) <= 0.5 * step * (1 + 1e-9)


def _write_raw(path, main_xml, members):
    with zipfile.ZipFile(path, "w") as zf:
        zf.writestr("main.xml", main_xml)
        for name, data in members.items():
            zf.writestr(name, data)


def _main(feature="SUR", cz_type="D", link=True, extra="", size=(2, 2)):
    data = ("<DataLink><PointDataLink>bindata/data.bin</PointDataLink>" + extra + "</DataLink>"
            if link else "<DataList><Datum>1.5e-6</Datum><Datum></Datum><Datum>-2e-6</Datum>"
            "<Datum>0</Datum></DataList>")
    return (f'<?xml version="1.0"?><p:ISO5436_2 xmlns:p="http://www.opengps.eu/2008/ISO5436_2">'
            f"<Record1><Revision>ISO5436 - 2000</Revision><FeatureType>{feature}</FeatureType>"
            "<Axes><CX><AxisType>I</AxisType><Increment>1e-6</Increment></CX>"
            "<CY><AxisType>I</AxisType><Increment>2e-6</Increment></CY>"
            f"<CZ><AxisType>A</AxisType><DataType>{cz_type}</DataType></CZ></Axes></Record1>"
            f"<Record3><MatrixDimension><SizeX>{size[0]}</SizeX><SizeY>{size[1]}</SizeY>"
            f"<SizeZ>1</SizeZ></MatrixDimension>{data}</Record3></p:ISO5436_2>")


def test_metres_without_increment_and_inline_data(tmp_path):
    raw = np.array([[1e-6, 2e-6], [np.nan, -5e-7]], "<f4")
    _write_raw(tmp_path / "b.x3p", _main(cz_type="F"), {"bindata/data.bin": raw.tobytes()})
    m = read_x3p(tmp_path / "b.x3p")                          # F: float32 µm
    np.testing.assert_allclose(m.height_um, raw.astype(np.float64) * 1e6, rtol=1e-7)
    assert m.pixel_size_um == pytest.approx((2.0, 1.0))
    _write_raw(tmp_path / "i.x3p", _main(link=False), {})
    m = read_x3p(tmp_path / "i.x3p")
    np.testing.assert_allclose(m.height_um, [[1.5, np.nan], [-2.0, 0.0]], rtol=1e-12)


@pytest.mark.parametrize("main, members, match", [
    (_main(feature="PRF"), {}, "feature type 'PRF'"),
    (_main(cz_type="Q"), {"bindata/data.bin": b""}, "data type 'Q'"),
    (_main(), {"bindata/data.bin": b"\0" * 8}, "holds 8 bytes, the grid needs 32"),
    (_main(), {}, "lacks the member 'bindata/data.bin'"),
    (_main(extra="<MD5ChecksumPointData>00</MD5ChecksumPointData>"),
     {"bindata/data.bin": b"\0" * 32}, "MD5 checksum"),
    (_main(size=(2, 0)), {}, "grid 2×0×1"),
    ("<root/>", {}, "not an ISO 5436-2"),
    ("<unclosed>", {}, "not well-formed"),
])
def test_malformed_files_are_refused_naming_the_file(tmp_path, main, members, match):
    _write_raw(tmp_path / "bad.x3p", main, members)
    with pytest.raises(InputError, match=match) as exc:
        read_x3p(tmp_path / "bad.x3p")
    assert "bad.x3p" in str(exc.value) and "\n" not in str(exc.value)


def test_not_a_zip_and_missing_file(tmp_path):
    (tmp_path / "n.x3p").write_bytes(b"not a zip")
    with pytest.raises(InputError, match="n.x3p: not an .x3p file"):
        read_x3p(tmp_path / "n.x3p")
    with pytest.raises(InputError, match="gone.x3p: file not found"):
        read_x3p(tmp_path / "gone.x3p")


def test_bad_arguments_are_refused(tmp_path):
    with pytest.raises(ValueError, match="height_um"):
        write_x3p(tmp_path / "a.x3p", np.zeros(3), 1.0)
    with pytest.raises(ValueError, match="pixel_size_um"):
        write_x3p(tmp_path / "a.x3p", np.zeros((2, 2)), (1.0, 0.0))
    with pytest.raises(ValueError, match="data_type"):
        write_x3p(tmp_path / "a.x3p", np.zeros((2, 2)), 1.0, data_type="X")
    assert not list(tmp_path.iterdir())


@pytest.mark.filterwarnings("ignore:Function/property `Sq` is deprecated")
@pytest.mark.parametrize("dtype", [np.float64, np.float32])
def test_surface_topography_reads_our_file(tmp_path, dtype):
    st = pytest.importorskip("SurfaceTopography")
    h = _heights(dtype, shape=(9, 6))
    write_x3p(tmp_path / "h.x3p", h, (0.4, 0.25))
    t = st.read_topography(str(tmp_path / "h.x3p"))
    assert t.nb_grid_pts == (6, 9)                             # (x, y)
    np.testing.assert_allclose(t.pixel_size, (0.25e-6, 0.4e-6), rtol=1e-12)
    theirs = np.ma.filled(np.ma.asarray(t.heights(), float), np.nan).T   # image orientation
    np.testing.assert_allclose(theirs, h.astype(np.float64) * 1e-6, rtol=1e-12)
    ok = np.isfinite(h)
    rms = np.sqrt(np.mean((h[ok] - h[ok].mean()) ** 2)) * 1e-6
    assert t.rms_height_from_area() == pytest.approx(rms, rel=1e-9)


@pytest.mark.parametrize("data_type", ["D", "F", "L", "I"])
def test_we_read_surface_topography_files(tmp_path, data_type):
    """Files written by SurfaceTopography's own X3P writer, in each data type, with an
    undefined point: our heights match its reading of them."""
    st = pytest.importorskip("SurfaceTopography")
    rng = np.random.default_rng(3)
    z = rng.normal(0, 2, (8, 5))                               # its [x, y], µm
    mask = np.zeros_like(z, bool)
    mask[2, 3] = True
    t = st.Topography(np.ma.masked_array(z, mask), (8 * 0.5, 5 * 0.3), unit="µm")
    t.to_x3p(str(tmp_path / "st.x3p"), dtype=data_type)
    m = read_x3p(tmp_path / "st.x3p")
    ref = np.ma.filled(np.ma.asarray(st.read_topography(str(tmp_path / "st.x3p")).heights(),
                                     float), np.nan).T * 1e6
    assert m.height_um.shape == (5, 8) and np.isnan(m.height_um[3, 2])
    np.testing.assert_allclose(m.height_um, ref, rtol=1e-6, atol=1e-9)
    assert m.pixel_size_um == pytest.approx((0.3, 0.5), rel=1e-12)


# ------------------------------------------------------------- x3pio as an independent oracle
@pytest.mark.parametrize("data_type", ["D", "F", "L", "I"])
def test_x3pio_reads_our_files_with_their_checksums(tmp_path, data_type):
    """x3pio (MIT, an independent ISO 25178-72 implementation) reads what we write with every
    MD5 checksum verified, the same heights (within one quantization step for the integer
    types; their z offset is in x3pio's placement, applied by ``globalized``), the same
    spacing and the same invalid points."""
    x3pio = pytest.importorskip("x3pio")
    h = _heights(shape=(9, 6))
    write_x3p(tmp_path / "h.x3p", h, (0.4, 0.25), data_type=data_type)
    layer = x3pio.read(tmp_path / "h.x3p", verify=True).globalized().layers[0]
    assert layer.shape == h.shape
    assert layer.spacing == pytest.approx((0.25e-6, 0.4e-6), rel=1e-12)   # (x, y), m
    np.testing.assert_array_equal(~layer.valid, np.isnan(h))
    ok = np.isfinite(h)
    step = {"D": 0.0, "F": 1e-6 * 60 * 2.0 ** -23, "L": 1e-6 * np.ptp(h[ok]) / 2.0 ** 31,
            "I": 1e-6 * np.ptp(h[ok]) / 2.0 ** 15}[data_type]
    np.testing.assert_allclose(np.asarray(layer.z)[ok], h[ok] * 1e-6, rtol=1e-12,
                               atol=1.01 * step)


def test_x3pio_sees_a_changed_byte(tmp_path):
    """Our checksums are real: one changed height byte is caught by x3pio's verification."""
    x3pio = pytest.importorskip("x3pio")
    write_x3p(tmp_path / "h.x3p", np.arange(12.0).reshape(3, 4), 0.5)
    with zipfile.ZipFile(tmp_path / "h.x3p") as zf:
        members = {n: zf.read(n) for n in zf.namelist()}
    data = bytearray(members["bindata/data.bin"])
    data[8] ^= 0x01
    members["bindata/data.bin"] = bytes(data)
    with zipfile.ZipFile(tmp_path / "bad.x3p", "w") as zf:
        for n, b in members.items():
            zf.writestr(n, b)
    with pytest.raises(x3pio.X3pChecksumError):
        x3pio.read(tmp_path / "bad.x3p", verify=True)


@pytest.mark.parametrize("z_type", ["D", "F", "L", "I"])
def test_we_read_x3pio_files(tmp_path, z_type):
    """Files x3pio writes, in each data type, with an unmeasured point: our heights (µm),
    pixel size and NaN match x3pio's own reading of them."""
    x3pio = pytest.importorskip("x3pio")
    rng = np.random.default_rng(5)
    z = rng.normal(0, 2e-6, (5, 8))                            # metres, rows = y
    z[3, 2] = np.nan
    x3pio.write(tmp_path / "x.x3p", z, x_scale=0.5e-6, y_scale=0.3e-6,
                z_type=x3pio.DataType(z_type))
    m = read_x3p(tmp_path / "x.x3p")
    theirs = x3pio.read(tmp_path / "x.x3p").layers[0]
    ref = np.where(np.asarray(theirs.valid), np.asarray(theirs.z), np.nan) * 1e6
    assert m.height_um.shape == (5, 8) and np.isnan(m.height_um[3, 2])
    np.testing.assert_allclose(m.height_um, ref, rtol=1e-6, atol=1e-9)
    assert m.pixel_size_um == pytest.approx((0.3, 0.5), rel=1e-12)
