"""The options tree of an analysis (microfacet.analysis.options): the defaults (the seed's),
validation naming the option's dotted path, the round trip through plain dicts and JSON,
``replace``, and the scene an analysis derives from a stack. The focus section:
tests/focus/test_options.py; the command-line flags: tests/cli/."""

from __future__ import annotations

import dataclasses
import json
import math
from types import SimpleNamespace as NS

import pytest

from microfacet.analysis.options import (
    AnalysisOptions,
    FitOptions,
    JointOptions,
    MaskOptions,
    OpticsOptions,
    RoiOptions,
    TiltOptions,
    scene_of,
)
from microfacet.core.errors import InputError
from microfacet.core.options import Options, option_fields
from microfacet.focus.options import FocusOptions
from microfacet.optics.defaults import DEFAULT_FILM, DEFAULT_ILLUMINANT, DEFAULT_SUBSTRATE

SECTIONS = {"focus": FocusOptions, "mask": MaskOptions, "roi": RoiOptions,
            "joint": JointOptions, "tilt": TiltOptions, "fits": FitOptions,
            "optics": OpticsOptions}

# ------------------------------------------------------------------------- defaults


def test_defaults_are_the_seeds():
    o = AnalysisOptions()
    assert o.mode == "joint" and o.seed == 0
    assert o.roi.size_px == 255 and o.roi.stride_px is None        # seed: 255 px ROIs
    assert o.mask.saturation_min == 15.0                             # seed: HSV S < 15
    assert o.optics.delta_e_method == "CIEDE2000"                    # seed: ΔE00
    assert o.optics.thickness_range_nm == (0.0, 400.0)
    assert o.optics.film is None and o.optics.exposure is None       # the stack's, or default
    assert o.fits.max_components == 5 and o.tilt.step_deg == 1.0
    for name, cls in SECTIONS.items():
        assert getattr(o, name) == cls(), name


def test_every_option_is_documented_and_its_default_valid():
    paths = []
    for f in option_fields(AnalysisOptions):
        paths.append(f.path)
        assert f.help.strip(), f.path
        meta = f.field.metadata
        if meta.get("low") is not None and f.default is not None:
            assert f.default >= meta["low"], f.path
        if meta.get("high") is not None and f.default is not None:
            assert f.default <= meta["high"], f.path
    assert paths == list(AnalysisOptions().flat())
    assert len(paths) == len(set(paths)) and {p.split(".")[0] for p in paths if "." in p} == \
        set(SECTIONS)


def test_sections_are_frozen():
    o = AnalysisOptions()
    with pytest.raises(dataclasses.FrozenInstanceError):
        o.roi.size_px = 64
    with pytest.raises(dataclasses.FrozenInstanceError):
        o.mode = "seed"


# ------------------------------------------------------------------------- validation


@pytest.mark.parametrize("data, path, reason", [
    ({"mode": "fast"}, "mode", "must be one of joint, seed, got 'fast'"),
    ({"seed": -1}, "seed", "must be >= 0, got -1"),
    ({"mask": {"saturation_min": 300}}, "mask.saturation_min", "must be <= 255, got 300"),
    ({"mask": {"steep_ratio": -0.1}}, "mask.steep_ratio", "must be >= 0"),
    ({"roi": {"size_px": 4}}, "roi.size_px", "must be >= 8, got 4"),
    ({"roi": {"size_px": 64, "stride_px": 65}}, "roi.stride_px",
     "must be in [1, roi.size_px], got 65"),
    ({"joint": {"facet_size_um": 0}}, "joint.facet_size_um", "must be > 0, got 0"),
    ({"joint": {"merge_alpha": 0.9}}, "joint.merge_alpha", "must be <= 0.5"),
    ({"tilt": {"step_deg": 10}}, "tilt.step_deg", "must be <= 5, got 10"),
    ({"tilt": {"step_deg": math.nan}}, "tilt.step_deg", "must be a finite number, got nan"),
    ({"fits": {"max_components": 11}}, "fits.max_components", "must be <= 10, got 11"),
    ({"fits": {"max_components": True}}, "fits.max_components", "must be a finite number"),
    ({"fits": {"max_width_error": "0.2"}}, "fits.max_width_error", "must be a finite number"),
    ({"fits": {"thickness_max_sd_nm": 0.05}}, "fits.thickness_max_sd_nm",
     "must be > fits.thickness_sd_floor_nm (0.1), got 0.05"),
    ({"optics": {"delta_e_method": "CMC"}}, "optics.delta_e_method",
     "must be one of CIEDE2000, CIE94, CIE76, got 'CMC'"),
    ({"optics": {"thickness_range_nm": [300, 100]}}, "optics.thickness_range_nm",
     "need 0 <= low < high <= 2000, got 300:100"),
    ({"optics": {"thickness_range_nm": "thin"}}, "optics.thickness_range_nm",
     "expected (low, high) in nm"),
    ({"optics": {"film": "TiO2_nowhere"}}, "optics.film", "unknown optical-constant set"),
    ({"optics": {"exposure": 0}}, "optics.exposure", "must be > 0, got 0"),
    ({"roi": {"size_px": None}}, "roi.size_px", "must be given, got None"),
])
def test_a_bad_value_names_its_dotted_path(data, path, reason):
    with pytest.raises(InputError) as err:
        AnalysisOptions.from_dict(data)
    assert err.value.param == path
    assert str(err.value).startswith(f"{path}: ") and reason in str(err.value)
    assert "\n" not in str(err.value)


def test_unknown_options_are_named_with_the_known_ones():
    with pytest.raises(InputError, match=r"^roi: unknown option\(s\) size, step; known: "
                                         r"size_px, stride_px") as err:
        AnalysisOptions.from_dict({"roi": {"size": 64, "step": 2}})
    assert err.value.param == "roi"
    with pytest.raises(InputError, match=r"^unknown option\(s\) colour; known: mode, seed"):
        AnalysisOptions.from_dict({"colour": {}})


def test_a_section_alone_names_its_field():
    with pytest.raises(InputError, match=r"^size_px: must be >= 8, got 4$"):
        RoiOptions(size_px=4)
    with pytest.raises(InputError, match="stride_px"):
        RoiOptions(size_px=16, stride_px=32)
    assert RoiOptions(size_px=16, stride_px=16).stride_px == 16


def test_a_section_that_is_not_a_mapping_is_refused():
    with pytest.raises(InputError, match="roi"):
        AnalysisOptions.from_dict({"roi": 5})


def test_a_whole_number_option_refuses_a_fraction():
    with pytest.raises(InputError, match="roi.size_px: must be a whole number"):
        AnalysisOptions.from_dict({"roi": {"size_px": 12.5}})
    assert AnalysisOptions.from_dict({"roi": {"size_px": 128}}).roi.size_px == 128


# ------------------------------------------------------------------------- round trip


def _custom():
    return AnalysisOptions(
        mode="seed", seed=7, focus=FocusOptions(window_px=9),
        mask=MaskOptions(saturation_min=20.0, shadow_ratio=0.0),
        roi=RoiOptions(size_px=128, stride_px=64), joint=JointOptions(facet_size_um=3.5),
        tilt=TiltOptions(step_deg=1.0, coarse_stride=2), fits=FitOptions(max_components=3),
        optics=OpticsOptions(film=DEFAULT_FILM, exposure=0.9, thickness_range_nm=(20.0, 300.0),
                             delta_e_method="CIE94"))


def test_to_dict_from_dict_round_trip_through_json():
    o = _custom()
    d = o.to_dict()
    assert d["roi"] == {**RoiOptions().to_dict(), "size_px": 128, "stride_px": 64}
    assert d["optics"]["thickness_range_nm"] == [20.0, 300.0]          # plain JSON values
    back = AnalysisOptions.from_dict(json.loads(json.dumps(d, allow_nan=False)))
    assert back == o and back.optics.thickness_range_nm == (20.0, 300.0)
    assert AnalysisOptions.from_dict(AnalysisOptions().to_dict()) == AnalysisOptions()
    # absent keys take their defaults, section by section
    part = AnalysisOptions.from_dict({"roi": {"size_px": 128}})
    assert part.roi == RoiOptions(size_px=128) and part.mask == MaskOptions()
    assert AnalysisOptions.from_dict(None) == AnalysisOptions()


def test_flat_lists_every_leaf_by_its_path():
    flat = _custom().flat()
    assert flat["roi.size_px"] == 128 and flat["optics.delta_e_method"] == "CIE94"
    assert flat["focus.window_px"] == 9 and flat["mode"] == "seed"
    assert not any(isinstance(v, dict) for v in flat.values())


# ------------------------------------------------------------------------- replace


def test_replace_changes_only_what_is_given():
    o = AnalysisOptions()
    r = o.replace(mode="seed", roi={"size_px": 128}, fits=FitOptions(max_components=2))
    assert (r.mode, r.roi.size_px, r.fits.max_components) == ("seed", 128, 2)
    assert r.roi.replace(size_px=255) == o.roi and r.mask == o.mask and r.optics == o.optics
    assert o == AnalysisOptions()                                      # the original stays
    assert isinstance(r, AnalysisOptions) and isinstance(r.roi, RoiOptions)


def test_replace_validates():
    with pytest.raises(InputError, match="must be >= 8"):
        AnalysisOptions().replace(roi={"size_px": 4})
    with pytest.raises(InputError, match="mode: must be one of"):
        AnalysisOptions().replace(mode="fast")
    with pytest.raises(InputError, match="stride_px"):
        RoiOptions(size_px=64).replace(stride_px=128)


def test_replace_in_a_section_names_the_dotted_path():
    with pytest.raises(InputError) as err:
        AnalysisOptions().replace(roi={"size_px": 4})
    assert err.value.param == "roi.size_px"


def test_replace_of_an_unknown_option_is_an_input_error():
    with pytest.raises(InputError, match="size"):
        RoiOptions().replace(size=64)


# ------------------------------------------------------------------------- the scene


def _stack(**kw):
    base = dict(film=None, substrate=None, illuminant=None, exposure=None,
                numerical_aperture=0.8, pixel_size_yx_um=(0.2, 0.25), has_slices=True)
    return NS(**(base | kw))


def test_the_scene_takes_the_options_then_the_stack_then_the_defaults():
    s = scene_of(_stack(), AnalysisOptions(seed=3))
    assert (s.film, s.substrate, s.illuminant) == (DEFAULT_FILM, DEFAULT_SUBSTRATE,
                                                   DEFAULT_ILLUMINANT)
    assert s.exposure is None and s.exposure_source == "estimated" and s.estimate_exposure
    assert s.max_tilt_deg == pytest.approx(math.degrees(math.asin(0.8)) / 2)   # asin(NA)/2
    assert s.pixel_size_um == (0.2, 0.25) and s.from_focus and s.seed == 3
    assert s.optics_json() == {"film": DEFAULT_FILM, "substrate": DEFAULT_SUBSTRATE,
                               "illuminant": DEFAULT_ILLUMINANT, "numerical_aperture": 0.8}
    st = _stack(film="TiO2_Franta2015_amorphous", illuminant="D50", exposure=1.2)
    s = scene_of(st, AnalysisOptions())
    assert (s.film, s.illuminant, s.exposure, s.exposure_source) == (
        "TiO2_Franta2015_amorphous", "D50", 1.2, "stack.json")
    s = scene_of(st, AnalysisOptions(optics=OpticsOptions(film=DEFAULT_FILM, exposure=0.7)))
    assert (s.film, s.illuminant, s.exposure, s.exposure_source) == (
        DEFAULT_FILM, "D50", 0.7, "option")
    assert not s.estimate_exposure
    assert not scene_of(_stack(has_slices=False), AnalysisOptions()).from_focus


def test_an_unknown_film_in_the_stack_names_the_option():
    with pytest.raises(InputError, match="unknown optical-constant set 'TiO2_nowhere'") as err:
        scene_of(_stack(film="TiO2_nowhere"), AnalysisOptions())
    assert err.value.param == "optics.film"


def test_options_are_the_core_options_type():
    assert all(issubclass(c, Options) for c in (AnalysisOptions, *SECTIONS.values()))
