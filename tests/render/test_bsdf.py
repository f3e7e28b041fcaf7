"""The Mitsuba thin-film BSDF (microfacet.render.bsdf) against the package's own BRDF: eval,
reciprocity, sampling against pdf (χ²), the white furnace, and a rendered flat plate against
``simulate``'s angular map."""

import math

import numpy as np
import pytest

mi = pytest.importorskip("mitsuba")
dr = pytest.importorskip("drjit")

from microfacet.colour.colorimetry import xyz_to_lab  # noqa: E402
from microfacet.colour.difference import delta_e_2000  # noqa: E402
from microfacet.colour.srgb import linear_srgb_to_xyz  # noqa: E402
from microfacet.core.distributions import NDFMixture, ThicknessMixture  # noqa: E402
from microfacet.core.errors import InputError  # noqa: E402
from microfacet.forward.angular import simulate_map  # noqa: E402
from microfacet.forward.brdf import microfacet_geometry  # noqa: E402
from microfacet.forward.material import Material  # noqa: E402
from microfacet.render import bsdf  # noqa: E402
from microfacet.render.scene import gonio_scene  # noqa: E402

SCALAR = "scalar_spectral"
THICKNESS = ThicknessMixture([(0.6, 112.0, 3.0), (0.4, 150.0, 5.0)])
NDF = NDFMixture([(0.7, 6.0), (0.3, 20.0)])


def _llvm():
    from microfacet.render.variants import available_variants
    return "llvm_ad_spectral" if "llvm_ad_spectral" in available_variants() else None


@pytest.fixture(scope="module")
def material_file(tmp_path_factory):
    path = tmp_path_factory.mktemp("mat") / "material.npz"
    Material.build(thickness=THICKNESS, ndf=NDF, theta_step_deg=0.5,
                   wavelength_step_nm=2.0).write(path)
    return path


@pytest.fixture(scope="module")
def unit_film_file(tmp_path_factory):
    """A film that reflects everything: the furnace test's material."""
    m = Material.build(thickness=100.0, ndf=NDFMixture([(0.5, 8.0), (0.5, 25.0)]),
                       theta_step_deg=5.0, wavelength_step_nm=10.0)
    path = tmp_path_factory.mktemp("unit") / "unit.npz"
    Material(m.ndf, np.ones_like(m.film_average), m.theta_d_deg, m.wavelength_nm,
             m.thickness).write(path)
    return path


def _load(path, variant=SCALAR):
    mi.set_variant(variant)
    bsdf.register()
    return mi.load_dict({"type": bsdf.PLUGIN, "filename": str(path)})


def _hemisphere(rng, n):
    v = rng.normal(size=(n, 3))
    v[:, 2] = np.abs(v[:, 2])
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def _si(wi, wavelengths):
    si = dr.zeros(mi.SurfaceInteraction3f)
    si.wi = mi.Vector3f(*map(float, wi))
    si.wavelengths = mi.Spectrum(*map(float, wavelengths))
    return si


def _eval(b, wi, wo, wavelengths):
    ctx = mi.BSDFContext()
    v = b.eval(ctx, _si(wi, wavelengths), mi.Vector3f(*map(float, wo)))
    return np.array([v[k] for k in range(4)])


def test_eval_equals_the_packages_brdf(material_file):
    """eval / cos θ_o is Material.brdf (which the forward tests tie to microfacet_brdf) to
    1e-4 relative, on random directions and wavelengths (nodes and between them)."""
    b = _load(material_file)
    m = Material.read(material_file)
    rng = np.random.default_rng(0)
    wi, wo = _hemisphere(rng, 200), _hemisphere(rng, 200)
    wl = rng.uniform(365.0, 820.0, size=(200, 4))
    wl[:100] = 2 * np.round(wl[:100] / 2)  # grid nodes
    got = np.array([_eval(b, wi[i], wo[i], wl[i]) / wo[i, 2] for i in range(200)])
    ref = np.stack([m.brdf(wi[i], wo[i], wavelength_nm=wl[i]) for i in range(200)])
    big = ref > 1e-6 * ref.max()  # float32 underflow far off the lobes
    assert big.mean() > 0.8
    np.testing.assert_allclose(got[big], ref[big], rtol=1e-4)
    assert np.all(np.abs(got[~big]) <= 1e-6 * ref.max())


def test_eval_is_reciprocal(material_file):
    b = _load(material_file)
    rng = np.random.default_rng(1)
    wi, wo = _hemisphere(rng, 100), _hemisphere(rng, 100)
    wl = (450.0, 520.0, 600.0, 700.0)
    for i in range(100):
        f_io = _eval(b, wi[i], wo[i], wl) / wo[i, 2]
        f_oi = _eval(b, wo[i], wi[i], wl) / wi[i, 2]
        np.testing.assert_allclose(f_io, f_oi, rtol=2e-5, atol=1e-12)


def test_below_the_horizon_is_black_and_finite(material_file):
    b = _load(material_file)
    wl = (450.0, 520.0, 600.0, 700.0)
    for wi, wo in (([0, 0, 1], [0.6, 0, -0.8]), ([0.6, 0, -0.8], [0, 0, 1]),
                   ([1, 0, 0], [0, 0, 1]), ([0, 0, 1], [-1, 0, 0])):
        assert np.all(_eval(b, wi, wo, wl) == 0)
    ctx = mi.BSDFContext()
    bs, w = b.sample(ctx, _si([0.0, 0.0, -1.0], wl), 0.5, mi.Point2f(0.3, 0.6))
    assert bs.pdf == 0 and all(w[k] == 0 for k in range(4))


def test_sample_weight_and_pdf_agree_with_eval(material_file):
    """Each sample's weight is eval / pdf and its pdf is pdf(wo), at any incidence."""
    b = _load(material_file)
    ctx = mi.BSDFContext()
    rng = np.random.default_rng(2)
    wl = (430.0, 510.0, 590.0, 680.0)
    n_valid = 0
    for wi in _hemisphere(rng, 60):
        si = _si(wi, wl)
        bs, w = b.sample(ctx, si, float(rng.random()), mi.Point2f(*rng.random(2)))
        if bs.pdf == 0:
            continue
        n_valid += 1
        f = b.eval(ctx, si, bs.wo)
        assert b.pdf(ctx, si, bs.wo) == pytest.approx(bs.pdf, rel=1e-4)
        for k in range(4):
            assert w[k] == pytest.approx(f[k] / bs.pdf, rel=1e-4)
        value, pdf = b.eval_pdf(ctx, si, bs.wo)
        assert pdf == pytest.approx(bs.pdf, rel=1e-4) and value[0] == pytest.approx(f[0])
    assert n_valid > 40


def _numerical_albedo(ndf, wi, n=1000):
    """∫ D G₂ / (4 cos θ_i cos θ_o) cos θ_o dω_o by the midpoint rule (numpy, independent of
    Mitsuba): the directional albedo of a film reflecting everything."""
    th = (np.arange(n) + 0.5) * (math.pi / 2 / n)
    ph = (np.arange(2 * n) + 0.5) * (math.pi / n)
    t, p = np.meshgrid(th, ph, indexing="ij")
    wo = np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)], axis=-1)
    geom, _ = microfacet_geometry(np.asarray(wi, float), wo, ndf)
    dw = np.sin(t) * (math.pi / 2 / n) * (math.pi / n)
    return float(np.sum(geom * np.cos(t) * dw))


@pytest.mark.slow
@pytest.mark.parametrize("cos_i", [1.0, 0.5, 0.15])
def test_white_furnace_with_a_unit_film(unit_film_file, cos_i):
    """With ⟨R⟩ ≡ 1 the sampled albedo is ≤ 1 and equals the single-scattering albedo of the
    lobes' D and Smith G₂ integrated independently: the Smith loss is what it should be."""
    b = _load(unit_film_file)
    m = Material.read(unit_film_file)
    wi = np.array([math.sqrt(1 - cos_i ** 2), 0.0, cos_i])
    expected = _numerical_albedo(m.ndf, wi)
    ctx = mi.BSDFContext()
    si = _si(wi, (450.0, 520.0, 600.0, 700.0))
    rng = np.random.default_rng(3)
    n = 6000
    s1, s2 = rng.random(n), rng.random((n, 2))
    w = np.array([b.sample(ctx, si, float(s1[i]), mi.Point2f(*s2[i]))[1][0] for i in range(n)])
    mean, se = w.mean(), w.std() / math.sqrt(n)
    assert expected <= 1.0
    assert mean <= 1.0 + 3 * se
    assert abs(mean - expected) < max(4 * se, 2e-3), (mean, se, expected)
    # the single-scattering (Smith) loss grows towards grazing incidence
    assert expected < _numerical_albedo(m.ndf, [0.0, 0.0, 1.0]) + 1e-9


@pytest.mark.slow
def test_sampling_passes_chi_square_in_the_jit_variant(material_file):
    """Mitsuba's own χ² test of the sampled directions against pdf (1e5 samples, three
    incidences down to 73°)."""
    variant = _llvm()
    if variant is None:
        pytest.skip("no JIT spectral variant loads here")
    _load(material_file, variant)
    from mitsuba.chi2 import BSDFAdapter, ChiSquareTest, SphericalDomain
    spec = {"type": bsdf.PLUGIN, "filename": str(material_file)}
    for wi in ([0.0, 0.0, 1.0], [0.6, 0.0, 0.8], [0.95, 0.1, 0.2958]):
        wi = np.asarray(wi) / np.linalg.norm(wi)
        sample, pdf = BSDFAdapter(bsdf.PLUGIN, spec, wi=mi.Vector3f(*map(float, wi)))
        test = ChiSquareTest(domain=SphericalDomain(), sample_func=sample, pdf_func=pdf,
                             sample_dim=3, sample_count=100_000)
        assert test.run(), test.messages


def test_a_missing_filename_is_named(tmp_path):
    mi.set_variant(SCALAR)
    bsdf.register()
    with pytest.raises(Exception, match="filename"):
        mi.load_dict({"type": bsdf.PLUGIN})
    with pytest.raises(Exception, match="no such file"):
        mi.load_dict({"type": bsdf.PLUGIN, "filename": str(tmp_path / "none.npz")})


def test_a_results_folder_gives_the_material_of_its_export(tmp_path):
    """``results`` instead of ``filename``: the plugin tabulates the analysis' material
    itself, and evaluates as the exported file does."""
    import json
    folder = tmp_path / "analysis"
    folder.mkdir()
    (folder / "summary.json").write_text(json.dumps({
        "format": "microfacet-results/1", "thickness": {"mixture": THICKNESS.to_json()},
        "ndf": {"mixture": NDF.to_json()}}))
    exported = tmp_path / "exported.npz"
    Material.from_results(folder).write(exported)
    a = _load(exported)
    mi.set_variant(SCALAR)
    b = mi.load_dict({"type": bsdf.PLUGIN, "results": str(folder)})
    wl = (450.0, 520.0, 600.0, 700.0)
    for wi, wo in (([0.1, 0.2, 0.97], [-0.2, 0.1, 0.97]), ([0.5, 0.0, 0.87], [-0.4, 0.1, 0.9])):
        np.testing.assert_allclose(_eval(b, wi, wo, wl), _eval(a, wi, wo, wl), rtol=1e-6)


def test_rgb_variants_are_refused():
    with pytest.raises(InputError, match="spectral"):
        bsdf.check_variant("scalar_rgb")


# --------------------------------------------------------------- a plate in a renderer
def _plate_scene(bsdf_spec, theta_light_deg, theta_view_deg, variant):
    mi.set_variant(variant)
    bsdf.register()
    return mi.load_dict(gonio_scene(bsdf=bsdf_spec, theta_light_deg=theta_light_deg,
                                    theta_view_deg=theta_view_deg))


def _mean_xyz(scene):
    rgb = np.asarray(mi.render(scene), dtype=np.float64).reshape(-1, 3).mean(axis=0)
    return linear_srgb_to_xyz(rgb)


@pytest.mark.slow
def test_a_rendered_plate_reproduces_simulate(material_file):
    """A flat plate under a D65 directional light seen at simulate's angles (in the plane of
    incidence) has simulate's microfacet colours within ΔE00 1: XYZ relative to a white
    Lambertian plate rendered the same way is that of π f_r."""
    variant = _llvm() or SCALAR
    m = Material.read(material_file)
    angles = [(0.0, 10.0), (30.0, 30.0), (45.0, 20.0), (60.0, 65.0)]
    spec = {"type": bsdf.PLUGIN, "filename": str(material_file)}
    white = {"type": "diffuse", "reflectance": 1.0}
    for tl, tv in angles:
        ref = simulate_map(model="microfacet", thickness=m.thickness, ndf=m.ndf,
                           theta_light_deg=[tl], theta_view_deg=[tv])
        xyz = _mean_xyz(_plate_scene(spec, tl, tv, variant))
        y_white = _mean_xyz(_plate_scene(white, tl, tv, variant))[1]
        lab = xyz_to_lab(xyz / y_white)
        de = float(delta_e_2000(lab, ref.lab[0, 0]))
        assert de <= 1.0, (tl, tv, de, lab, ref.lab[0, 0])
