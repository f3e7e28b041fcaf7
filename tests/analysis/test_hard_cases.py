"""Hard cases (issue "numerical stability on hard cases").

Each case gives a finite, documented result or a clear error: ``ValueError`` naming the
argument, or ``InputError`` naming the file and the key. Results are checked against
independent references (``tmm``, the textbook Fresnel formula, direct spectral integration,
synthetic truth, the raw pixel values), never against numbers copied from a run.

Where each case is covered (``here`` = this file; other files in tests/analysis/ by name)
---------------------------------------------------------------------------------------
* θ → 90° (89.99°) in ``thinfilm.reflectance``: here, against ``tmm`` (89.9°:
  tests/optics/test_thinfilm.py::test_required_corner_cases_match_tmm).
* d = 0 is the bare Fresnel interface: tests/optics/test_thinfilm.py::test_zero_thickness_
  is_the_bare_substrate (hypothesis, θ ≤ 89.99°); here at 89.99° with the bundled optical
  constants.
* d = 5 µm finite, in [0, 1], equal to ``tmm``: here (lossless film across the visible and
  absorbing films); bounds: tests/optics/test_thinfilm.py::test_reflectance_is_a_fraction;
  absorbing 5 µm film: tests/optics/test_thinfilm.py::test_thick_absorbing_film_hides_the_
  substrate.
* k = 0 and k = 10 for the film and the substrate: here, against ``tmm``.
* film index equal to the ambient's: here, the bare substrate for every d (textbook Fresnel).
* film thinner than 5 nm: here (colour table and ROI thickness fit).
* every pixel masked (grey images, saturation 0): here, InputError (API and CLI); too few
  unmasked pixels in every ROI: here, InputError.
* ROI larger than the image: here, one ROI of the image's size; ``roi.size_px`` < 8 names
  the option.
* one-slice (and two-slice) stack: here, InputError (analyze and the CLI);
  ``height_from_focus``: tests/focus/test_height.py::test_bad_options.
* identical slices (no focus information): here, documented result (height NaN, flat
  surface, tilts from colour); flat focus curves in ``peak_fit``: here.
* NaN or ±inf in a height map (normals, tilt, fill, facet planes): here; NaN holes:
  tests/focus/test_normals.py::test_nan_handling_and_smoothing.
* thickness histogram of a single value: fit: test_mixtures.py::test_thickness_single_value_
  is_degenerate; here end to end (seed mode, one ROI) with the pdf table.
* tilt histogram all at 0°: fit: test_ndf_fit.py::test_ndf_all_zero_is_degenerate_and_zeros_
  tolerated; here the pdf table on the analysis' NDF grid.
* noise so heavy nothing is reliable: here, documented result (finite, flagged in summary).
* 16-bit slices at full scale: here, InputError; partly clipped 16-bit: here, the clipped
  pixels are masked; clip level: test_mask.py::test_sixteen_bit_clip_level.
* unsorted z in stack.json: here (the analysis); image arrays: tests/focus/test_height.py::
  test_tilted_plane_uniform_and_unsorted_z.
* numerical aperture so small that max tilt < 0.75° (the NDF grid of ``write_results``):
  here.
"""

from __future__ import annotations

import json
import logging
import math
import warnings

import numpy as np
import pytest

from microfacet import colour as color
from microfacet.analysis import AnalysisOptions, analyse_stack, write_results
from microfacet.analysis.options import MaskOptions, RoiOptions
from microfacet.cli import main
from microfacet.core.errors import InputError
from microfacet.forward.synth import generate_stack, preset
from microfacet.io.stack import read_stack, write_stack
from microfacet.optics.thinfilm import reflectance

tmm = pytest.importorskip("tmm")

SIZE = 64
N_SLICES = 5
#: One ROI of the whole image (a side far larger than the 64 px images).
ONE_ROI = RoiOptions(size_px=10_000)


def _tmm_R(pol, n0, n1, n2, d, theta_deg, wl):
    return tmm.coh_tmm(pol, [n0, n1, n2], [np.inf, d, np.inf], np.deg2rad(theta_deg), wl)["R"]


def _textbook_fresnel(theta_deg, n0, n2, pol):
    """Ambient n0 (real) → n2 = n + ik, written from Born & Wolf, independently of thinfilm."""
    c0 = math.cos(math.radians(theta_deg))
    s0 = n0 * math.sin(math.radians(theta_deg))
    q2 = np.sqrt(complex(n2) ** 2 - s0 ** 2)
    if q2.imag < 0 or (q2.imag == 0 and q2.real < 0):
        q2 = -q2
    q0 = n0 * c0
    if pol == "s":
        r = (q0 - q2) / (q0 + q2)
    else:
        r = (complex(n2) ** 2 * q0 - n0 ** 2 * q2) / (complex(n2) ** 2 * q0 + n0 ** 2 * q2)
    return abs(r) ** 2


# ------------------------------------------------------------------------- thin film


FILMS = [2.45 + 0j, 2.2 + 1.0j, 2.0 + 10.0j]           # k = 0, absorbing, k = 10
SUBSTRATES = [2.54 + 3.43j, 1.5 + 10.0j, 1.5 + 0j, 0.5 + 0j]  # Ti-like, k = 10, k = 0 (two)


@pytest.mark.parametrize("theta", [0.0, 45.0, 89.99])
@pytest.mark.parametrize("d", [0.0, 51.0, 5000.0])
def test_reflectance_matches_tmm_at_grazing_incidence_thick_films_and_extreme_k(theta, d):
    wl = np.array([380.0, 550.0, 780.0])
    for n1 in FILMS:
        for n2 in SUBSTRATES:
            for pol in ("s", "p"):
                ours = reflectance(wl, theta, d, n1, n2, polarization=pol)
                ref = [_tmm_R(pol, 1.0, n1, n2, d, theta, w) for w in wl]
                assert np.all(np.isfinite(ours)) and np.all((ours >= 0) & (ours <= 1 + 1e-12))
                np.testing.assert_allclose(ours, ref, rtol=0, atol=1e-10,
                                           err_msg=f"{pol} n1={n1} n2={n2}")


@pytest.mark.slow
def test_five_micron_lossless_film_matches_tmm_across_the_visible():
    # 5 µm of a k = 0 film: ~60 interference fringes across the visible, phase up to ~400 rad.
    wl = np.arange(380.0, 781.0, 1.0)
    for theta in (0.0, 60.0, 89.99):
        for pol in ("s", "p"):
            ours = reflectance(wl, theta, 5000.0, 2.45, 2.54 + 3.43j, polarization=pol)
            ref = np.array([_tmm_R(pol, 1.0, 2.45, 2.54 + 3.43j, 5000.0, theta, w) for w in wl])
            assert np.all((ours >= 0) & (ours <= 1 + 1e-12))
            np.testing.assert_allclose(ours, ref, rtol=0, atol=1e-10)
            assert np.ptp(ours) > 0.05 or theta == 89.99  # the fringes are really there


def test_bare_substrate_at_89_99_deg_with_the_bundled_sets():
    from microfacet.optics import optical_constants

    wl = np.arange(380.0, 781.0, 20.0)
    n2 = optical_constants("Ti_JohnsonChristy1974", wl)
    for pol in ("s", "p"):
        R = reflectance(wl, 89.99, 0.0, "TiO2_Jolivet2023_amorphous", "Ti_JohnsonChristy1974",
                        polarization=pol)
        ref = [_textbook_fresnel(89.99, 1.0, n, pol) for n in n2]
        np.testing.assert_allclose(R, ref, rtol=0, atol=1e-12)


@pytest.mark.parametrize("n_ambient", [1.0, 1.5])
def test_film_with_the_ambient_index_is_invisible_at_every_thickness(n_ambient):
    d = np.linspace(0.0, 5000.0, 11)
    for theta in (0.0, 30.0, 60.0, 89.99):
        for n2 in (2.54 + 3.43j, 1.5 + 10.0j, 3.0 + 0j):
            for pol in ("s", "p"):
                R = reflectance(550.0, theta, d, n_ambient, n2, n_ambient=n_ambient,
                                polarization=pol)
                bare = _textbook_fresnel(theta, n_ambient, n2, pol)
                np.testing.assert_allclose(R, bare, rtol=0, atol=1e-12)


# ---------------------------------------------------------------- films below 5 nm


@pytest.fixture(scope="module")
def thin_table():
    from microfacet.colour.table import build_colour_table

    return build_colour_table(thickness_range_nm=(0.0, 5.0), theta_range_deg=(0.0, 27.0))


def _direct_lab(theta, d, white):
    """Lab from the reflectance spectrum integrated at 1 nm (independent of any table)."""
    from microfacet.colour.table import direct_xyz

    return color.xyz_to_lab(direct_xyz(theta, d, spectral_step_nm=1.0), white=white)


def test_colour_table_of_a_film_thinner_than_5_nm(thin_table):
    t = thin_table
    assert np.all(np.isfinite(t.xyz)) and np.all(np.isfinite(t.lab))
    assert math.isfinite(t.spectral_error_de00) and t.interp_error_de00 <= 0.05
    rng = np.random.default_rng(0)
    th, d = rng.uniform(0, 27, 300), rng.uniform(0, 5, 300)
    lab = t.lab_at(th, d)
    assert np.all(np.isfinite(lab))
    # against 1 nm direct integration (the table's own white is that of its grid)
    wl = np.arange(380.0, 781.0, 1.0)
    ref = _direct_lab(th, d, color.spectral_weights(wl).sum(axis=0))
    assert np.max(color.delta_e_2000(lab.astype(np.float64), ref)) < 0.1
    # the colour does change with thickness below 5 nm (what the fit relies on)
    assert color.delta_e_2000(t.lab_at(0.0, 0.0), t.lab_at(0.0, 5.0)) > 1.0


@pytest.fixture(scope="module")
def fit_table():
    from microfacet.colour.table import build_colour_table

    return build_colour_table(thickness_range_nm=(0.0, 100.0), theta_range_deg=(0.0, 27.0))


@pytest.mark.slow
@pytest.mark.parametrize("d_true", [0.5, 2.0, 4.5])
def test_thickness_fit_of_a_film_thinner_than_5_nm(fit_table, d_true):
    from microfacet.analysis.mixtures import fit_thickness_mixture
    from microfacet.analysis.roi import fit_roi_thickness, roi_grid
    from microfacet.colour.model import FilmColourModel

    rng = np.random.default_rng(1)
    H = W = 40
    tilt = rng.uniform(0.0, 20.0, (H, W))
    lab = _direct_lab(tilt, np.full((H, W), d_true), fit_table.white_xyz).astype(np.float32)
    rois = roi_grid((H, W), size_px=255)
    mask = np.zeros((H, W), bool)
    model = FilmColourModel(fit_table)
    known = fit_roi_thickness(lab, tilt, mask, model, RoiOptions(), rois=rois, exposure=1.0)
    # no saturation at the lower end of the range, nothing NaN
    assert np.isfinite(known.thickness_nm).all() and np.isfinite(known.mean_delta_e).all()
    assert known.thickness_nm[0] == pytest.approx(d_true, abs=0.1)
    free = fit_roi_thickness(lab, tilt, mask, model, RoiOptions(), rois=rois)
    assert np.isfinite(free.thickness_nm).all() and 0.5 < free.exposure < 2.0
    assert free.thickness_nm[0] == pytest.approx(d_true, abs=0.5)
    fit = fit_thickness_mixture(np.full(H * W, known.thickness_nm[0]))
    assert np.isfinite(fit.bic) and fit.mixture.means_nm[0] == known.thickness_nm[0]


# ---------------------------------------------------------------- stacks and analysis


@pytest.fixture(scope="module")
def sd(tmp_path_factory):
    """A small synthetic stack of one 51 nm film (64×64 px, 5 slices) and its truth."""
    root = tmp_path_factory.mktemp("hard")
    path = root / "sd"
    generate_stack(path, preset("sd", height_px=SIZE, width_px=SIZE, n_slices=N_SLICES,
                                seed=3))
    st = read_stack(path)
    slices = [np.round(st.read_slice(i) * 255).astype(np.uint8) for i in range(N_SLICES)]
    truth = {k: np.load(path / "truth" / f"{k}.npy") for k in ("thickness_nm", "height_um")}
    return {"root": root, "path": path, "stack": st, "slices": slices, "truth": truth}


@pytest.fixture(scope="module")
def clean(sd):
    # roi.size_px far larger than the 64 px image: one ROI of the image's size
    return analyse_stack(sd["path"], AnalysisOptions(roi=ONE_ROI))


def _summary(result, out):
    write_results(result, out)
    return json.loads((out / "summary.json").read_text())


def _pdf_integral(path):
    t = np.genfromtxt(path, delimiter=",", skip_header=1, ndmin=2)
    x = t[:, 0]
    mid = 0.5 * (x[1:] + x[:-1])
    edges = np.concatenate([[x[0] - (mid[0] - x[0])], mid, [x[-1] + (x[-1] - mid[-1])]])
    w = np.diff(edges)
    return t, edges, float(np.sum(t[:, 1] * w)), float(np.sum(t[:, 2] * w))


def test_roi_larger_than_the_image_is_one_roi_of_the_image(clean, sd):
    roi = clean.roi
    assert roi.row0.tolist() == [0] and roi.col0.tolist() == [0]
    assert (roi.height_px, roi.width_px) == (SIZE, SIZE)
    assert roi.n_pixels[0] == int((~clean.colour.mask.mask).sum())
    assert roi.thickness_nm[0] == pytest.approx(float(sd["truth"]["thickness_nm"].mean()), abs=1.0)


def test_roi_smaller_than_8_px_is_refused_naming_the_option(sd, tmp_path, capsys):
    with pytest.raises(InputError, match=r"roi\.size_px: must be >= 8") as err:
        AnalysisOptions.from_dict({"roi": {"size_px": 4}})
    assert err.value.param == "roi.size_px"
    with pytest.raises(InputError, match=r"roi\.stride_px: must be in \[1, roi\.size_px\]"):
        AnalysisOptions.from_dict({"roi": {"size_px": 16, "stride_px": 32}})
    out = tmp_path / "o"
    assert main(["analyze", str(sd["path"]), "--out", str(out), "--roi-size-px", "4"]) == 2
    err = capsys.readouterr().err
    assert "--roi-size-px" in err and "Traceback" not in err and not out.exists()


def _grey_stack(path, *, patch=None, dtype=np.uint8):
    """Textured grey slices (R = G = B, HSV saturation 0), sharpest in the middle."""
    import cv2

    rng = np.random.default_rng(2)
    tex = rng.random((SIZE, SIZE)).astype(np.float32)
    top = np.iinfo(dtype).max
    imgs = []
    for k in range(N_SLICES):
        g = cv2.GaussianBlur(tex, (0, 0), 0.5 + abs(k - 2))
        rgb = np.repeat((0.3 + 0.4 * g)[..., None], 3, axis=-1)
        if patch is not None:
            rgb[patch] = (0.2, 0.3, 0.7)  # a blue patch, the same in every slice
        imgs.append(np.round(rgb * top).astype(dtype))
    write_stack(path, imgs, z_step_um=1.0, pixel_size_um=0.2)
    return imgs


def test_every_pixel_masked_is_a_clear_input_error(tmp_path, capsys):
    from microfacet.analysis.mask import colour_mask

    imgs = _grey_stack(tmp_path / "grey")
    # independent check of the premise: every slice has saturation 0 everywhere
    assert all(colour_mask(im / 255.0, MaskOptions(shadow_ratio=0)).low_saturation.all()
               for im in imgs)
    with pytest.raises(InputError, match=r"grey/stack\.json: key 'slices': no colour information"
                                         r".*every pixel is masked.*low saturation 100%") as ei:
        analyse_stack(tmp_path / "grey")
    assert "\n" not in str(ei.value)
    out = tmp_path / "out"
    assert main(["analyze", str(tmp_path / "grey"), "--out", str(out), "-q"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err
    assert "stack.json" in err and "'slices'" in err and "every pixel is masked" in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["grey"]  # no results, no .partial


@pytest.mark.slow
def test_too_few_unmasked_pixels_is_a_clear_input_error(tmp_path):
    patch = (slice(30, 33), slice(30, 33))  # 9 coloured pixels, fewer than a ROI needs (20)
    _grey_stack(tmp_path / "grey", patch=patch)
    with pytest.raises(InputError, match=r"stack\.json: key 'slices'.*only (\d) unmasked pixels, "
                                         r"too few in every region of interest"):
        analyse_stack(tmp_path / "grey")


def test_sixteen_bit_full_scale_is_clipped_everywhere_and_refused(tmp_path):
    full = np.full((SIZE, SIZE, 3), 65535, np.uint16)
    write_stack(tmp_path / "white", [full] * N_SLICES, z_step_um=1.0, pixel_size_um=0.2)
    assert read_stack(tmp_path / "white").dtype == np.uint16
    with pytest.raises(InputError, match=r"key 'slices'.*every pixel is masked.*clipped 100%"):
        analyse_stack(tmp_path / "white")


@pytest.mark.slow
def test_sixteen_bit_partly_clipped_masks_exactly_the_clipped_pixels(tmp_path):
    """The sd film over-exposed 2.5 times in 16 bits: about 3/4 of the pixels clip. Those
    with two or three channels at full scale are masked; those with one are analysed with
    the model clipped alike (their thickness as near the truth as the unclipped pixels'),
    or masked with the rest by ``mask.clipped_one_channel`` off."""
    p = preset("16bit", height_px=SIZE, width_px=SIZE, n_slices=N_SLICES, seed=4, exposure=2.5,
               thickness=preset("sd").thickness)
    generate_stack(tmp_path / "s16", p)
    r = analyse_stack(tmp_path / "s16", AnalysisOptions(roi=ONE_ROI))
    assert read_stack(tmp_path / "s16").dtype == np.uint16
    aif = r.focus.all_in_focus  # the slices' code values / 65535
    n_full = np.sum(np.round(aif * 65535) >= 65535, axis=-1)
    assert 0.02 < (n_full > 0).mean() < 0.98 and (n_full == 1).mean() > 0.1   # really there
    mask, px = r.colour.mask, r.pixels
    np.testing.assert_array_equal(mask.clipped | mask.clipped_one, n_full > 0)
    assert not mask.clipped_one[n_full != 1].any() and r.colour.clip_rgb == (1.0, 1.0, 1.0)
    assert np.isnan(px.thickness_nm[mask.clipped]).all()
    ok = ~mask.mask
    assert np.isfinite(px.thickness_nm[ok]).all() and np.isfinite(px.tilt_deg[ok]).all()
    truth = np.load(tmp_path / "s16" / "truth" / "thickness_nm.npy")
    err = np.abs(px.thickness_nm - truth)
    one, rest = ok & mask.clipped_one, ok & ~mask.clipped_one
    assert np.median(err[one]) < max(1.0, 1.5 * np.median(err[rest]))
    off = analyse_stack(tmp_path / "s16", AnalysisOptions(
        roi=ONE_ROI, mask=MaskOptions(clipped_one_channel=False)))
    np.testing.assert_array_equal(off.colour.mask.clipped, n_full > 0)
    assert np.isnan(off.pixels.thickness_nm[n_full > 0]).all() and off.colour.clip_rgb is None


@pytest.mark.parametrize("n", [1, 2])
def test_fewer_than_three_slices_is_a_clear_input_error(tmp_path, capsys, sd, n):
    write_stack(tmp_path / "few", sd["slices"][:n], z_step_um=1.0, pixel_size_um=0.2)
    assert read_stack(tmp_path / "few").n_slices == n  # the format allows it
    with pytest.raises(InputError, match=rf"few/stack\.json: key 'slices'.*at least 3 slices.*"
                                         rf"has {n}"):
        analyse_stack(tmp_path / "few")
    for cmd in ("analyze", "height"):
        assert main([cmd, str(tmp_path / "few"), "--out", str(tmp_path / "o")]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and "key 'slices'" in err and "at least 3" in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["few"]


def test_identical_slices_give_no_height_and_colour_only_tilts(sd, tmp_path, caplog):
    write_stack(tmp_path / "same", [sd["slices"][2]] * N_SLICES, z_step_um=0.5,
                pixel_size_um=sd["stack"].pixel_size_um)
    with caplog.at_level(logging.WARNING, logger="microfacet.analysis"):
        r = analyse_stack(tmp_path / "same", AnalysisOptions(roi=ONE_ROI))
    assert "no pixel has a reliable height" in caplog.text
    assert np.isnan(r.focus.height_um).all() and not r.focus.reliable.any()
    assert r.surface.no_focus
    assert np.all(r.surface.tilt_deg == 0)          # the fitted height is flat, not noise
    ok = ~r.colour.mask.mask
    assert ok.mean() > 0.9 and np.isfinite(r.pixels.thickness_nm[ok]).all()
    # thickness from colour alone is still right (tilts are small on this preset)
    truth = sd["truth"]["thickness_nm"]
    assert r.roi.thickness_nm[0] == pytest.approx(float(truth.mean()), abs=1.0)
    s = _summary(r, tmp_path / "res")
    assert s["height"]["unreliable_fraction"] == 1.0
    assert np.isnan(np.load(tmp_path / "res" / "height_um.npy")).all()
    assert np.isnan(np.load(tmp_path / "res" / "normals.npy")).all()
    # no height: the NDF is fitted for inspection but not identified, and says why
    assert s["thickness"]["mixture"]["components"] and s["thickness"]["mixture"]["identified"]
    assert s["ndf"]["identified"] is False and "identified" not in s["ndf"]["mixture"]
    assert s["ndf"]["reason_code"] == "few_planes"
    assert "height from focus gives a plane on 0 of" in s["ndf"]["reason"]
    assert any(w.startswith("NDF not identified") for w in s["warnings"])


def test_peak_fit_of_a_flat_focus_curve_has_no_maximum():
    from microfacet.focus.height import peak_fit

    # constant focus values of many magnitudes, with and without missing neighbours: the
    # rounding-level curvature must not become a peak clipped to the window's edge
    rng = np.random.default_rng(0)
    v = np.repeat(rng.uniform(1e-4, 0.1, (1, 500)), 5, axis=0)
    x = np.repeat(np.arange(-2.0, 3.0)[:, None], 500, axis=1)
    x[:2, :200] = np.nan
    for dtype in (np.float32, np.float64):
        off, _, ok = peak_fit(v.astype(dtype), x.astype(dtype), dtype=dtype)
        assert not ok.any() and np.all(off == 0)


def test_heavy_noise_gives_a_finite_result_that_reports_its_unreliability(sd, clean, tmp_path):
    # the 'noisy' preset has 150 e- full well and 0.02 read noise; this is 50x / 15x worse
    p = preset("sd", height_px=SIZE, width_px=SIZE, n_slices=N_SLICES, seed=3, full_well_e=3.0,
               read_noise=0.3)
    generate_stack(tmp_path / "noisy", p)
    r = analyse_stack(tmp_path / "noisy", AnalysisOptions(roi=ONE_ROI))
    s = _summary(r, tmp_path / "res")
    c = _summary(clean, tmp_path / "clean")
    assert s["colour_noise_de"] > 10 * c["colour_noise_de"]
    assert s["height"]["unreliable_fraction"] > c["height"]["unreliable_fraction"] + 0.2
    assert s["delta_e"]["mean"] > 5 * c["delta_e"]["mean"]
    # fewer facets get a tilt from the height map, and the NDF says whether it is measured
    assert (s["facets"]["height_plane_area_fraction"]
            < c["facets"]["height_plane_area_fraction"])
    assert s["ndf"]["identified"] is False and s["ndf"]["reason"]
    ok = ~r.colour.mask.mask
    for name in ("thickness_nm", "tilt_deg", "tilt_sigma_deg", "delta_e"):
        a = getattr(r.pixels, name)
        assert np.isfinite(a[ok]).all() and np.isnan(a[~ok]).all(), name
    for name in ("thickness_pdf.csv", "ndf_pdf.csv"):
        _, _, hist, mix = _pdf_integral(tmp_path / "res" / name)
        assert hist == pytest.approx(1.0, abs=1e-4) and mix == pytest.approx(1.0, abs=1e-4)


def test_unsorted_z_in_stack_json_gives_the_same_analysis(sd, clean, tmp_path):
    perm = [3, 0, 4, 1, 2]
    z = sd["stack"].z_um
    write_stack(tmp_path / "shuffled", [sd["slices"][i] for i in perm],
                z_um=[float(z[i]) for i in perm], pixel_size_um=sd["stack"].pixel_size_um,
                illumination=sd["stack"].illumination)
    st = read_stack(tmp_path / "shuffled")
    assert list(st.z_um) != sorted(st.z_um)
    r = analyse_stack(st, AnalysisOptions(roi=ONE_ROI))
    np.testing.assert_allclose(r.focus.height_fit_um, clean.focus.height_fit_um, rtol=0,
                               atol=1e-4)
    np.testing.assert_array_equal(np.isnan(r.focus.height_um), np.isnan(clean.focus.height_um))
    np.testing.assert_array_equal(np.asarray(perm)[r.focus.best_index], clean.focus.best_index)
    np.testing.assert_allclose(r.pixels.thickness_nm, clean.pixels.thickness_nm, atol=1e-3,
                               equal_nan=True)
    # and the height is the true one where reliable (unsorted z were not mixed up)
    ok = r.focus.reliable
    assert np.median(np.abs(r.focus.height_um[ok] - sd["truth"]["height_um"][ok])) < 0.2


def test_tiny_numerical_aperture_still_gives_an_ndf_table(sd, tmp_path):
    write_stack(tmp_path / "na", sd["slices"], z_um=list(sd["stack"].z_um),
                pixel_size_um=sd["stack"].pixel_size_um,
                illumination={"geometry": "coaxial", "numerical_aperture": 0.02})
    r = analyse_stack(tmp_path / "na", AnalysisOptions(roi=ONE_ROI, mode="seed"))
    max_tilt = math.degrees(math.asin(0.02)) / 2.0   # 0.573°: fewer than 2 cells of 0.5°
    assert r.scene.max_tilt_deg == pytest.approx(max_tilt)
    tl = r.pixels.tilt_deg[np.isfinite(r.pixels.tilt_deg)]
    assert tl.size and tl.min() >= 0 and tl.max() <= max_tilt + 1e-6
    assert 0 < np.mean(tl == 0) < 1          # tilts at both ends of the range
    _summary(r, tmp_path / "res")
    t, edges, hist, mix = _pdf_integral(tmp_path / "res" / "ndf_pdf.csv")
    assert t.shape[0] >= 2
    assert edges[0] == pytest.approx(0.0, abs=1e-5) and edges[-1] == pytest.approx(max_tilt)
    assert hist == pytest.approx(1.0, abs=1e-4) and mix == pytest.approx(1.0, abs=1e-4)
    # every tilt is counted, those at max_tilt too (float32 may round them past it)
    edges = np.linspace(0.0, max_tilt, t.shape[0] + 1)
    edges[-1] += 1e-6
    counts, _ = np.histogram(tl, bins=edges)
    assert counts.sum() == tl.size
    np.testing.assert_allclose(t[:, 1], counts / (tl.size * np.diff(edges)), rtol=1e-4)


def test_single_thickness_value_end_to_end(sd, tmp_path):
    # seed mode with one ROI: every pixel gets the ROI's thickness, a one-value histogram
    r = analyse_stack(sd["path"], AnalysisOptions(roi=ONE_ROI, mode="seed"))
    vals = np.unique(r.pixels.thickness_nm[np.isfinite(r.pixels.thickness_nm)])
    assert vals.size == 1
    s = _summary(r, tmp_path / "res")
    mix = s["thickness"]["mixture"]
    assert "single value" in mix["degenerate"] and mix["bic"] is not None
    assert mix["components"][0]["mean_nm"] == pytest.approx(float(vals[0]))
    t, edges, hist, mixture = _pdf_integral(tmp_path / "res" / "thickness_pdf.csv")
    assert hist == pytest.approx(1.0, abs=1e-4) and mixture == pytest.approx(1.0, abs=1e-4)
    # the histogram is one cell holding the value; the mixture column is the normal law's
    # mass per cell (independent: scipy.stats.norm), renormalised over the grid
    from scipy.stats import norm

    cell = np.searchsorted(edges, vals[0]) - 1
    assert np.count_nonzero(t[:, 1]) == 1 and t[cell, 1] > 0
    sd_nm = mix["components"][0]["sd_nm"]
    mass = np.diff(norm.cdf(edges, loc=vals[0], scale=sd_nm))
    np.testing.assert_allclose(t[:, 2], mass / mass.sum() / np.diff(edges), rtol=1e-4,
                               atol=1e-9)


def test_all_zero_tilts_give_a_finite_ndf_table():
    from microfacet.analysis.ndf_fit import fit_ndf_mixture
    from microfacet.core.densities import pdf_table

    fit = fit_ndf_mixture(np.zeros(500))
    max_tilt = math.degrees(math.asin(0.8)) / 2.0
    n = math.ceil(max_tilt / 0.5)
    grid = (np.arange(n) + 0.5) * (max_tilt / n)   # write_results' NDF grid
    t = pdf_table(np.zeros(500), fit.mixture, grid=grid)
    w = max_tilt / n
    assert np.all(np.isfinite(t))
    assert t[0, 1] * w == pytest.approx(1.0) and np.all(t[1:, 1] == 0)
    # Rayleigh slope law of the floor lobe (sd 0.05°): its mass within the first cell
    s = math.tan(math.radians(fit.mixture.sds_deg[0]))
    first = 1.0 - math.exp(-0.5 * (math.tan(math.radians(w)) / s) ** 2)
    assert t[0, 2] * w == pytest.approx(first, rel=1e-9)


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
@pytest.mark.parametrize("smooth", [0.0, 1.5])
def test_non_finite_heights_propagate_to_the_normals_without_warnings(bad, smooth):
    from microfacet.focus.fill import fill_missing
    from microfacet.focus.normals import normals_from_height, tilt_azimuth_deg

    rows, cols = np.mgrid[0:24, 0:30]
    h = (0.1 * cols + 0.05 * rows).astype(np.float32)
    h[5:8, 10:13] = bad
    h[0, 0] = bad
    good = np.isfinite(h)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no RuntimeWarning from inf − inf
        n = normals_from_height(h, pixel_size_um=0.5, smooth_sigma_px=smooth)
        tilt, az = tilt_azimuth_deg(n)
        filled = fill_missing(h)
    assert np.isnan(n[~good]).all() and np.isfinite(n[good]).all()
    assert np.isnan(tilt[~good]).all() and np.isnan(az[~good]).all()
    # slope (0.2, -0.1) per µm in the x-right / y-up frame: an exact plane
    expected = math.degrees(math.atan(math.hypot(0.1 / 0.5, 0.05 / 0.5)))
    np.testing.assert_allclose(tilt[good], expected, atol=1e-4)
    assert np.isfinite(filled).all() and np.array_equal(filled[good], h[good])


def test_all_non_finite_height_map_and_non_finite_normals():
    from microfacet.focus.normals import normals_from_height, tilt_azimuth_deg

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        for bad in (np.nan, np.inf):
            n = normals_from_height(np.full((6, 7), bad), pixel_size_um=1.0)
            assert n.shape == (6, 7, 3) and np.isnan(n).all()
        tilt, az = tilt_azimuth_deg(np.array([[np.inf, 0.0, 1.0], [0.0, 0.0, np.inf],
                                              [np.nan, 0.0, 1.0], [0.0, 0.0, 1.0]]))
    assert np.isnan(tilt[:3]).all() and np.isnan(az[:3]).all()
    assert tilt[3] == 0 and az[3] == 0


def test_facet_planes_ignore_non_finite_heights():
    from microfacet.analysis.planes import fit_facet_planes

    rows, cols = np.mgrid[0:20, 0:20]
    h = 0.1 * cols * 0.5       # dh/dx = 0.1 with 0.5 µm pixels
    labels = (cols >= 10).astype(np.int32)
    h[3:6, 2:5] = np.nan
    h[8:10, 12:15] = np.inf
    h[:, 10:] = np.where(rows[:, 10:] % 2 == 0, np.inf, np.nan)  # segment 1: no finite height
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        ff = fit_facet_planes(labels, h, height_sigma_um=np.full(h.shape, 0.01),
                              reliable=np.isfinite(h), pixel_size_um=0.5, min_pixels=8)
    assert ff.fitted.tolist() == [True, False]
    assert ff.tilt_deg[0] == pytest.approx(math.degrees(math.atan(0.1)), abs=1e-6)
    # no height, no guess: the unfitted facet has no tilt
    assert np.isnan(ff.tilt_deg[1]) and np.isfinite(ff.tilt_sigma_deg[0])
