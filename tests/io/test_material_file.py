"""The material file (microfacet.io.material_file): atomic writing and every way a file can be
wrong, each named in one line."""

import io
import json
import zipfile

import numpy as np
import pytest

from microfacet.core.errors import InputError
from microfacet.io.material_file import FORMAT, read_material_file, write_material_file

ARRAYS = {"film_average": np.full((4, 3), 0.25, np.float32),
          "theta_d_deg": np.arange(4.0) * 10.0,
          "wavelength_nm": np.array([400.0, 500.0, 600.0])}


def _npy(a):
    buf = io.BytesIO()
    np.save(buf, a)
    return buf.getvalue()


def _write_raw(path, members):
    with zipfile.ZipFile(path, "w") as zf:
        for name, data in members.items():
            zf.writestr(name, data)
    return path


def _members(**change):
    m = {f"{k}.npy": _npy(v) for k, v in ARRAYS.items()}
    m["metadata.json"] = json.dumps({"format": FORMAT})
    m.update(change)
    return {k: v for k, v in m.items() if v is not None}


def test_round_trip_and_no_leftovers(tmp_path):
    f = tmp_path / "m.npz"
    write_material_file(f, ARRAYS, {"ndf": {"x": 1}, "format": "ignored"})
    arrays, meta = read_material_file(f)
    assert meta == {"format": FORMAT, "ndf": {"x": 1}}
    np.testing.assert_array_equal(arrays["film_average"], ARRAYS["film_average"])
    assert [p.name for p in tmp_path.iterdir()] == ["m.npz"]


def test_a_failed_write_leaves_the_old_file(tmp_path):
    f = tmp_path / "m.npz"
    write_material_file(f, ARRAYS, {})
    before = f.read_bytes()
    with pytest.raises(ValueError, match="theta_d_deg"):
        write_material_file(f, {**ARRAYS, "theta_d_deg": np.zeros((2, 2))}, {})
    assert f.read_bytes() == before and len(list(tmp_path.iterdir())) == 1


@pytest.mark.parametrize("change, message", [
    ({"metadata.json": None}, "no metadata.json"),
    ({"film_average.npy": None}, "no film_average.npy"),
    ({"metadata.json": json.dumps({"format": "other/1"})}, "format 'other/1'"),
    ({"metadata.json": "{"}, "metadata.json: invalid JSON"),
    ({"metadata.json": '{"format": "microfacet-brdf/1", "format": "x"}'}, "given twice"),
    ({"film_average.npy": _npy(np.full((4, 2), 0.2, np.float32))}, "shape"),
    ({"film_average.npy": _npy(np.full((4, 3), 0.2))}, "float32"),
    ({"film_average.npy": _npy(np.full((4, 3), 1.5, np.float32))}, r"\[0, 1\]"),
    ({"theta_d_deg.npy": _npy(np.array([0.0, 1.0, 5.0, 6.0]))}, "uniform"),
    ({"theta_d_deg.npy": _npy(np.array([5.0, 10.0, 15.0, 20.0]))}, "start at 0"),
])
def test_bad_files_are_named(tmp_path, change, message):
    f = _write_raw(tmp_path / "bad.npz", _members(**change))
    with pytest.raises(InputError, match=message) as exc:
        read_material_file(f)
    assert "bad.npz" in str(exc.value) and "\n" not in str(exc.value)


def test_not_a_zip_and_missing(tmp_path):
    (tmp_path / "x.npz").write_text("hello")
    with pytest.raises(InputError, match="x.npz: cannot read"):
        read_material_file(tmp_path / "x.npz")
    with pytest.raises(InputError, match="no such file"):
        read_material_file(tmp_path / "none.npz")
