"""microfacet.render.variants: the variant chosen renders; unknown, unsuitable or missing
variants are refused naming ``variant``; the probes run once per process; an LLVM variant
that aborts with an old libLLVM falls back to a newer one, and when none works the scalar
variant comes with a one-line reason (both in a fresh process, with an old libLLVM forced).
"""

from __future__ import annotations

import importlib.util
import json
import os
import subprocess
import sys

import numpy as np
import pytest

mi = pytest.importorskip("mitsuba")

from microfacet.core.errors import InputError  # noqa: E402
from microfacet.render import variants  # noqa: E402
from microfacet.render.variants import (  # noqa: E402
    available_variants,
    choose_variant,
    find_libllvm,
    libllvm_major,
    variant_probes,
)


def test_the_chosen_variant_renders():
    v, note = choose_variant()
    assert v in available_variants() and v.endswith("_spectral")
    assert (note is None) == (not v.startswith("scalar"))
    mi.set_variant(v)
    scene = mi.load_dict({
        "type": "scene", "integrator": {"type": "path"},
        "ball": {"type": "sphere", "bsdf": {"type": "diffuse", "reflectance": 1.0}},
        "sky": {"type": "constant", "radiance": {"type": "d65", "scale": 1.0}},
        "cam": {"type": "perspective", "fov": 10.0, "film": {"type": "hdrfilm", "width": 4,
                                                           "height": 4},
                "to_world": mi.ScalarTransform4f().look_at(origin=[0, 0, 5], target=[0, 0, 0],
                                                           up=[0, 1, 0])}})
    img = np.array(mi.render(scene, spp=64))
    # a white sphere in a uniform unit sky is as bright as the sky (a furnace): Y ≈ 1
    assert np.isfinite(img).all() and np.mean(img) == pytest.approx(1.0, rel=0.05)


@pytest.mark.parametrize("name", ["no_such_variant", "scalar_rgb",
                                  "llvm_ad_spectral_polarized"])
def test_unknown_or_unsuitable_variants_are_refused_naming_variant(name):
    with pytest.raises(InputError) as e:
        choose_variant(name)
    assert e.value.param == "variant" and name in str(e.value)
    assert "\n" not in str(e.value)


def test_an_available_variant_can_be_requested():
    v = available_variants()[-1]
    assert choose_variant(v)[0] == v


def test_probes_run_once_per_process(monkeypatch):
    first = variant_probes()
    assert first and all(p.seconds > 0 for p in first)

    def no_child(*a, **k):
        raise AssertionError("probed again")

    monkeypatch.setattr(subprocess, "Popen", no_child)
    assert variant_probes() is first
    assert available_variants() == tuple(p.variant for p in first if p.works)
    assert choose_variant()[0] == available_variants()[0]


def test_without_mitsuba_the_message_says_what_to_install(monkeypatch):
    real = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec",
                        lambda name, *a: None if name == "mitsuba" else real(name, *a))
    with pytest.raises(InputError) as e:
        choose_variant()
    assert e.value.param == "variant" and 'pip install "microfacet[render]"' in str(e.value)


def _old_libllvm():
    """A libLLVM older than 16 on this machine (Dr.Jit's kernels abort or refuse it)."""
    old = [p for p in find_libllvm() if (libllvm_major(p) or 99) < 16]
    if not old:
        pytest.skip("no libLLVM older than 16 here to force")
    return old[0]


def _child(code: str, libllvm: str) -> dict:
    env = {**os.environ, "DRJIT_LIBLLVM_PATH": libllvm}
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True,
                         timeout=300, check=True).stdout
    return json.loads(out.strip().splitlines()[-1])


@pytest.mark.slow
@pytest.mark.subprocess
def test_an_old_libllvm_falls_back_to_a_newer_one_before_mitsuba_loads():
    if "llvm_ad_spectral" not in available_variants():
        pytest.skip("no working LLVM variant here")
    old = _old_libllvm()
    code = """if True:
        import json, os
        from microfacet.render.variants import choose_variant
        v, note = choose_variant()
        import mitsuba as mi
        mi.set_variant(v)
        img = mi.render(mi.load_dict({"type": "scene", "integrator": {"type": "path"},
            "ball": {"type": "sphere"}, "sky": {"type": "constant"},
            "cam": {"type": "perspective", "film": {"type": "hdrfilm", "width": 4,
                                                    "height": 4},
                    "to_world": mi.ScalarTransform4f().translate([0, 0, -5])}}), spp=4)
        lib = next(l.split()[-1] for l in open("/proc/self/maps") if "libLLVM" in l)
        print(json.dumps({"variant": v, "note": note, "env": os.environ["DRJIT_LIBLLVM_PATH"],
                          "loaded": os.path.realpath(lib), "mean": float(img.numpy().mean())}))
    """
    r = _child(code, old)
    assert r["variant"] == "llvm_ad_spectral" and r["note"] is None
    assert r["env"] != old and r["loaded"] == os.path.realpath(r["env"]) and r["mean"] > 0
    assert libllvm_major(r["env"]) > libllvm_major(old)


@pytest.mark.slow
@pytest.mark.subprocess
def test_with_only_an_old_libllvm_scalar_comes_with_the_reason():
    old = _old_libllvm()
    code = f"""if True:
        import json
        import microfacet.render.variants as V
        V.find_libllvm = lambda: [{old!r}]             # hide the newer ones
        v, note = V.choose_variant()
        try:
            V.choose_variant("llvm_ad_spectral")
            refused = None
        except V.InputError as exc:
            refused = exc.param
        print(json.dumps({{"variant": v, "note": note, "refused": refused}}))
    """
    r = _child(code, old)
    assert r["variant"] == "scalar_spectral" and r["refused"] == "variant"
    note = r["note"]
    assert "\n" not in note and "llvm_ad_spectral unavailable" in note
    assert f"libLLVM {libllvm_major(old)}" in note and "using scalar_spectral" in note


def test_libllvm_candidates_are_newest_first():
    majors = [libllvm_major(p) or -1 for p in find_libllvm()]
    assert majors == sorted(majors, reverse=True)
    assert variants.PROBE_TIMEOUT_S >= 10
