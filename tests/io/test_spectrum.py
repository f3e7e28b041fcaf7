"""Measured spectra (microfacet.io.spectrum): the dialects of real spectrometer exports
(delimiters, headers, decimal commas, encodings, units), the notes saying what was assumed,
``columns``, and errors naming the file, the line or the option."""

import logging

import numpy as np
import pytest

from microfacet.core.errors import InputError
from microfacet.io import spectrum as spectrum_io
from microfacet.io.spectrum import parse_columns, read_spectrum, read_spectrum_csv
from microfacet.optics.thinfilm import reflectance

FILM, SUB = "TiO2_Jolivet2023_amorphous", "Ti_JohnsonChristy1974"
WL = np.arange(400.0, 751.0, 5.0)
R70 = reflectance(WL, 0.0, 70.0, FILM, SUB)


def _write(path, header, rows, *, delim=",", comma=False, encoding="utf-8", newline="\n",
           preamble=()):
    def fmt(v):
        s = f"{v:.6f}"
        return s.replace(".", ",") if comma else s
    lines = list(preamble) + ([header] if header is not None else [])
    lines += [delim.join(fmt(v) for v in row) for row in rows]
    path.write_bytes((newline.join(lines) + newline).encode(encoding))
    return path


def test_csv_round_trip_and_percent(tmp_path):
    p = tmp_path / "s.csv"
    p.write_text("wavelength_nm,reflectance\n"
                 + "".join(f"{w},{100 * r}\n" for w, r in zip(WL, R70)))
    wl, R2 = read_spectrum_csv(p)
    np.testing.assert_array_equal(wl, WL)
    np.testing.assert_allclose(R2, R70, rtol=1e-9)  # percent values read as fractions


# (header, delimiter, decimal comma, wavelength factor, reflectance factor, encoding,
#  words the notes must contain)
DIALECTS = {
    "comma, fraction": ("wavelength_nm,reflectance", ",", False, 1, 1, "utf-8",
                        ["comma-delimited", "header on line", "in nm", "fraction"]),
    "semicolon, decimal comma, %": ("Wavelength (nm);R (%)", ";", True, 1, 100, "utf-8",
                                    ["semicolon-delimited, decimal comma", "percent"]),
    "tab, lambda, %R": ("lambda\t%R", "\t", False, 1, 100, "utf-8",
                        ["tab-delimited", "no unit in the header", "percent"]),
    "tab, decimal comma, um": ("Wellenlänge [µm]\tReflectance (%)", "\t", True, 1e-3, 100,
                               "utf-8", ["decimal comma", "does not name both", "µm"]),
    "whitespace, units in brackets": ("wavelength (nm) Reflectance (%)", " ", False, 1, 100,
                                      "utf-8", ["whitespace-delimited", "in nm", "percent"]),
    "whitespace, no header, um": (None, " ", False, 1e-3, 1, "utf-8",
                                  ["no header", "column 1 read as wavelength", "read as µm"]),
    "windows-1252 µm": ("Wavelength (µm);Refl.", ";", True, 1e-3, 1, "cp1252",
                        ["Windows-1252", "wavelength in µm"]),
    "utf-16": ("WL_nm\tR", "\t", False, 1, 1, "utf-16", ["tab-delimited", "in nm"]),
}


@pytest.mark.parametrize("name", list(DIALECTS))
def test_dialects_of_real_exports(tmp_path, name, caplog):
    header, delim, comma, wf, rf, enc, words = DIALECTS[name]
    p = _write(tmp_path / "x.txt", header, zip(WL * wf, R70 * rf), delim=delim, comma=comma,
               encoding=enc)
    with caplog.at_level(logging.INFO, logger="microfacet.io.spectrum"):
        s = read_spectrum(p)
    np.testing.assert_allclose(s.wavelength_nm, WL, atol=1e-3)
    np.testing.assert_allclose(s.reflectance, R70, atol=1e-6)
    text = " | ".join(s.notes)
    for w in words:
        assert w in text, (w, text)
    assert all("\n" not in n for n in s.notes)
    for n in s.notes:                      # every note is also logged, naming the file
        assert n in caplog.text
    assert "x.txt" in caplog.text


def test_preamble_markers_bom_crlf_and_trailing_delimiters(tmp_path):
    pre = ["Data from Sample_00001.txt Node", "Date: Tue Jun 11 10:00:00 2024",
           "Integration Time (sec): 1.000000E-1", "Number of Pixels in Spectrum: 71",
           ">>>>>Begin Spectral Data<<<<<"]
    p = tmp_path / "ocean.txt"
    p.write_bytes(b"\xef\xbb\xbf" + "\r\n".join(
        pre + [f"{w:.2f}\t{100 * r:.4f}\t" for w, r in zip(WL, R70)]
        + [">>>>>End Spectral Data<<<<<"]).encode() + b"\r\n")
    s = read_spectrum(p)
    np.testing.assert_allclose(s.reflectance, R70, atol=1e-6)
    assert s.columns == ("column 1", "column 2")
    assert any("no header" in n for n in s.notes)


def test_comment_header_and_header_case(tmp_path):
    p = tmp_path / "c.txt"
    p.write_text("# WAVELENGTH REFLECTANCE\n" + "".join(f"{w} {r}\n" for w, r in zip(WL, R70)))
    s = read_spectrum(p)
    assert s.columns == ("WAVELENGTH", "REFLECTANCE")
    np.testing.assert_allclose(s.reflectance, R70, atol=1e-12)


def test_columns_found_by_name_among_others(tmp_path):
    p = _write(tmp_path / "m.csv", "Index,Dark,Reflectance (%),Wavelength_nm",
               [(i, 0.0, 100 * r, w) for i, (w, r) in enumerate(zip(WL, R70))])
    s = read_spectrum(p)
    assert s.columns == ("Wavelength_nm", "Reflectance (%)")
    np.testing.assert_allclose(s.reflectance, R70, atol=1e-6)


@pytest.mark.parametrize("columns", ["wavelength_nm,SAMPLE", "4,3", ("4", "sample"), (4, 3)])
def test_columns_by_name_or_number(tmp_path, columns):
    p = _write(tmp_path / "m.csv", "index,reference,sample,wavelength_nm",
               [(i, 0.9, r, w) for i, (w, r) in enumerate(zip(WL, R70))])
    s = read_spectrum(p, columns=columns)
    np.testing.assert_allclose(s.wavelength_nm, WL)
    np.testing.assert_allclose(s.reflectance, R70, atol=1e-6)
    assert any("as chosen" in n for n in s.notes)


@pytest.mark.parametrize("header, columns, msg", [
    ("index,reference,sample,wavelength_nm", "wl,sample", r"no column 'wl' in .*m\.csv"),
    ("index,reference,sample,wavelength_nm", "1,7", "has 4 columns, not 7"),
    ("index,reference,sample,wavelength_nm", "3,3", "are the same"),
    ("index,reference,sample,wavelength_nm", "0,2", "start at 1"),
    ("index,reference,sample,wavelength_nm", "1", "expected two columns"),
    (None, "wavelength_nm,sample", "has no header; choose columns by number"),
])
def test_bad_columns_name_the_option(tmp_path, header, columns, msg):
    p = _write(tmp_path / "m.csv", header,
               [(i, 0.9, r, w) for i, (w, r) in enumerate(zip(WL, R70))])
    with pytest.raises(InputError, match=msg) as e:
        read_spectrum(p, columns=columns)
    assert e.value.param == "columns"
    assert e.value.cli_message().startswith("--columns: ")


def test_parse_columns():
    assert parse_columns("Wavelength (nm), %R") == ("Wavelength (nm)", "%R")
    assert parse_columns("1,2") == (0, 1)


def test_unrecognised_header_of_three_columns_asks_for_columns(tmp_path):
    p = _write(tmp_path / "u.csv", "a,b,c", [(w, r, 1.0) for w, r in zip(WL, R70)])
    with pytest.raises(InputError, match="no wavelength column") as e:
        read_spectrum(p)
    assert "u.csv" in str(e.value) and "--columns" in e.value.cli_message()


# --------------------------------------------------------------------- units and notes
@pytest.mark.parametrize("header, values, factor, level, words", [
    ("wavelength (nm),R", WL / 1000, 1000, logging.WARNING, "says nm but values 0.4-0.75"),
    ("wavelength (um),R", WL, 1, logging.WARNING, "says µm but values 400-750"),
    ("wavelength (µm),R", WL / 1000, 1000, logging.INFO, "wavelength in µm"),
    ("wavelength,R", WL / 1000, 1000, logging.INFO, "values 0.4-0.75 read as µm"),
])
def test_wavelength_unit_from_values_checked_against_header(tmp_path, caplog, header, values,
                                                            factor, level, words):
    p = _write(tmp_path / "w.csv", header, zip(values, R70))
    with caplog.at_level(logging.INFO, logger="microfacet.io.spectrum"):
        s = read_spectrum(p)
    np.testing.assert_allclose(s.wavelength_nm, WL, atol=1e-9)
    rec = [r for r in caplog.records if words in r.getMessage()]
    assert rec and rec[0].levelno == level, caplog.text


@pytest.mark.parametrize("header, factor, divided, level, words", [
    ("wl,R", 1, False, logging.INFO, "fraction"),
    ("wl,R", 100, True, logging.INFO, "read as percent and divided by 100"),
    ("wl,%R", 100, True, logging.INFO, "percent (header '%R')"),
    ("wl,Reflectance (%)", 1, True, logging.WARNING, "says percent but every value is <= 1"),
    ("wl,R", 2.4, True, logging.WARNING, "exceed 1 (no fraction does) but not 1.5"),
])
def test_percent_from_header_or_values(tmp_path, caplog, header, factor, divided, level, words):
    p = _write(tmp_path / "r.csv", header, zip(WL, R70 * factor))
    with caplog.at_level(logging.INFO, logger="microfacet.io.spectrum"):
        s = read_spectrum(p)
    np.testing.assert_allclose(s.reflectance, R70 * factor / (100 if divided else 1),
                               rtol=1e-5)
    rec = [r for r in caplog.records if words in r.getMessage()]
    assert rec and rec[0].levelno == level, caplog.text


def test_slightly_negative_noise_is_kept_and_warned(tmp_path, caplog):
    R = R70.copy()
    R[:3] = -0.004
    with caplog.at_level(logging.INFO, logger="microfacet.io.spectrum"):
        s = read_spectrum(_write(tmp_path / "n.csv", "wl,R", zip(WL, R)))
    assert s.reflectance.min() == pytest.approx(-0.004)
    assert "3 value(s) slightly below 0" in caplog.text


# ------------------------------------------------------------------ hostile input
@pytest.mark.parametrize("text, msg", [
    ("wavelength_nm,reflectance\n400,0.1\n500,abc\n600,0.2\n", r"line 3: expected numbers"),
    ("wavelength_nm,reflectance\n400,0.1\n500,nan\n600,0.2\n", r"line 3: non-finite value"),
    ("wavelength_nm,reflectance\n400,0.1\n", "at least 3"),
    ("wl;R\n400;0,1\n400;0,2\n400;0,3\n", r"1 distinct wavelength\(s\) in 3 rows"),
    ("", "empty file"),
    ("wavelength_nm,reflectance\n", "no row of numbers"),
    ("wl,counts\n400,31000\n500,42000\n600,12000\n", "neither a fraction nor a percentage"),
    ("wl,R\n400,-0.3\n500,0.2\n600,0.3\n", "reflectance down to -0.3"),
])
def test_bad_files_name_file_and_line(tmp_path, text, msg):
    p = tmp_path / "bad.csv"
    p.write_text(text)
    with pytest.raises(InputError, match=msg) as e:
        read_spectrum_csv(p)
    assert "bad.csv" in str(e.value)


def test_row_limit_refused_while_reading(tmp_path, monkeypatch):
    monkeypatch.setattr(spectrum_io, "MAX_SPECTRUM_ROWS", 50)
    p = _write(tmp_path / "big.csv", "wl,R", zip(WL, R70))          # 71 rows
    with pytest.raises(InputError, match="more than 50 rows"):
        read_spectrum(p)


def test_binary_and_endless_lines_are_refused(tmp_path):
    p = tmp_path / "bin.csv"
    p.write_bytes(b"wl,R\n400,0.1\x00\x00\n")
    with pytest.raises(InputError, match="line 2: binary data"):
        read_spectrum(p)
    p.write_text("4" * (spectrum_io.MAX_LINE_CHARS + 10))
    with pytest.raises(InputError, match="line 1: longer than"):
        read_spectrum(p)


def test_duplicates_kept_and_sorted(tmp_path):
    p = _write(tmp_path / "d.csv", "wl,R", [(600, 0.3), (400, 0.1), (500, 0.2), (500, 0.25)])
    s = read_spectrum(p)
    assert s.wavelength_nm.tolist() == [400, 500, 500, 600]
    assert s.reflectance.tolist() == [0.1, 0.2, 0.25, 0.3]
