"""``summary.json`` as a typed, versioned Summary (microfacet.io.summary): the round trip
through JSON, the reading of version-1 summaries, and hostile summaries refused in one line
naming the file and the key. Results folders that hold them: test_results.py; what the
analysis writes: tests/analysis/test_output.py."""

from __future__ import annotations

import json
import math
import time

import pytest

from microfacet.analysis.options import AnalysisOptions
from microfacet.core.errors import InputError
from microfacet.io.results import Results
from microfacet.io.summary import (
    FORMAT,
    MAX_COMPONENTS,
    MAX_ITEMS,
    SUMMARY_VERSION,
    V1_PARAMETERS,
    DeltaE,
    FacetCounts,
    Inputs,
    Iso25178Section,
    NdfSection,
    RoiCounts,
    Summary,
    ThicknessSection,
)

THICKNESS = {"components": [{"weight": 0.4, "mean_nm": 112.0, "sd_nm": 3.0},
                            {"weight": 0.6, "mean_nm": 130.0, "sd_nm": 2.5}],
             "bic": 12.5, "identified": True, "reason": "", "reason_code": None,
             "reason_parameter": None}
NDF = {"form": "gaussian-slope", "components": [{"weight": 1.0, "mean_deg": 0.0,
                                                 "sd_deg": 6.0}], "bic": -3.0}


def _summary():
    return Summary(
        created="2026-01-01T00:00:00+00:00", mode="joint",
        inputs=Inputs(stack="/data/s1", shape=[256, 320], n_slices=20,
                      pixel_size_um=[0.2, 0.25], z_um_range=[-5.0, 4.5],
                      height_source="focus stack", film="TiO2_x", substrate="Ti_y",
                      illuminant="D65", numerical_aperture=0.8),
        parameters=AnalysisOptions().to_dict(), versions={"microfacet": "0.1.0"},
        thickness=ThicknessSection(dict(THICKNESS), RoiCounts(4, 3, 125.0, 1, 1.0)),
        ndf=NdfSection(True, "", None, None, dict(NDF), 26.57, 1.5, "per-pixel tilt"),
        facets=FacetCounts(120, 35.0, 110, 0.93, 0.02), exposure=0.91,
        exposure_source="estimated", delta_e=DeltaE(1.2, 1.0, 3.4, 0.8, 0.77),
        masked_fraction=0.04, mask={"any": 0.04}, colour_noise_de=0.5,
        tilt_information={"colour_weight_mean": 0.1}, height={"unreliable_fraction": 0.03},
        iso25178=Iso25178Section(reference="least-squares plane", differences="forward",
                                 n_points=81000, Sq_um=0.41, Sa_um=0.33, Sdq=0.12,
                                 Sdr_percent=0.71, plane_tilt_deg=1.2, rms_height_um=0.6,
                                 rms_gradient=0.125, rms_slope_normals=0.09),
        colour_table={"spectral_step_nm": 5.0},
        warnings=["1 of 4 ROIs have an ambiguous interference order"],
        timings_s={"normals": 0.1, "total": 9.5})


# ------------------------------------------------------------------------- round trip


def test_a_summary_survives_strict_json_unchanged():
    s = _summary()
    text = json.dumps(s.to_json(), allow_nan=False)       # strict JSON: no NaN, no inf
    back = Summary.from_json(json.loads(text))
    assert back == s
    assert back.to_json() == s.to_json()
    assert back.format == FORMAT and back.summary_version == SUMMARY_VERSION == 2
    assert isinstance(back.inputs, Inputs) and isinstance(back.facets, FacetCounts)
    assert isinstance(back.iso25178, Iso25178Section) and back.iso25178.Sdr_percent == 0.71
    assert AnalysisOptions.from_dict(back.parameters) == AnalysisOptions()


def test_non_finite_numbers_are_written_as_null_and_read_as_none():
    s = _summary()
    s.exposure, s.delta_e.mean, s.masked_fraction = math.nan, math.inf, -math.inf
    js = s.to_json()
    assert js["exposure"] is None and js["delta_e"]["mean"] is None
    back = Summary.from_json(json.loads(json.dumps(js, allow_nan=False)))
    assert back.exposure is None and back.delta_e.mean is None and back.masked_fraction is None


def test_keys_of_a_newer_writer_are_kept_but_not_used():
    js = {**_summary().to_json(), "future_section": {"x": [1, 2]}}
    back = Summary.from_json(js)
    assert back.extra == {"future_section": {"x": [1, 2]}}
    assert back.to_json() == js


def test_an_empty_summary_takes_the_defaults():
    s = Summary.from_json({"summary_version": SUMMARY_VERSION})
    assert s == Summary() and s.facets is None and s.iso25178 is None   # an older writer's
    assert Summary.from_json({}).summary_version == 1          # no version: version 1


# ------------------------------------------------------------------------- version 1


def _v1():
    """A summary as version 1 wrote it: the optics repeated at the top level, ``identified``
    and ``reason`` inside ``ndf.mixture`` too, flat parameters, no ``summary_version``."""
    return {
        "format": FORMAT, "mode": "seed",
        "film": "TiO2_x", "substrate": "Ti_y", "illuminant": "D50",
        "inputs": {"stack": "/data/s1", "shape": [64, 64], "n_slices": 5,
                   "numerical_aperture": 0.8},
        "parameters": {"roi_size_px": 128, "roi_stride_px": None, "delta_e_method": "CIE76",
                       "tilt_step_deg": 1.0, "thickness_range_nm": [20.0, 300.0],
                       "operator": "sml", "mode": "seed"},
        "thickness": {"mixture": dict(THICKNESS)},
        "ndf": {"identified": False, "reason": "no height",
                "mixture": {**NDF, "identified": False, "reason": "no height"}},
        "exposure": 1.0, "warnings": ["NDF not identified: no height"]}


def test_a_version_1_summary_is_read_in_the_version_2_layout():
    s = Summary.from_json(_v1())
    assert s.summary_version == 1                     # where it came from
    assert (s.inputs.film, s.inputs.substrate, s.inputs.illuminant) == ("TiO2_x", "Ti_y",
                                                                        "D50")
    js = s.to_json()
    assert not {"film", "substrate", "illuminant"} & set(js) and not s.extra
    assert s.ndf.identified is False and s.ndf.reason == "no height"
    assert "identified" not in s.ndf.mixture and "reason" not in s.ndf.mixture
    assert s.ndf.mixture["components"] == NDF["components"]
    assert s.thickness.mixture == THICKNESS and s.warnings == _v1()["warnings"]
    # the flat parameters are the options tree
    assert s.parameters == {"roi": {"size_px": 128, "stride_px": None},
                            "optics": {"delta_e_method": "CIE76",
                                       "thickness_range_nm": [20.0, 300.0]},
                            "tilt": {"step_deg": 1.0}, "focus": {"operator": "sml"},
                            "mode": "seed"}
    o = AnalysisOptions.from_dict(s.parameters)
    assert o.roi.size_px == 128 and o.optics.thickness_range_nm == (20.0, 300.0)


def test_version_1_optics_in_the_inputs_are_not_overwritten():
    v1 = _v1()
    v1["inputs"]["film"] = "TiO2_x"
    assert Summary.from_json(v1).inputs.film == "TiO2_x"


def test_every_version_1_parameter_is_an_option_of_the_tree():
    paths = set(AnalysisOptions().flat())
    assert set(V1_PARAMETERS.values()) <= paths
    flat = {k: AnalysisOptions().flat()[p] for k, p in V1_PARAMETERS.items()}
    nested = Summary.from_json({"parameters": json.loads(json.dumps(flat))}).parameters
    assert AnalysisOptions.from_dict(nested) == AnalysisOptions()


# ------------------------------------------------------------------------- hostile summaries


def _component(i=0):
    return {"weight": 1.0, "mean_nm": 100.0 + i, "sd_nm": 2.0}


HOSTILE = [
    ({"thickness": {"mixture": {"components": [_component()] * 10 ** 6}}},
     r"key 'thickness\.mixture\.components': 1000000 components, more than 10"),
    ({"ndf": {"mixture": {"components": [_component()] * (MAX_COMPONENTS + 1)}}},
     r"key 'ndf\.mixture\.components': 11 components"),
    ({"thickness": {"mixture": {"components": [{**_component(), "weight": math.nan}]}}},
     r"key 'thickness\.mixture\.components\[0\]\.weight': expected a finite number, got nan"),
    ({"ndf": {"mixture": {"components": [_component(), {"sd_deg": math.inf}]}}},
     r"key 'ndf\.mixture\.components\[1\]\.sd_deg': expected a finite number"),
    ({"thickness": {"mixture": {"components": [_component(), "x"]}}},
     r"key 'thickness\.mixture\.components\[1\]': expected an object, got 'x'"),
    ({"thickness": {"mixture": {"components": {"weight": 1}}}},
     r"key 'thickness\.mixture\.components': expected a list"),
    ({"thickness": {"mixture": None}}, r"key 'thickness\.mixture': expected an object"),
    ({"exposure": "bright"}, r"key 'exposure': expected a number, got 'bright'"),
    ({"masked_fraction": True}, r"key 'masked_fraction': expected a number, got True"),
    ({"inputs": {"n_slices": 2.5}}, r"key 'inputs\.n_slices': expected an integer"),
    ({"inputs": {"n_slices": 10 ** 30}}, r"key 'inputs\.n_slices': expected an integer"),
    ({"inputs": []}, r"key 'inputs': expected an object, got \[\]"),
    ({"ndf": {"identified": "yes"}}, r"key 'ndf\.identified': expected true or false"),
    ({"summary_version": "2"}, r"key 'summary_version': expected an integer, got '2'"),
    ({"mode": ["joint"]}, r"key 'mode': expected a string"),
    ({"iso25178": {"Sq_um": "0.4 µm"}}, r"key 'iso25178\.Sq_um': expected a number"),
    ({"iso25178": {"n_points": 1.5}}, r"key 'iso25178\.n_points': expected an integer"),
    ({"warnings": "check the film"}, r"key 'warnings': expected a list"),
    ({"warnings": ["w"] * (MAX_ITEMS + 1)}, r"key 'warnings': 1001 items, more than 1000"),
    ({"parameters": {str(i): i for i in range(10 ** 5)}},
     r"key 'parameters': 100000 items, more than 1000"),
    ({"delta_e": {"median": "x" * 1000}}, r"key 'delta_e\.median': expected a number, got "
                                          r"'x{36}\.\.\.$"),   # shortened
    ({"format": "microfacet-height/1"}, r"key 'format': 'microfacet-height/1' is not"),
]


@pytest.mark.parametrize("data, match", HOSTILE, ids=[m.split("'")[1] if "'" in m else m
                                                       for _, m in HOSTILE])
def test_hostile_summaries_are_refused_in_one_line_naming_the_file_and_key(data, match):
    t0 = time.perf_counter()
    with pytest.raises(InputError, match=match) as err:
        Summary.from_json(data, where="/data/res/summary.json")
    assert time.perf_counter() - t0 < 1.0                 # refused before walking them all
    msg = str(err.value)
    assert msg.startswith("/data/res/summary.json: key '") and "\n" not in msg
    assert len(msg) < 200


def test_not_an_object_is_refused():
    for data in ([1, 2], "summary", None, 3):
        with pytest.raises(InputError, match=r"^s\.json: must hold a JSON object$"):
            Summary.from_json(data, where="s.json")


@pytest.mark.slow
def test_a_results_folder_with_a_hostile_summary_names_the_file(tmp_path):
    """Through the file: NaN written by a non-strict writer, 10**5 components."""
    d = tmp_path / "res"
    d.mkdir()
    f = d / "summary.json"
    f.write_text('{"format": "%s", "thickness": {"mixture": {"components": '
                 '[{"weight": NaN, "mean_nm": 100, "sd_nm": 2}]}}}' % FORMAT)
    with pytest.raises(InputError, match=r"summary\.json: key 'thickness\.mixture\."
                                         r"components\[0\]\.weight': expected a finite") as err:
        Results(d)
    assert str(f) in str(err.value) and "\n" not in str(err.value)
    f.write_text(json.dumps({"ndf": {"mixture": {"components": [_component()] * 10 ** 4}}}))
    with pytest.raises(InputError, match=r"summary\.json: key 'ndf\.mixture\.components': "
                                         r"10000 components"):
        Results(d)
    f.write_text(json.dumps({"ndf": {"mixture": {"components": [_component()] * 10 ** 5}}}))
    with pytest.raises(InputError, match=r"summary\.json: 5 MB is too large for this file"):
        Results(d)                                    # refused before it is parsed
