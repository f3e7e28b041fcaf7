"""The analysis end to end (microfacet.analysis.pipeline) on the bundled synthetic stack,
against its truth: the joint mode beats the seed's method, the stages in the order of the
Stage enum, the exposure from stack.json, a microscope export without slices, the options
reaching their stages."""

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
import tifffile
from PIL import Image

from microfacet.analysis import AnalysisOptions, analyse_stack
from microfacet.analysis.options import FitOptions, OpticsOptions, RoiOptions
from microfacet.analysis.output import build_summary
from microfacet.analysis.stages import JOINT_ONLY, Stage
from microfacet.cli import main
from microfacet.core.densities import wasserstein1
from microfacet.io.x3p import read_x3p

FIXTURE = Path(__file__).resolve().parents[2] / "fixtures" / "stacks" / "nd-fixture"
TRUTH = FIXTURE / "truth"


def test_joint_mode_beats_the_seed_method_on_truth(nd_analysis):
    d_true = np.load(TRUTH / "thickness_nm.npy")
    t_true = np.load(TRUTH / "tilt_deg.npy")
    vis = np.load(TRUTH / "visible.npy")
    err = {}
    for mode in ("seed", "joint"):
        r = nd_analysis(mode)
        d, t = r.pixels.thickness_nm, r.pixels.tilt_deg
        ok = np.isfinite(d)
        okt = np.isfinite(t) & vis
        err[mode] = dict(
            d=float(np.mean(np.abs(d[ok] - d_true[ok]))),
            t=float(np.median(np.abs(t[okt] - t_true[okt]))),
            w1=wasserstein1(t[okt], t_true[vis]),
            de=r.delta_e_stats["mean"])
    j, s = err["joint"], err["seed"]
    assert j["d"] < s["d"] and j["t"] < s["t"] and j["w1"] < s["w1"] and j["de"] < s["de"]
    # Absolute bars measured on this fixture (docs/accuracy.md has the per-preset table).
    assert j["d"] < 2.0 and j["w1"] < 2.0 and j["t"] < 6.0


def test_the_self_check_on_its_own_thread_changes_nothing(nd_analysis):
    """With two threads the self-check runs beside the facet, tilt and mixture stages
    (core.threads.Background); with one it runs where it did. The results are the same to
    the bit: it reads nothing they change."""
    from microfacet.core.threads import default_num_threads, limited_threads

    if default_num_threads() > 1:
        two = nd_analysis("joint")
    else:
        with limited_threads(2):
            two = analyse_stack(FIXTURE, AnalysisOptions(mode="joint"))
    with limited_threads(1):
        one = analyse_stack(FIXTURE, AnalysisOptions(mode="joint"))
    assert one.self_check is not None and one.self_check.facets > 0
    assert one.self_check.to_json() == two.self_check.to_json()
    s1, s2 = build_summary(one).to_json(), build_summary(two).to_json()
    for key in ("thickness", "ndf", "white_balance", "exposure", "delta_e", "warnings"):
        assert s1[key] == s2[key], key
    for a, b in ((one.pixels.thickness_nm, two.pixels.thickness_nm),
                 (one.pixels.tilt_deg, two.pixels.tilt_deg)):
        np.testing.assert_array_equal(a, b)


@pytest.mark.slow
def test_exposure_from_stack_json_is_used(tmp_path):
    st = tmp_path / "s"
    shutil.copytree(FIXTURE, st)
    meta = json.loads((st / "stack.json").read_text())
    meta["exposure"] = 1.0
    (st / "stack.json").write_text(json.dumps(meta))
    r = analyse_stack(st, AnalysisOptions(mode="seed", fits=FitOptions(max_components=2)))
    assert r.exposure == 1.0 and r.scene.exposure_source == "stack.json"
    assert r.roi.exposure == 1.0 and not r.roi.exposure_estimated
    assert r.thickness_fit.n_components <= 2 and max(r.thickness_fit.bic_by_k) <= 2
    # the option overrides the stack's
    o = AnalysisOptions(mode="seed", optics=OpticsOptions(exposure=0.8),
                        fits=FitOptions(max_components=2))
    r = analyse_stack(st, o)
    assert r.exposure == 0.8 and r.scene.exposure_source == "option"


@pytest.mark.slow
def test_microscope_export_is_analysed_without_slices(tmp_path):
    """A stack of `height_um` + `image` (a microscope export) skips height from focus; with
    the synthetic truth as the export, thickness and height tilts match the truth."""
    truth = FIXTURE / "truth"
    st = tmp_path / "export"
    st.mkdir()
    shutil.copy(truth / "height_um.npy", st / "height_um.npy")
    shutil.copy(truth / "all_in_focus.png", st / "image.png")
    (st / "stack.json").write_text(json.dumps({
        "format": "microfacet-stack/1", "pixel_size_um": 0.216,
        "height_um": "height_um.npy", "image": "image.png"}))
    out = tmp_path / "res"
    assert main(["analyze", str(st), "--out", str(out), "--no-report", "-q"]) == 0
    s = json.loads((out / "summary.json").read_text())
    assert s["inputs"]["height_source"] == "microscope export" and s["inputs"]["n_slices"] == 0
    d = np.load(out / "thickness_nm.npy")
    d_true = np.load(truth / "thickness_nm.npy")
    ok = np.isfinite(d)
    assert ok.mean() > 0.8
    assert np.median(np.abs(d[ok] - d_true[ok])) < 0.5
    t_h = np.load(out / "tilt_height_deg.npy")
    vis = np.load(truth / "visible.npy") & np.isfinite(t_h)
    assert np.median(np.abs(t_h[vis] - np.load(truth / "tilt_deg.npy")[vis])) < 2.5


@pytest.mark.slow
def test_non_square_pixels_are_analysed_on_the_sample(tmp_path):
    """The export of the test above with every other column dropped: pixels 0.216 µm high
    and 0.432 µm wide. Height tilts still match the truth (read as square pixels the x slopes
    would double); summary, TIFF resolution, x3p axes and the report keep both spacings."""
    truth = FIXTURE / "truth"
    st = tmp_path / "export"
    st.mkdir()
    np.save(st / "height_um.npy", np.load(truth / "height_um.npy")[:, ::2])
    img = np.asarray(Image.open(truth / "all_in_focus.png"))[:, ::2]
    Image.fromarray(np.ascontiguousarray(img)).save(st / "image.png")
    (st / "stack.json").write_text(json.dumps({
        "format": "microfacet-stack/1", "pixel_size_um": [0.216, 0.432],
        "height_um": "height_um.npy", "image": "image.png"}))
    out = tmp_path / "res"
    assert main(["analyze", str(st), "--out", str(out), "-q"]) == 0
    s = json.loads((out / "summary.json").read_text())
    assert s["inputs"]["pixel_size_um"] == [0.216, 0.432]
    t_h = np.load(out / "tilt_height_deg.npy")
    vis = np.load(truth / "visible.npy")[:, ::2] & np.isfinite(t_h)
    err = np.abs(t_h[vis] - np.load(truth / "tilt_deg.npy")[:, ::2][vis])
    assert vis.mean() > 0.5 and np.median(err) < 2.5
    with tifffile.TiffFile(out / "height_um.tif") as tf:
        page = tf.pages[0]
        xres, yres = (page.tags[k].value for k in ("XResolution", "YResolution"))
        assert (xres[1] / xres[0], yres[1] / yres[0]) == pytest.approx((0.432, 0.216), 1e-4)
    assert read_x3p(out / "height_um.x3p").pixel_size_um == pytest.approx((0.216, 0.432))
    assert (out / "report.pdf").stat().st_size > 0


@pytest.mark.slow
def test_an_instrument_file_export_is_analysed_with_its_own_pixel_size(tmp_path):
    """A real Alicona .al3d as the export's height (no pixel_size_um in stack.json) with the
    colour a 70 nm film shows at its tilts: the pixel size is the file's, the thickness is
    found, and the 12.6° mounting tilt of that measurement is reported."""
    pytest.importorskip("SurfaceTopography")
    from microfacet.colour.srgb import srgb_encode
    from microfacet.colour.table import build_colour_table
    from microfacet.focus.normals import normals_from_height, tilt_azimuth_deg
    from microfacet.io.images import write_image
    from microfacet.io.instruments import read_height_map

    src = Path(__file__).resolve().parents[2] / "fixtures" / "instrument-heights" / "al3d-1.al3d"
    m = read_height_map(src)
    tilt, _ = tilt_azimuth_deg(normals_from_height(m.height_um, pixel_size_um=m.pixel_size_um))
    table = build_colour_table(thickness_range_nm=(60, 80), theta_range_deg=(0, 40))
    rgb = table.linear_rgb_at(np.clip(tilt, 0, 40), np.full(tilt.shape, 70.0))
    st = tmp_path / "export"
    st.mkdir()
    shutil.copy(src, st / src.name)
    write_image(st / "image.png", srgb_encode(np.clip(rgb / rgb.max() * 0.8, 0, 1),
                                              dtype=np.uint8))
    (st / "stack.json").write_text(json.dumps({
        "format": "microfacet-stack/1", "height_um": src.name, "image": "image.png"}))
    out = tmp_path / "res"
    assert main(["analyze", str(st), "--out", str(out), "--no-report", "-q",
                 "--facet-size-um", "4.4"]) == 0
    s = json.loads((out / "summary.json").read_text())
    assert s["inputs"]["pixel_size_um"] == pytest.approx(m.pixel_size_um[1], rel=1e-12)
    assert np.nanmedian(np.load(out / "thickness_nm.npy")) == pytest.approx(70.0, abs=1.0)
    # the mean plane of this measurement: arctan of its mean gradient
    gy, gx = np.gradient(m.height_um.astype(np.float64), *m.pixel_size_um)
    plane = np.degrees(np.arctan(np.hypot(gx.mean(), gy.mean())))
    assert s["ndf"]["mean_plane_tilt_deg"] == pytest.approx(plane, abs=0.25)
    assert any("mean plane is tilted" in w for w in s["warnings"])


@pytest.mark.slow
def test_the_colour_difference_formula_reaches_every_stage(tmp_path):
    """``optics.delta_e_method`` is passed through the pipeline: with CIE76 the per-pixel ΔE
    is CIE76 between each pixel and its model colour, and the ROI fit reports CIE76
    differences too (they differ from the CIEDE2000 run). The stages are announced in the
    order of the Stage enum, and each is timed under its key."""
    from microfacet import colour as color

    roi = RoiOptions(size_px=128)
    seen = []
    r76 = analyse_stack(FIXTURE, AnalysisOptions(roi=roi, optics=OpticsOptions(
        delta_e_method="CIE76")), progress=seen.append)
    assert r76.model.delta_e_method == "CIE76"
    px, table = r76.pixels, r76.model.table
    ok = np.isfinite(px.delta_e)
    xyz = table.xyz_at(px.tilt_deg[ok], px.thickness_nm[ok]) * r76.exposure
    model = color.xyz_to_lab(xyz.astype(np.float32), white=table.white_xyz.astype(np.float32))
    np.testing.assert_allclose(px.delta_e[ok], color.delta_e_76(model, r76.colour.lab[ok]),
                               rtol=1e-3, atol=1e-3)
    r00 = analyse_stack(FIXTURE, AnalysisOptions(roi=roi))
    assert not np.allclose(r76.roi.mean_delta_e, r00.roi.mean_delta_e)
    # the stages of the analysis (writing and the report are the workflow's), in order
    analysis = [s for s in Stage if s not in (Stage.WRITE, Stage.REPORT)]
    assert seen == analysis
    assert set(r76.timings_s) == {s.key for s in analysis} | {"total"}
    assert r76.timings_s["total"] >= sum(r76.timings_s[s.key] for s in analysis) - 1e-3


def test_the_seed_mode_skips_the_joint_stages(nd_analysis):
    r = nd_analysis("seed")
    keys = {s.key for s in Stage if s not in JOINT_ONLY + (Stage.WRITE, Stage.REPORT)}
    assert set(r.timings_s) == keys | {"total"} and r.joint is None
    assert set(nd_analysis("joint").timings_s) == keys | {s.key for s in JOINT_ONLY} | {"total"}


def _reencoded(folder, variant):
    """The fixture's slices, in z order, as a plain folder: re-encoded as JPEG of a quality,
    saved as 16-bit PNG, or re-exposed by a factor (linear)."""
    import cv2

    from microfacet.colour.transfer import srgb_decode, srgb_encode
    from microfacet.io.images import write_image
    from microfacet.io.stack import read_stack
    st = read_stack(FIXTURE)
    folder.mkdir()
    for k, i in enumerate(st.z_order):
        img = st.read_slice(int(i), np.uint8)
        if variant.startswith("jpeg"):
            cv2.imwrite(str(folder / f"{k:03d}.jpg"), cv2.cvtColor(img, cv2.COLOR_RGB2BGR),
                        [cv2.IMWRITE_JPEG_QUALITY, int(variant[4:])])
        elif variant == "16bit":
            write_image(folder / f"{k:03d}.png", img.astype(np.uint16) * 257, bit_depth=16)
        else:
            lin = srgb_decode(img) * (1.0 + float(variant[8:]) / 100.0)
            write_image(folder / f"{k:03d}.png", srgb_encode(lin, dtype=np.uint8))
    return folder, float(np.median(np.diff(np.sort(st.z_um))))


@pytest.mark.slow
@pytest.mark.parametrize("variant", ["jpeg97", "jpeg90", "16bit", "exposure+5", "exposure-5"])
def test_the_thickness_populations_do_not_follow_encoding_or_exposure(tmp_path, variant,
                                                                      nd_analysis):
    """Issue 23: the same slices re-encoded as JPEG (quality 97, 90), saved as 16-bit or
    re-exposed by ±5 % give the fixture's number of thickness populations, each mean within
    1 nm. The JPEG quality is read from the files and its block error enters the noise
    model (larger at lower quality; none for the lossless variants)."""
    from microfacet.io.stack import read_stack
    ref = nd_analysis("joint").thickness_fit.mixture
    folder, step = _reencoded(tmp_path / variant, variant)
    st = read_stack(folder, pixel_size_um=0.216, z_step_um=step)
    res = analyse_stack(st)
    got = res.thickness_fit.mixture
    if variant.startswith("jpeg"):
        assert st.jpeg.quality == int(variant[4:])
        assert 0.0 < res.colour.block_noise_de < res.colour.noise_de
    else:
        assert st.jpeg is None and res.colour.block_noise_de == 0.0
    assert len(got.components) == len(ref.components) == 3
    np.testing.assert_allclose(np.sort(got.means_nm), np.sort(ref.means_nm), atol=1.0)


@pytest.mark.slow
def test_white_balance_is_not_called_determined_where_the_thickness_is_not(monkeypatch):
    """A white-balance estimate whose spread calls it determined stays so where the
    thickness is identified, and is withdrawn (the estimate kept, with why) where it is not:
    the gains the colours ask for are those of the thicknesses they were read at. (Gains
    within 3 % of 1: farther off, the order rests on the image being balanced and is not
    established, which withdraws them too.)"""
    import microfacet.analysis.pipeline as pl
    from microfacet.analysis.identification import Judgement, Reason
    from microfacet.analysis.white_balance import WhiteBalance

    est = WhiteBalance(estimate_rgb=(1.025, 1.0, 0.98), estimate_sigma=(0.005, 0.006),
                       determined=(True, True), tiles=40)
    monkeypatch.setattr(pl, "choose_white_balance", lambda *a, **k: est)
    ok = analyse_stack(FIXTURE, AnalysisOptions(mode="joint"))
    assert ok.distributions.thickness_judgement.identified
    assert ok.white_balance.determined == (True, True) and ok.white_balance.withdrawn is None
    real = pl.fit_joint_distributions

    def unidentified(*args, **kwargs):
        d = real(*args, **kwargs)
        d.thickness_judgement = Judgement(False, Reason("order_ambiguous", "order uncertain"))
        return d

    monkeypatch.setattr(pl, "fit_joint_distributions", unidentified)
    r = analyse_stack(FIXTURE, AnalysisOptions(mode="joint"))
    wb = r.white_balance
    assert wb.determined == (False, False) and wb.estimate_rgb == est.estimate_rgb
    assert "the thickness is not identified" in wb.withdrawn
    assert wb.to_dict()["determined_withdrawn"] == wb.withdrawn


@pytest.mark.slow
def test_white_balance_is_not_called_determined_where_the_order_is_not(monkeypatch):
    """The thickness identified but its interference order not established (here a ROI's
    runner-up order within the threshold): the gains the colours ask for are those of the
    orders they were read in, so none is called determined; the order's reasons are
    summary.json's."""
    import microfacet.analysis.pipeline as pl
    from microfacet.analysis.output import build_summary
    from microfacet.analysis.white_balance import WhiteBalance

    est = WhiteBalance(estimate_rgb=(1.04, 1.0, 0.97), estimate_sigma=(0.005, 0.006),
                       determined=(True, True), tiles=40)
    monkeypatch.setattr(pl, "choose_white_balance", lambda *a, **k: est)
    real = pl.fit_joint_distributions

    def ambiguous(*args, **kwargs):
        d = real(*args, **kwargs)
        d.roi_ambiguous = np.zeros_like(d.roi_ambiguous)
        d.roi_ambiguous[0] = True
        return d

    monkeypatch.setattr(pl, "fit_joint_distributions", ambiguous)
    r = analyse_stack(FIXTURE, AnalysisOptions(mode="joint"))
    assert r.distributions.thickness_judgement.identified
    assert not r.order["established"] and "1 ROI(s) with an ambiguous order" in r.order["reasons"]
    wb = r.white_balance
    assert wb.determined == (False, False) and wb.estimate_rgb == est.estimate_rgb
    assert "the interference order is not established" in wb.withdrawn
    assert build_summary(r).thickness.order == r.order


def _two_populations(folder, means_nm, **kw):
    """A 128² ``nd`` stack of two equal populations (SD 1.5 nm, 8 µm regions) written to
    ``folder``; the populations' own means (truth), sorted."""
    from microfacet.forward.synth import generate_stack, preset
    from microfacet.forward.synth_params import ThicknessComponent

    generate_stack(folder, preset("nd", height_px=128, width_px=128, n_slices=8,
                                  region_size_um=8.0, **kw, thickness=tuple(
                                      ThicknessComponent(0.5, m, 1.5) for m in means_nm)))
    truth = json.loads((folder / "truth" / "params.json").read_text())
    return sorted(q["mean_thickness_nm"] for q in truth["populations"])


@pytest.mark.slow
def test_a_cyan_population_outside_the_srgb_gamut_is_explained_by_the_film_model(tmp_path):
    """TiO2 of ~172 nm is a cyan of negative linear red, which the synthetic camera, like
    any sRGB image, records at 0: the film model records it alike, so it explains the
    colours (median ΔE00 within 1 of the noise floor) and, with the camera's balance given
    (stack.json ``white_balance``), the interference order is established; both means
    within 1 nm of the populations' own. (Compared unclipped, the model missed the 172 nm
    colours by 2-4 ΔE00 and the order was withheld.) Without the balance the order rests on
    it: the cyan's red, at 0, says nothing of the R gain, so the two film colours pin one
    gain combination, not two, and the scene's estimate leaves the gains free."""
    from microfacet.analysis.identification import MEDIAN_NOISE_FLOOR_FACTOR

    true_means = _two_populations(tmp_path / "s", (120.0, 172.0), seed=3)
    unbalanced = analyse_stack(tmp_path / "s")
    assert not unbalanced.order["established"]
    assert unbalanced.white_balance.film_colours == 1
    meta = json.loads((tmp_path / "s" / "stack.json").read_text())
    (tmp_path / "s" / "stack.json").write_text(json.dumps({**meta,
                                                          "white_balance": [1.0, 1.0, 1.0]}))
    r = analyse_stack(tmp_path / "s")
    assert r.order["established"], r.order["reasons"]
    assert r.delta_e_stats["median"] < MEDIAN_NOISE_FLOOR_FACTOR * r.colour.noise_de + 1.0
    np.testing.assert_allclose(np.sort(r.thickness_fit.mixture.means_nm), true_means, atol=1.0)


@pytest.mark.slow
def test_a_population_of_a_grey_film_is_measured_not_masked(tmp_path):
    """Rutile near 50 nm on Werner's Ti is grey (HSV saturation ~6 < the seed's 15): the
    seed's saturation test masks that population whole. Beside a film of colour it is a
    wide grey area, analysed as film (mask.grey_film): both populations within 1 nm of their
    regions' true means; with ``mask.grey_film_min_px`` 0 (the seed's rule) the grey one is
    masked and missing."""
    from microfacet.analysis.options import MaskOptions

    true_means = _two_populations(tmp_path / "s", (51.0, 158.0), seed=7, exposure=0.85,
                                  film="TiO2_Devore1951_rutile_e",
                                  substrate="Ti_Werner2009_REELS")
    r = analyse_stack(tmp_path / "s")
    assert r.colour.mask.fractions()["grey_film"] > 0.2
    np.testing.assert_allclose(np.sort(r.thickness_fit.mixture.means_nm), true_means, atol=1.0)
    seed_rule = analyse_stack(tmp_path / "s", AnalysisOptions(mask=MaskOptions(
        grey_film_min_px=0)))
    assert seed_rule.colour.mask.fractions()["low_saturation"] > 0.2
    assert np.min(np.abs(seed_rule.thickness_fit.mixture.means_nm - true_means[0])) > 5.0
