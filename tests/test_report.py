"""The PDF report of a results folder (microfacet.report.writer)."""

from __future__ import annotations

import json
import re
import shutil
import subprocess
import sys

import numpy as np
import pytest

from microfacet.core.distributions import NDFMixture, ThicknessMixture
from microfacet.report.writer import NO_VALUE, PAGES, parameter_tables, write_report

H, W = 64, 80
OPTIONAL = ("mask.npy", "delta_e.npy", "tilt_height_deg.npy", "angular_map.png")


def _smooth(rng, shape, k=7):
    a = rng.normal(size=shape)
    ker = np.ones(k) / k
    a = np.apply_along_axis(lambda r: np.convolve(r, ker, mode="same"), 0, a)
    return np.apply_along_axis(lambda r: np.convolve(r, ker, mode="same"), 1, a)


def _png(path, rgb8):
    import cv2

    assert cv2.imwrite(str(path), np.ascontiguousarray(rgb8[..., ::-1]))


def _csv(path, header, columns):
    rows = "".join(",".join(f"{v:.6g}" for v in r) + "\n" for r in zip(*columns))
    path.write_text(header + "\n" + rows)


def make_results(folder, *, seed=0):
    """A small, plausible results folder (64 × 80 pixels) with every optional file."""
    rng = np.random.default_rng(seed)
    folder.mkdir(parents=True, exist_ok=True)
    thick = ThicknessMixture([(0.25, 112.0, 4.0), (0.5, 130.0, 5.0), (0.25, 146.0, 3.5)])
    ndf = NDFMixture([(0.6, 3.0), (0.4, 9.0)])

    height = (0.4 * _smooth(rng, (H, W)) + 5.0).astype(np.float32)
    height[:3, :5] = np.nan
    mask = np.zeros((H, W), bool)
    mask[40:50, 10:22] = True
    mask |= rng.random((H, W)) < 0.03
    comp = rng.choice(3, size=(H, W), p=thick.weights)
    thickness = (thick.means_nm[comp] + thick.sds_nm[comp] * rng.normal(size=(H, W)))
    thickness = np.where(mask, np.nan, thickness).astype(np.float32)
    lobe = rng.choice(2, size=(H, W), p=ndf.weights)
    slope = ndf.slope_sd[lobe] * np.hypot(rng.normal(size=(H, W)), rng.normal(size=(H, W)))
    tilt = np.where(mask, np.nan, np.degrees(np.arctan(slope))).astype(np.float32)
    tilt_h = np.clip(tilt + rng.normal(0, 1.5, (H, W)), 0, None).astype(np.float32)
    sigma = np.where(mask, np.nan, 0.5 + rng.random((H, W))).astype(np.float32)
    delta_e = np.where(mask, np.nan, rng.gamma(3.0, 1.6, (H, W))).astype(np.float32)
    for name, a in [("height_um", height), ("thickness_nm", thickness), ("tilt_deg", tilt),
                    ("tilt_sigma_deg", sigma), ("delta_e", delta_e), ("tilt_height_deg", tilt_h),
                    ("mask", mask)]:
        np.save(folder / f"{name}.npy", a)
    np.save(folder / "normals.npy", np.dstack([np.zeros((H, W, 2)), np.ones((H, W, 1))])
            .astype(np.float32))
    aif = np.clip(np.dstack([150 + 120 * _smooth(rng, (H, W)), np.full((H, W), 110.0),
                             200 - (np.nan_to_num(thickness, nan=130.0) - 130.0) * 3]), 0, 255)
    _png(folder / "all_in_focus.png", aif.astype(np.uint8))
    ang = rng.integers(0, 255, (13, 13, 3), dtype=np.uint8).repeat(4, 0).repeat(4, 1)
    _png(folder / "angular_map.png", ang)

    edges = np.arange(90.0, 171.0, 1.0)
    x = 0.5 * (edges[1:] + edges[:-1])
    d, _ = np.histogram(thickness[np.isfinite(thickness)], bins=edges, density=True)
    _csv(folder / "thickness_pdf.csv", "thickness_nm,density,mixture_density",
         [x, d, thick.pdf(x)])
    edges = np.arange(0.0, 36.1, 0.5)
    x = 0.5 * (edges[1:] + edges[:-1])
    d, _ = np.histogram(tilt[np.isfinite(tilt)], bins=edges, density=True)
    _csv(folder / "ndf_pdf.csv", "tilt_deg,density,mixture_density", [x, d, ndf.tilt_pdf(x)])
    roi = [(0, 0, 32, 118.4, 4.1, 1000), (0, 40, 32, 131.0, 3.7, 990),
           (32, 40, 32, 144.2, 5.2, 1012)]
    _csv(folder / "thickness_roi.csv", "row0,col0,size,thickness_nm,mean_delta_e,n_pixels",
         list(zip(*roi)))
    summary = {
        "format": "microfacet-results/1",
        "inputs": {"stack": "/data/stacks/sample-1", "pixel_size_um": 0.216},
        "mode": "joint",
        "thickness": {"mixture": {**thick.to_json(), "bic": 41234.5}},
        "ndf": {"mixture": {**ndf.to_json(), "bic": 30012.25}},
        "exposure": 1.07,
        "delta_e": {"mean": float(np.nanmean(delta_e)), "median": float(np.nanmedian(delta_e))},
        "masked_fraction": float(mask.mean()),
        "timings_s": {"total": 12.5, "focus": 3.2, "thickness": 6.1, "tilt": 2.9},
        "versions": {"microfacet": "0.1.0"},
    }
    (folder / "summary.json").write_text(json.dumps(summary, indent=1))
    return folder


def make_empty_results(folder):
    """What the analysis writes when every pixel is masked: NaN maps, header-only CSVs,
    empty mixtures and null statistics."""
    folder.mkdir(parents=True, exist_ok=True)
    nan = np.full((H, W), np.nan, np.float32)
    for name in ("height_um", "thickness_nm", "tilt_deg", "tilt_sigma_deg", "delta_e",
                 "colour_weight"):
        np.save(folder / f"{name}.npy", nan)
    np.save(folder / "tilt_height_deg.npy", np.zeros((H, W), np.float32))
    np.save(folder / "mask.npy", np.ones((H, W), bool))
    _png(folder / "all_in_focus.png", np.full((H, W, 3), 128, np.uint8))
    (folder / "thickness_pdf.csv").write_text("thickness_nm,density,mixture_density\n")
    (folder / "ndf_pdf.csv").write_text("tilt_deg,density,mixture_density\n")
    (folder / "thickness_roi.csv").write_text(
        "row0,col0,size,thickness_nm,mean_delta_e,n_pixels\n0,0,64,nan,nan,0\n")
    empty = {"components": [], "bic": None}
    summary = {
        "format": "microfacet-results/1", "mode": "joint",
        "inputs": {"stack": "/data/stacks/grey", "pixel_size_um": 0.5,
                   "numerical_aperture": 0.8},
        "thickness": {"mixture": empty, "roi": {"count": 1, "fitted": 0,
                                                "thickness_nm_mean": None}},
        "ndf": {"mixture": empty, "max_tilt_deg": 26.57},
        "exposure": 1.0, "delta_e": {"mean": None, "median": None, "p95": None},
        "masked_fraction": 1.0, "timings_s": {"total": 1.5},
    }
    (folder / "summary.json").write_text(json.dumps(summary))
    return folder


def pdf_pages(path):
    """Number of page objects in a PDF written by matplotlib (no object streams)."""
    return len(re.findall(rb"/Type\s*/Page\b(?!s)", path.read_bytes()))


def read_png(path):
    """RGB uint8 array of a PNG (asserts it decodes)."""
    import cv2

    img = cv2.imread(str(path), cv2.IMREAD_COLOR)
    assert img is not None, f"{path} is not a readable image"
    return img[..., ::-1]


def check_pngs(folder):
    """Every page PNG exists, decodes, is A4 landscape at ~110 dpi and is not blank."""
    names = [f"report_{i}_{n}.png" for i, n in enumerate(PAGES, start=1)]
    for name in names:
        img = read_png(folder / name)
        h, w = img.shape[:2]
        assert 1200 <= w <= 1400 and abs(w / h - 11.69 / 8.27) < 0.01, (name, img.shape)
        assert img.std() > 10, f"{name} looks blank"
    return names


def pdf_text(path, page):
    """Text of one PDF page by pdftotext (poppler), or skip if it is not installed."""
    exe = shutil.which("pdftotext")
    if exe is None:
        pytest.skip("pdftotext not installed")
    out = subprocess.run([exe, "-f", str(page), "-l", str(page), "-layout", str(path), "-"],
                         capture_output=True, text=True, check=True)
    return out.stdout


@pytest.fixture(scope="module")
def results(tmp_path_factory):
    return make_results(tmp_path_factory.mktemp("res") / "run")


@pytest.fixture(scope="module")
def report(results, tmp_path_factory):
    png = tmp_path_factory.mktemp("png")
    return write_report(results, png_dir=png), png


def test_full_folder_gives_five_pages_and_pngs(results, report):
    out, png = report
    assert PAGES == ("overview", "maps", "distributions", "parameters", "angular")
    assert out == results / "report.pdf" and out.is_file()
    assert out.read_bytes().startswith(b"%PDF") and pdf_pages(out) == len(PAGES)
    assert out.stat().st_size < 2_000_000
    assert sorted(p.name for p in png.iterdir()) == check_pngs(png)
    assert not [p for p in results.iterdir() if p.name.startswith(".report.pdf")]


def test_masked_pixels_are_drawn_in_the_no_value_grey(report):
    _, png = report
    grey = tuple(int(NO_VALUE[i:i + 2], 16) for i in (1, 3, 5))
    maps = read_png(png / "report_2_maps.png")
    n = int(np.all(maps == grey, axis=-1).sum())
    assert n > 500  # the 10 x 12 masked block and the scattered pixels, on five maps
    # the histogram page has no maps: the grey is only on map pages
    dist = read_png(png / "report_3_distributions.png")
    assert int(np.all(dist == grey, axis=-1).sum()) < n / 10


def test_header_and_units_are_on_the_pages(report):
    out, _ = report
    p1 = pdf_text(out, 1)
    assert "microfacet report — sample-1" in p1 and "microfacet 0.1.0" in p1
    assert "height (µm)" in p1 and "x (µm)" in p1
    p2 = pdf_text(out, 2)
    for label in ("thickness (nm)", "tilt from optical axis (°)", "tilt 1σ (°)", "CIEDE2000",
                  "no value"):
        assert label in p2, label
    p3 = pdf_text(out, 3)
    for label in ("oxide thickness (nm)", "probability density (1/nm)",
                  "probability density (1/°)", "D(θ) (1/sr)", "fitted mixture",
                  "weight 0.25, mean 112.0 nm, SD 4.00 nm", "weight 0.60, slope SD 3.00°"):
        assert label in p3, label
    p5 = pdf_text(out, 5)
    assert "microfacet thin-film BRDF" in p5 and "light zenith" in p5


def test_parameter_table_matches_summary(results, report):
    summary = json.loads((results / "summary.json").read_text())
    t = parameter_tables(results)
    comps = summary["thickness"]["mixture"]["components"]
    assert t["thickness"]["rows"] == [
        [str(i + 1), f"{c['weight']:.3f}", f"{c['mean_nm']:.1f}", f"{c['sd_nm']:.2f}"]
        for i, c in enumerate(comps)]
    lobes = summary["ndf"]["mixture"]["components"]
    assert [r[:3] for r in t["ndf"]["rows"]] == [
        [str(i + 1), f"{c['weight']:.3f}", f"{c['sd_deg']:.2f}"] for i, c in enumerate(lobes)]
    for r, c in zip(t["ndf"]["rows"], lobes):  # tan σ and Beckmann α = √2 tan σ
        assert float(r[3]) == pytest.approx(np.tan(np.radians(c["sd_deg"])), abs=1e-4)
        assert float(r[4]) == pytest.approx(np.sqrt(2) * float(r[3]), abs=2e-4)
    analysis = dict(t["analysis"]["rows"])
    assert analysis["exposure"] == f"{summary['exposure']:.4g}"
    de = summary["delta_e"]
    de_row = f"{de['mean']:.2f} / {de['median']:.2f} / —"  # no p95 in this summary
    assert analysis["ΔE₀₀ mean / median / p95"] == de_row
    assert analysis["masked fraction"] == f"{100 * summary['masked_fraction']:.1f} %"
    timings = dict(t["timings"]["rows"])
    assert timings["total analysis"] == "12.5 s" and timings["thickness"] == "6.1 s"
    assert "BIC (41234.5" in t["thickness"]["note"] and "BIC (30012.2" in t["ndf"]["note"]
    # ... and the PDF's parameter page prints them
    text = pdf_text(report[0], 4)
    for row in t["thickness"]["rows"] + t["ndf"]["rows"]:
        assert re.search(r"\s+".join(map(re.escape, row)), text), row
    assert f"{de['mean']:.2f} / {de['median']:.2f}" in text


def test_missing_optional_files_are_tolerated(tmp_path):
    folder = make_results(tmp_path / "r", seed=1)
    for name in OPTIONAL:
        (folder / name).unlink()
    out = write_report(folder, out_pdf=tmp_path / "elsewhere.pdf")
    assert out == tmp_path / "elsewhere.pdf" and pdf_pages(out) == len(PAGES)
    assert not (folder / "report.pdf").exists()
    assert dict(parameter_tables(folder)["run"]["rows"])["not in the folder"] == \
        "mask.npy, delta_e.npy, tilt_height_deg.npy"


def test_all_masked_folder_without_fits_still_renders(tmp_path, capsys):
    folder = make_empty_results(tmp_path / "empty")
    out = write_report(folder, png_dir=tmp_path / "png")
    assert pdf_pages(out) == len(PAGES)
    check_pngs(tmp_path / "png")
    t = parameter_tables(folder)
    assert t["thickness"]["rows"] == [] and t["ndf"]["rows"] == []
    assert t["thickness"]["note"].startswith("no fit")
    assert dict(t["analysis"]["rows"])["masked fraction"] == "100.0 %"
    assert capsys.readouterr() == ("", "")  # library code prints nothing


def test_only_summary_json_is_needed_even_without_fits(tmp_path):
    """summary.json alone, with the empty mixtures the analysis writes when it cannot fit."""
    folder = make_results(tmp_path / ".run.partial-abc123", seed=2)
    for p in folder.iterdir():
        if p.name != "summary.json":
            p.unlink()
    s = json.loads((folder / "summary.json").read_text())
    s["ndf"]["mixture"] = {"components": [], "bic": None}
    (folder / "summary.json").write_text(json.dumps(s))
    out = write_report(folder)
    assert pdf_pages(out) == len(PAGES)
    title = out.read_bytes().split(b"/Title (", 1)[1].split(b") >>", 1)[0]
    assert title.decode("utf-16").endswith("run")  # the folder's final name, not .partial-


def test_missing_summary_names_the_file(tmp_path):
    folder = make_results(tmp_path / "r", seed=3)
    (folder / "summary.json").unlink()
    with pytest.raises(FileNotFoundError, match="summary.json"):
        write_report(folder)
    with pytest.raises(FileNotFoundError, match="nowhere"):
        write_report(tmp_path / "nowhere")
    assert not (folder / "report.pdf").exists()


@pytest.mark.parametrize("name, text, where", [
    ("summary.json", "{not json", "summary.json"),
    ("summary.json", json.dumps({"thickness": {"mixture": {"components": [
        {"weight": 1.0, "mean_nm": 130.0, "sd_nm": 0.0}]}}}), "summary.json"),
    ("ndf_pdf.csv", "tilt_deg,density\n1,0.1\n", "ndf_pdf.csv"),
])
def test_malformed_files_are_value_errors_naming_them(tmp_path, name, text, where):
    folder = make_results(tmp_path / "r", seed=4)
    (folder / name).write_text(text)
    with pytest.raises(ValueError, match=re.escape(where)):
        write_report(folder)
    assert not [p for p in folder.iterdir() if "report.pdf" in p.name]


def test_import_does_not_import_matplotlib():
    code = "import sys, microfacet.report.writer; print('matplotlib' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"
