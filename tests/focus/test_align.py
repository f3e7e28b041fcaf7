"""Registration of slices that drift or change magnification (microfacet.focus.align).

Slices are moved by known affine warps (``cv2.warpAffine``: the slice at ``A·x`` shows what
the reference shows at ``x``) and registered back: the estimated warps (reference pixel
coordinates → slice pixel coordinates) must equal ``A`` within a stated number of pixels
everywhere inside the image, and what is built on them (the all-in-focus composite, the
height map) must be better than without alignment. Also on the real PCB stack, whose lens
zooms while focusing (fixtures/focus-stacks/focus-stack-pcb-topdown-small).
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from microfacet.core.errors import InputError
from microfacet.focus.align import estimate_warps, warp_to_reference, warped_loader
from microfacet.focus.height import height_from_focus
from microfacet.focus.measures import focus_measure
from microfacet.focus.options import FocusOptions
from microfacet.io.stack import read_stack

PCB = (Path(__file__).resolve().parents[2] / "fixtures" / "focus-stacks"
       / "focus-stack-pcb-topdown-small")
#: Every pixel keeps its height (no reliability cut).
ALL = FocusOptions(min_reliability_db=-np.inf)
PCB_SCALES = [0.939, 0.948, 0.965, 0.986, 1.000, 1.015, 1.035, 1.054, 1.068, 1.085]


@pytest.mark.slow
def test_pcb_alignment_scales_and_sharp_composite():
    """The real PCB stack (lens refocus, ~15 % zoom): the estimated magnifications against
    slice 4 match the source README's, and the aligned composite is sharp in every tile."""
    st = read_stack(PCB)
    res = height_from_focus(st, FocusOptions(align="ecc", reference=4))
    warps = [np.array(w) for w in res.params["alignment"]["warps"]]
    scales = [0.5 * (w[0, 0] + w[1, 1]) for w in warps]
    np.testing.assert_allclose(scales, PCB_SCALES, atol=0.01)
    # automatic reference: the most magnified slice (its field lies in every other slice)
    auto = height_from_focus(st, FocusOptions(align="ecc"))
    assert auto.params["alignment"]["reference"] == 9
    # sharp everywhere: in each 64-px tile the composite is nearly as sharp as the sharpest
    # aligned slice there
    aif = focus_measure(auto.all_in_focus, operator="tenengrad", window_px=1)
    warps = [np.array(w, np.float32) for w in auto.params["alignment"]["warps"]]
    per_slice = [focus_measure(warp_to_reference(im, warps[i]), operator="tenengrad",
                               window_px=1) for i, _, im in st.iter_slices()]
    T = 64
    ratios = []
    H, W = st.shape
    for y in range(T, H - T, T):           # skip the outer tiles (warped-in borders)
        for x in range(T, W - T, T):
            best_slice = max(f[y:y + T, x:x + T].mean() for f in per_slice)
            ratios.append(aif[y:y + T, x:x + T].mean() / best_slice)
    assert min(ratios) > 0.85


def test_alignment_recovers_synthetic_zoom_and_drift(render_stack):
    H, W = 96, 120
    yy, xx = np.mgrid[0:H, 0:W]
    h = (1.0 + 5.0 * xx / W).astype(np.float32)
    z = np.arange(0.0, 7.0, 0.5)
    imgs = render_stack(h, z, seed=9)
    ref = height_from_focus(imgs, ALL, z_um=z)
    # each slice magnified about the centre by 1 + 0.006 k and shifted by (0.4 k, -0.3 k) px
    moved, true = [], []
    for k, im in enumerate(imgs):
        s = 1.0 + 0.006 * k
        A = np.array([[s, 0, (1 - s) * W / 2 + 0.4 * k], [0, s, (1 - s) * H / 2 - 0.3 * k]],
                     np.float32)
        moved.append(cv2.warpAffine(im, A, (W, H), flags=cv2.INTER_LINEAR,
                                    borderMode=cv2.BORDER_REFLECT))
        true.append(A)
    res = height_from_focus(moved, ALL.replace(align="ecc", reference=0), z_um=z)
    gy, gx = np.mgrid[16:H - 16:8, 16:W - 16:8]
    pts = np.stack([gx.ravel(), gy.ravel(), np.ones(gx.size)])
    for A, w in zip(true, res.params["alignment"]["warps"]):
        # A maps original (= slice 0, the reference) coordinates to slice k coordinates;
        # chained neighbour registration of blurred slices: within 0.6 px everywhere inside
        d = np.hypot(*((np.array(w, np.float64) - A) @ pts))
        assert d.max() < 0.6
    c = (slice(16, -16), slice(16, -16))
    rmse_aligned = np.sqrt(np.mean((res.height_um[c] - h[c]) ** 2))
    plain = height_from_focus(moved, ALL, z_um=z)
    rmse_plain = np.sqrt(np.mean((plain.height_um[c] - h[c]) ** 2))
    rmse_ref = np.sqrt(np.mean((ref.height_um[c] - h[c]) ** 2))
    assert rmse_aligned < rmse_ref + 0.05
    assert rmse_aligned < 0.7 * rmse_plain


# ------------------------------------------------------------------ estimate_warps directly

H, W = 128, 160
N = 6
CENTRE = np.array([W / 2, H / 2])


def _texture(seed=0, sigma=1.5):
    """A sharp random texture (float32, mean 0.5, SD 0.15), smooth enough for sub-pixel
    registration."""
    rng = np.random.default_rng(seed)
    tex = cv2.GaussianBlur(rng.random((H, W)).astype(np.float32), (0, 0), sigma)
    return (tex - tex.mean()) / tex.std() * 0.15 + 0.5


def _affine(scale=1.0, rot_deg=0.0, shift=(0.0, 0.0)):
    """2×3 affine: rotation and magnification about the image centre, then a shift."""
    t = np.deg2rad(rot_deg)
    A = np.zeros((2, 3))
    A[:, :2] = scale * np.array([[np.cos(t), -np.sin(t)], [np.sin(t), np.cos(t)]])
    A[:, 2] = CENTRE - A[:, :2] @ CENTRE + np.asarray(shift)
    return A


def _move(img, A):
    return cv2.warpAffine(img, A.astype(np.float32), (W, H), flags=cv2.INTER_LINEAR,
                          borderMode=cv2.BORDER_REFLECT)


def _max_error_px(warp, A, margin=16):
    """Largest distance between where ``warp`` and the truth ``A`` send the points of a
    grid inside the image (``margin`` px from the border)."""
    gy, gx = np.mgrid[margin:H - margin:4, margin:W - margin:4]
    pts = np.stack([gx.ravel(), gy.ravel(), np.ones(gx.size)])
    return float(np.hypot(*((np.asarray(warp, np.float64) - A) @ pts)).max())


@pytest.fixture(scope="module")
def zoom_drift():
    """Slice k: magnified by 1 + 0.01 k, rotated by 0.3 k degrees and shifted by
    (0.7 k, −0.45 k) px (a lens that zooms while focusing, on a drifting stage)."""
    tex = _texture()
    true = [_affine(1 + 0.01 * k, 0.3 * k, (0.7 * k, -0.45 * k)) for k in range(N)]
    return tex, true, [_move(tex, A) for A in true]


def test_ecc_recovers_zoom_rotation_and_drift(zoom_drift):
    _, true, moved = zoom_drift
    calls = []

    def load(i):
        calls.append(i)
        return moved[i]

    warps, ref = estimate_warps(load, list(range(N)), (H, W), method="ecc", reference=0)
    assert ref == 0
    # one streaming pass: every slice decoded once, in the given z order
    assert calls == list(range(N))
    np.testing.assert_allclose(warps[0], np.eye(2, 3), atol=1e-6)
    for k, (w, A) in enumerate(zip(warps, true)):
        assert w.shape == (2, 3) and w.dtype == np.float32
        # chained neighbour registration: errors add up along the chain (measured ~0.01 px
        # per step on this texture); 0.05 px per step, inside the image
        assert _max_error_px(w, A) < 0.02 + 0.05 * k, k


def test_warps_are_expressed_in_the_chosen_reference_frame(zoom_drift):
    """With reference r, slice i's warp is A_i ∘ A_r⁻¹ (reference r coordinates → slice i)."""
    _, true, moved = zoom_drift
    r = 3
    warps, ref = estimate_warps(lambda i: moved[i], list(range(N)), (H, W), reference=r)
    assert ref == r
    Ar_inv = np.linalg.inv(np.vstack([true[r], [0, 0, 1]]))
    for i, w in enumerate(warps):
        expected = (np.vstack([true[i], [0, 0, 1]]) @ Ar_inv)[:2]
        assert _max_error_px(w, expected) < 0.02 + 0.05 * abs(i - r), i


def test_automatic_reference_is_the_most_magnified_slice(zoom_drift):
    """Its field of view lies inside every other slice's: the slice of largest zoom."""
    _, _, moved = zoom_drift
    warps, ref = estimate_warps(lambda i: moved[i], list(range(N)), (H, W))
    assert ref == N - 1
    np.testing.assert_allclose(warps[ref], np.eye(2, 3), atol=1e-6)


def test_z_order_is_the_registration_order_not_the_file_order(zoom_drift):
    """Files listed out of z order: neighbours in ``order`` are registered pairwise and the
    warps stay indexed by file."""
    _, true, moved = zoom_drift
    perm = [2, 0, 5, 1, 4, 3]                      # file i holds slice perm[i]
    files = [moved[p] for p in perm]
    order = [perm.index(k) for k in range(N)]      # file indices in increasing z
    calls = []

    def load(i):
        calls.append(i)
        return files[i]

    warps, _ = estimate_warps(load, order, (H, W), reference=perm.index(0))
    assert calls == order
    for i, w in enumerate(warps):
        assert _max_error_px(w, true[perm[i]]) < 0.02 + 0.05 * perm[i], i


def test_registration_on_downscaled_copies_is_scaled_back(zoom_drift):
    """``max_side`` half the image: the warps found on half-size copies are expressed in
    full-size pixels (without rescaling, the shift of slice 5 would be off by half its
    length, ~2 px); the registration is coarser, so the bound is looser."""
    _, true, moved = zoom_drift
    warps, _ = estimate_warps(lambda i: moved[i], list(range(N)), (H, W), reference=0,
                              max_side=W // 2)
    errors = [_max_error_px(w, A) for w, A in zip(warps, true)]
    shift = float(np.hypot(*(true[-1][:, 2] - _affine(1 + 0.01 * (N - 1), 0.3 * (N - 1))[:, 2])))
    assert shift > 3.5
    assert max(errors) < 1.0 < 0.5 * shift


def test_phase_correlation_recovers_a_drift():
    tex = _texture(seed=1)
    true = [_affine(shift=(0.8 * k, -0.55 * k)) for k in range(N)]
    moved = [_move(tex, A) for A in true]
    warps, _ = estimate_warps(lambda i: moved[i], list(range(N)), (H, W), method="phase",
                              reference=0)
    for k, (w, A) in enumerate(zip(warps, true)):
        np.testing.assert_array_equal(w[:, :2], np.eye(2))   # translation only
        # OpenCV's sub-pixel peak is biased towards whole pixels (~0.1-0.3 px per pair on
        # this texture): a quarter pixel per step of the chain (a sign error would be ~2 px
        # per step)
        assert _max_error_px(w, A) < 0.25 * (k + 1), k


def test_warp_to_reference_undoes_the_warp(zoom_drift):
    tex, true, moved = zoom_drift
    inner = (slice(16, -16), slice(16, -16))
    load = warped_loader(lambda i: moved[i], [A.astype(np.float32) for A in true], (H, W))
    for k in range(1, N):
        back = warp_to_reference(moved[k], true[k].astype(np.float32))
        assert back.shape == tex.shape and back.dtype == tex.dtype
        # bilinear resampling twice: a small, uniform error, far below the misregistration
        err = np.abs(back - tex)[inner]
        assert err.mean() < 0.02 and err.max() < 0.1
        assert np.abs(moved[k] - tex)[inner].mean() > 3 * err.mean()
        np.testing.assert_array_equal(load(k), back)
    rgb = np.repeat(moved[2][..., None], 3, axis=-1)
    out = warp_to_reference(rgb, true[2].astype(np.float32))
    assert out.shape == rgb.shape
    # each channel as the grey slice, to float32 rounding: OpenCV 5.1's three-channel
    # warpAffine rounds 15 of these 20480 pixels one unit in the last place apart from its
    # one-channel path (5.0 gave them bit for bit)
    np.testing.assert_allclose(out[..., 1], warp_to_reference(moved[2],
                                                              true[2].astype(np.float32)),
                               rtol=0, atol=2e-7)


def test_bad_method_and_reference_are_refused(zoom_drift):
    _, _, moved = zoom_drift
    with pytest.raises(ValueError, match="align method"):
        estimate_warps(lambda i: moved[i], list(range(N)), (H, W), method="sift")
    with pytest.raises(InputError, match="reference 9"):
        estimate_warps(lambda i: moved[i], list(range(N)), (H, W), reference=9)


# ------------------------------------------------------------------ through height_from_focus


@pytest.mark.slow
def test_aligned_all_in_focus_is_sharper_than_without_alignment(render_stack):
    """A drifting stage: the composite of aligned slices is close to the sharp texture (in
    the reference's frame); without alignment each pixel comes from a shifted slice."""
    h_, w_ = 96, 120
    h = np.add.outer(np.zeros(h_), np.linspace(1.0, 6.0, w_)).astype(np.float32)
    z = np.arange(0.0, 7.0, 0.5)
    imgs = render_stack(h, z, seed=11)
    sharp = render_stack(np.zeros_like(h), [0.0], seed=11, blur_per_um=0.0)[0]
    moved = [cv2.warpAffine(im, np.float32([[1, 0, 0.5 * k], [0, 1, 0.35 * k]]), (w_, h_),
                            flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT)
             for k, im in enumerate(imgs)]
    inner = (slice(16, -16), slice(16, -16))
    aligned = height_from_focus(moved, ALL.replace(align="ecc", reference=0),
                                z_um=z)
    plain = height_from_focus(moved, ALL, z_um=z)
    e_aligned = np.abs(aligned.all_in_focus - sharp)[inner].mean()
    e_plain = np.abs(plain.all_in_focus - sharp)[inner].mean()
    assert e_aligned < 0.5 * e_plain
    assert aligned.params["alignment"]["reference"] == 0
    rmse = {name: np.sqrt(np.mean((r.height_um[inner] - h[inner]) ** 2))
            for name, r in (("aligned", aligned), ("plain", plain))}
    assert rmse["aligned"] < rmse["plain"]
