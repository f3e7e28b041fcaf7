"""ISO 25178-2 areal parameters (microfacet.analysis.iso25178): Sq, Sa and Sdq against
SurfaceTopography on the three instrument fixtures (about the mean, as SurfaceTopography
reads a file, and about the least-squares plane, its ``detrend("height")``); Sdr, which
SurfaceTopography does not compute, against a tilted plane and sinusoids on non-square
pixels; unreliable pixels excluded; the summary's ``iso25178`` section through the analysis
of the x3p fixture."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from microfacet.analysis import analyse_stack, write_results
from microfacet.analysis.iso25178 import areal_parameters
from microfacet.core.errors import InputError
from microfacet.io.instruments import read_height_map
from microfacet.io.stack import read_stack

ROOT = Path(__file__).resolve().parents[2]
#: SurfaceTopography calls its own deprecated `Sq` internally (as in tests/io/test_x3p.py)
pytestmark = pytest.mark.filterwarnings("ignore:Function/property `Sq` is deprecated")
INSTRUMENTS = ROOT / "fixtures" / "instrument-heights"
X3P = ROOT / "fixtures" / "exports" / "nd-x3p"


def _surface_topography(path, reference):
    """SurfaceTopography's own reading of ``path`` (heights in µm), levelled for "plane"."""
    st = pytest.importorskip("SurfaceTopography")
    t = st.open_topography(str(path)).topography()
    scale = {"m": 1e6, "mm": 1e3, "µm": 1.0, "um": 1.0}[t.unit]
    return (t.detrend("height") if reference == "plane" else t), scale


@pytest.mark.parametrize("reference", ["mean", "plane"])
@pytest.mark.parametrize("name", ["al3d-1.al3d", "plu-1.plu", "mnt-1.mnt"])
def test_sq_sa_sdq_match_surface_topography(name, reference):
    """Within 1 % asked; they agree to 1e-5 (float32 maps). SurfaceTopography has no Sa
    (its ``mad_height`` is a robust estimate of the RMS height from the median absolute
    deviation, 0.0073 µm against Sa 0.0080 µm and Sq 0.0246 µm on mnt-1): Sa is checked
    against the mean absolute deviation of SurfaceTopography's own heights."""
    t, scale = _surface_topography(INSTRUMENTS / name, reference)
    m = read_height_map(INSTRUMENTS / name)
    p = areal_parameters(m.height_um, pixel_size_um=m.pixel_size_um, reference=reference)
    h = np.ma.compressed(t.heights()) * scale
    assert p.Sq_um == pytest.approx(t.rms_height_from_area() * scale, rel=1e-5)
    assert p.Sa_um == pytest.approx(np.mean(np.abs(h - h.mean())), rel=1e-5)
    assert p.Sdq == pytest.approx(t.rms_gradient(), rel=1e-5)
    assert p.n_points == h.size and p.n_cells == (m.height_um.shape[0] - 1) * (
        m.height_um.shape[1] - 1)
    assert p.Sdr_percent > 0


def test_non_square_pixels_apply_to_their_axes():
    """mnt-1's grid is 0.06 % non-square: with y and x swapped Sdq moves by 1e-4, ten times
    the tolerance that matches SurfaceTopography."""
    t, _ = _surface_topography(INSTRUMENTS / "mnt-1.mnt", "mean")
    m = read_height_map(INSTRUMENTS / "mnt-1.mnt")
    swapped = areal_parameters(m.height_um, pixel_size_um=m.pixel_size_um[::-1]).Sdq
    assert abs(swapped / t.rms_gradient() - 1) > 1e-4


@pytest.mark.parametrize("py,px", [(0.5, 0.25), (0.13, 0.31)])
def test_tilted_plane_sdr_sdq_exact(py, px):
    """A plane z = p·x + q·y: Sdq = √(p² + q²), Sdr = (√(1 + p² + q²) − 1)·100 % about the
    mean; about its least-squares plane everything is 0 and the plane's slopes are
    returned."""
    y, x = np.mgrid[0:40, 0:50]
    p, q = 0.7, -0.2
    h = p * x * px + q * y * py + 3.0
    a = areal_parameters(h, pixel_size_um=(py, px), reference="mean")
    assert a.Sdq == pytest.approx(math.hypot(p, q), rel=1e-9)
    assert a.Sdr_percent == pytest.approx((math.sqrt(1 + p * p + q * q) - 1) * 100, rel=1e-9)
    b = areal_parameters(h, pixel_size_um=(py, px))
    assert b.plane_slope_yx == pytest.approx((q, p), rel=1e-9)
    assert max(b.Sq_um, b.Sa_um, b.Sdq, b.Sdr_percent) < 1e-9


@pytest.mark.parametrize("axis", [0, 1])
def test_sinusoid_against_numerical_integration(axis):
    """z = A sin(2π s / λ) along y or x on 0.2 × 0.1 µm pixels (64 pixels per period):
    Sq = A/√2, Sa = 2A/π, Sdq = A k/√2 and Sdr = mean(√(1 + (A k cos)²) − 1) by numerical
    integration, within 0.5 % (forward differences lose (k·pixel)²/24 ≈ 0.04 %)."""
    py, px = 0.2, 0.1
    step = (py, px)[axis]
    lam = 64 * step
    amp = 0.15 * lam                            # A k ≈ 0.94: Sdr ≈ 20 %
    k = 2 * np.pi / lam
    y, x = np.mgrid[0:256, 0:320]
    s = (y * py, x * px)[axis]
    h = amp * np.sin(k * s)
    p = areal_parameters(h, pixel_size_um=(py, px), reference="mean")
    u = np.linspace(0, 2 * np.pi, 200001)[:-1]
    sdr = np.mean(np.sqrt(1 + (amp * k * np.cos(u)) ** 2) - 1) * 100
    assert p.Sq_um == pytest.approx(amp / np.sqrt(2), rel=5e-3)
    assert p.Sa_um == pytest.approx(2 * amp / np.pi, rel=5e-3)
    assert p.Sdq == pytest.approx(amp * k / np.sqrt(2), rel=5e-3)
    assert p.Sdr_percent == pytest.approx(sdr, rel=5e-3)
    assert sdr > 10  # steep enough that Sdr is not ~ Sdq²/2
    wrong = areal_parameters(h, pixel_size_um=(px, py), reference="mean")
    assert wrong.Sdq == pytest.approx(p.Sdq * (py / px) ** (1 if axis == 0 else -1), rel=1e-6)


def _cell_loop(h, ok, py, px):
    """Sdq and cell count by a plain loop: a cell only where (i, j), (i, j+1), (i+1, j) are
    all usable."""
    g2 = []
    for i in range(h.shape[0] - 1):
        for j in range(h.shape[1] - 1):
            if ok[i, j] and ok[i, j + 1] and ok[i + 1, j]:
                g2.append(((h[i, j + 1] - h[i, j]) / px) ** 2
                          + ((h[i + 1, j] - h[i, j]) / py) ** 2)
    return math.sqrt(sum(g2) / len(g2)), len(g2)


def test_unreliable_pixels_are_excluded():
    """NaN heights and pixels outside ``valid`` are not used: heights only where usable,
    gradients only where both forward neighbours are; the same as a plain loop."""
    rng = np.random.default_rng(3)
    h = rng.normal(0, 0.3, (30, 40))
    h[rng.random(h.shape) < 0.2] = np.nan
    valid = rng.random(h.shape) > 0.1
    ok = np.isfinite(h) & valid
    p = areal_parameters(h, pixel_size_um=(0.4, 0.3), reference="mean", valid=valid)
    sdq, n = _cell_loop(h, ok, 0.4, 0.3)
    assert p.n_cells == n and p.n_points == ok.sum()
    assert p.Sdq == pytest.approx(sdq, rel=1e-12)
    assert p.Sq_um == pytest.approx(np.std(h[ok]), rel=1e-12)
    huge = np.where(valid, h, 1e6)                          # excluded by `valid` alone
    assert areal_parameters(huge, pixel_size_um=(0.4, 0.3), reference="mean",
                            valid=valid) == p


def test_bad_input_names_the_parameter():
    h = np.zeros((4, 5))
    cases = [({"reference": "median"}, "reference"),
             ({"pixel_size_um": -1.0}, "pixel_size_um"),
             ({"pixel_size_um": (1.0, 0.0)}, "pixel_size_um"),
             ({"valid": np.ones((5, 4), bool)}, "valid")]
    for kw, param in cases:
        with pytest.raises(InputError) as exc:
            areal_parameters(h, **{"pixel_size_um": 1.0, **kw})
        assert exc.value.param == param
    for bad in (np.zeros(5), np.full((4, 5), np.nan), np.array([[0.0, 1.0, 2.0, 3.0]])):
        with pytest.raises(InputError) as exc:            # not 2-D, empty, on one line
            areal_parameters(bad, pixel_size_um=1.0)
        assert exc.value.param == "height_um"
    line = areal_parameters(np.array([[0.0, 1.0, 2.0, 4.0]]), pixel_size_um=1.0,
                            reference="mean")
    assert line.n_cells == 0 and math.isnan(line.Sdq) and line.Sq_um > 0


@pytest.mark.slow
def test_analysis_writes_the_iso25178_section(tmp_path):
    """The x3p fixture through the analysis: summary.json's ``iso25178`` holds the ISO
    parameters of the file's heights about their least-squares plane, SurfaceTopography's RMS
    height and gradient of the file as read (within 1 %), and the analysis' own RMS slope
    (central differences: lower than the forward differences' on this rough map)."""
    out = write_results(analyse_stack(X3P), tmp_path / "res")
    iso = json.loads((out / "summary.json").read_text())["iso25178"]
    st = read_stack(X3P)
    h = st.read_export_height()
    ref = areal_parameters(h, pixel_size_um=st.pixel_size_um)
    assert iso["standard"] == "ISO 25178-2" and iso["reference"] == "least-squares plane"
    assert iso["differences"] == "forward" and iso["n_points"] == h.size
    for key in ("Sq_um", "Sa_um", "Sdq", "Sdr_percent"):
        assert iso[key] == pytest.approx(getattr(ref, key), rel=1e-9), key
    t, scale = _surface_topography(X3P / "height.x3p", "mean")
    assert iso["rms_height_um"] == pytest.approx(t.rms_height_from_area() * scale, rel=0.01)
    assert iso["rms_gradient"] == pytest.approx(t.rms_gradient(), rel=0.01)
    gy, gx = np.gradient(np.asarray(h, np.float64), *([st.pixel_size_um] * 2))
    assert iso["rms_slope_normals"] == pytest.approx(np.sqrt(np.mean(gx ** 2 + gy ** 2)),
                                                     rel=0.01)
    assert iso["rms_slope_normals"] < 0.9 * iso["rms_gradient"]
    assert iso["plane_tilt_deg"] == pytest.approx(math.degrees(math.atan(math.hypot(
        *ref.plane_slope_yx))), rel=1e-9)


def test_plane_of_a_large_map_equals_the_direct_least_squares(monkeypatch):
    """The plane summed a block of rows at a time (normal equations, several blocks) is the
    least-squares plane that ``lstsq`` on the whole design matrix gives, and so are the
    parameters about it; points on a diagonal line have no plane."""
    from microfacet.core import threads

    monkeypatch.setattr(threads, "BLOCK_VALUES", 997)    # many blocks, a ragged last one
    rng = np.random.default_rng(5)
    yy, xx = np.mgrid[0:90, 0:70]
    h = 3.0 + 0.02 * yy - 0.05 * xx + rng.normal(0, 0.2, yy.shape)
    h[rng.random(h.shape) < 0.3] = np.nan
    ok = np.isfinite(h)
    py, px = 0.4, 0.3
    y, x = (yy[ok] - yy[ok].mean()) * py, (xx[ok] - xx[ok].mean()) * px
    coef = np.linalg.lstsq(np.column_stack([np.ones(y.size), y, x]), h[ok], rcond=None)[0]
    z = h[ok] - (coef[0] + coef[1] * y + coef[2] * x)
    p = areal_parameters(h, pixel_size_um=(py, px))
    assert p.plane_slope_yx == pytest.approx((coef[1], coef[2]), rel=1e-12)
    assert p.Sq_um == pytest.approx(math.sqrt(np.mean(z ** 2)), rel=1e-12)
    assert p.Sa_um == pytest.approx(np.mean(np.abs(z)), rel=1e-12)
    whole = areal_parameters(h, pixel_size_um=(py, px), reference="mean")
    monkeypatch.setattr(threads, "BLOCK_VALUES", 1 << 20)  # one block: the same numbers
    assert areal_parameters(h, pixel_size_um=(py, px)).Sdq == pytest.approx(p.Sdq, rel=1e-12)
    assert areal_parameters(h, pixel_size_um=(py, px), reference="mean") == whole
    far = areal_parameters(h + 3000.0, pixel_size_um=(py, px))   # a stage's offset, in µm
    assert far.plane_slope_yx == pytest.approx(p.plane_slope_yx, rel=1e-9)
    assert far.Sq_um == pytest.approx(p.Sq_um, rel=1e-9)
    diagonal = np.full((6, 6), np.nan)
    diagonal[np.arange(6), np.arange(6)] = np.arange(6.0)
    with pytest.raises(InputError, match="one line"):
        areal_parameters(diagonal, pixel_size_um=1.0)
    diagonal[0, 2] = 1.0                                  # one point off the line: a plane
    assert areal_parameters(diagonal, pixel_size_um=1.0).n_points == 7
