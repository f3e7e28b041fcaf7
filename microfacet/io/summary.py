"""``summary.json`` of a results folder as a typed, versioned :class:`Summary`.

The analysis builds a :class:`Summary` and writes it with :meth:`Summary.to_json`; every
reader gets it back through :meth:`Summary.from_json`, which validates it as the stack reader
validates a stack: every known key of its type (numbers finite where they must be), counts
and sizes bounded (at most :data:`MAX_COMPONENTS` mixture components, :data:`MAX_ITEMS` items
in a list or mapping), and one line naming the file and the key for the first breach. Keys it
does not know are kept (a newer writer's) but not used. Summaries of format version 1 (film,
substrate and illuminant repeated at the top level, ``identified`` also inside
``ndf.mixture``) are read too.

The keys are documented in docs/results-format.md.

Examples
--------
>>> s = Summary.from_json({"format": FORMAT, "summary_version": 2, "thickness": {"mixture": {
...     "components": [{"weight": 1.0, "mean_nm": 51.0, "sd_nm": 2.0}]}}})
>>> s.thickness.mixture["components"][0]["mean_nm"], s.summary_version
(51.0, 2)
>>> Summary.from_json({"format": FORMAT, "exposure": "bright"}, where="s.json")
Traceback (most recent call last):
...
microfacet.core.errors.InputError: s.json: key 'exposure': expected a number, got 'bright'
"""

from __future__ import annotations

import dataclasses
import math
import typing
from dataclasses import dataclass, field

from ..core.distributions import MAX_COMPONENTS
from ..core.errors import InputError
from .jsonfile import json_safe

__all__ = ["DeltaE", "FacetCounts", "Inputs", "Iso25178Section", "NdfSection", "RoiCounts",
           "Summary", "ThicknessSection"]

FORMAT = "microfacet-results/1"
#: Version of the summary's layout within the format (2: no repeated keys, structured
#: reasons, the options tree as ``parameters``).
SUMMARY_VERSION = 2
#: Most items of any list or mapping in a summary (warnings, timings, versions, ...).
MAX_ITEMS = 1000
#: Largest summary.json read (the analysis writes ~10 kB; a file of :data:`MAX_ITEMS` long
#: warnings stays far below this).
MAX_SUMMARY_BYTES = 4 << 20


@dataclass
class Inputs:
    """What was analysed: the stack, its size, pixel size, slices (and their JPEG
    compression), and the optics modelled."""

    stack: str = ""
    shape: list = field(default_factory=list)
    n_slices: int = 0
    jpeg: dict | None = None
    pixel_size_um: object = None
    z_um_range: list | None = None
    height_source: str = ""
    film: str = ""
    substrate: str = ""
    illuminant: str = ""
    numerical_aperture: float | None = None


@dataclass
class RoiCounts:
    """The regions of interest: how many, how many fitted, the mean thickness, how many have
    an ambiguous interference order (runner-up within ``ambiguous_delta_e``) and, for each of
    those, both candidates with their ΔE (``ambiguous``), how many fits disagree with their
    own pixels' thicknesses."""

    count: int = 0
    fitted: int = 0
    thickness_nm_mean: float | None = None
    ambiguous_count: int = 0
    ambiguous_delta_e: float | None = None
    pixel_disagree_count: int | None = None
    ambiguous: list = field(default_factory=list)


@dataclass
class ThicknessSection:
    """``mixture``: the components, the fit's statistics, ``identified``, ``reason``,
    ``reason_code``, ``reason_parameter``; ``roi``: :class:`RoiCounts`; ``order``: whether
    the interference order is established (``established``, ``reasons``)."""

    mixture: dict = field(default_factory=dict)
    roi: RoiCounts = field(default_factory=RoiCounts)
    order: dict = field(default_factory=dict)


@dataclass
class NdfSection:
    """Whether the NDF is identified (and why not), the lobes and their fit, the acceptance
    limit, the mean plane's tilt."""

    identified: bool = False
    reason: str = ""
    reason_code: str | None = None
    reason_parameter: str | None = None
    mixture: dict = field(default_factory=dict)
    max_tilt_deg: float | None = None
    mean_plane_tilt_deg: float | None = None
    histogram: str = ""
    self_check: dict | None = None


@dataclass
class FacetCounts:
    """The joint mode's facets."""

    count: int = 0
    median_area_px: float | None = None
    with_height_plane: int = 0
    height_plane_area_fraction: float | None = None
    censored_area_fraction: float | None = None


@dataclass
class DeltaE:
    """Per-pixel ΔE between the image and the model: mean, median, 95th percentile, and the
    image's noise floors of the mean and the median."""

    mean: float | None = None
    median: float | None = None
    p95: float | None = None
    noise_floor_mean: float | None = None
    noise_floor_median: float | None = None


@dataclass
class Iso25178Section:
    """ISO 25178-2 areal parameters of the height map on its reliable pixels
    (:mod:`microfacet.analysis.iso25178`): Sq, Sa (µm), Sdq, Sdr (%) about ``reference``
    (the least-squares plane: the S-F surface), gradients by ``differences``; beside them
    the map as measured (mean removed, not levelled) by SurfaceTopography's conventions,
    ``rms_height_um`` (``rms_height_from_area()``) and ``rms_gradient``
    (``rms_gradient()``), and microfacet's own ``rms_slope_normals`` (tan of
    ``tilt_height_deg.npy``: central differences, smoothed for a height from focus)."""

    standard: str = "ISO 25178-2"
    reference: str = ""
    differences: str = ""
    n_points: int = 0
    Sq_um: float | None = None
    Sa_um: float | None = None
    Sdq: float | None = None
    Sdr_percent: float | None = None
    plane_tilt_deg: float | None = None
    rms_height_um: float | None = None
    rms_gradient: float | None = None
    rms_slope_normals: float | None = None


@dataclass
class Summary:
    """``summary.json`` (docs/results-format.md)."""

    format: str = FORMAT
    summary_version: int = SUMMARY_VERSION
    created: str = ""
    mode: str = ""
    inputs: Inputs = field(default_factory=Inputs)
    parameters: dict = field(default_factory=dict)
    versions: dict = field(default_factory=dict)
    thickness: ThicknessSection = field(default_factory=ThicknessSection)
    ndf: NdfSection = field(default_factory=NdfSection)
    facets: FacetCounts | None = None
    exposure: float | None = None
    exposure_source: str = ""
    exposure_readings: dict | None = None
    white_balance: dict | None = None
    flat_field: dict | None = None
    delta_e: DeltaE = field(default_factory=DeltaE)
    masked_fraction: float | None = None
    mask: dict = field(default_factory=dict)
    colour_noise_de: float | None = None
    colour_block_noise_de: float | None = None
    tilt_information: dict = field(default_factory=dict)
    height: dict = field(default_factory=dict)
    iso25178: Iso25178Section | None = None
    colour_table: dict = field(default_factory=dict)
    warnings: list = field(default_factory=list)
    timings_s: dict = field(default_factory=dict)
    extra: dict = field(default_factory=dict, repr=False)

    def to_json(self) -> dict:
        """The JSON object (NaN and ±inf as None; keys not known to this version, read from
        a newer writer's file, kept as they were)."""

        out = {f.name: _plain(getattr(self, f.name)) for f in dataclasses.fields(self)
               if f.name != "extra"}
        out.update(self.extra)
        return json_safe(out)

    @classmethod
    def from_json(cls, data, *, where: str = "summary.json") -> "Summary":
        """Validate ``data`` (a parsed summary.json) and return it typed.

        Raises
        ------
        InputError
            ``where: key 'a.b': what is wrong`` for the first breach.
        """
        if not isinstance(data, dict):
            raise InputError(f"{where}: must hold a JSON object")
        data = _upgrade(dict(data))
        fmt = data.get("format", FORMAT)
        if not isinstance(fmt, str) or not fmt.startswith("microfacet-results/"):
            raise InputError(f"{where}: key 'format': {fmt!r} is not {FORMAT!r}")
        out = _load(cls, data, where, "")
        for key in ("thickness", "ndf"):
            _check_mixture(getattr(out, key).mixture, where, f"{key}.mixture")
        return out


def _plain(v):
    if dataclasses.is_dataclass(v):
        return {f.name: _plain(getattr(v, f.name)) for f in dataclasses.fields(v)}
    return v


#: Version 1's flat ``parameters`` → their dotted paths in the options tree of version 2.
V1_PARAMETERS = {
    "roi_size_px": "roi.size_px", "roi_stride_px": "roi.stride_px",
    "saturation_min": "mask.saturation_min", "value_min": "mask.value_min",
    "thickness_range_nm": "optics.thickness_range_nm", "exposure": "optics.exposure",
    "film": "optics.film", "substrate": "optics.substrate", "illuminant": "optics.illuminant",
    "delta_e_method": "optics.delta_e_method", "facet_size_um": "joint.facet_size_um",
    "tilt_step_deg": "tilt.step_deg", "max_components": "fits.max_components",
    "operator": "focus.operator", "window_px": "focus.window_px", "align": "focus.align"}


def _nested_parameters(flat: dict) -> dict:
    out: dict = {}
    for key, value in flat.items():
        node = out
        *parents, leaf = V1_PARAMETERS.get(key, key).split(".")
        for k in parents:
            node = node.setdefault(k, {})
        node[leaf] = value
    return out


def _upgrade(data: dict) -> dict:
    """A version-1 summary in the version-2 layout (nothing is lost: the repeated keys
    equal their originals; the flat parameters are nested as the options tree)."""
    if data.get("summary_version") is not None:
        return data
    if isinstance(data.get("parameters"), dict):
        data["parameters"] = _nested_parameters(data["parameters"])
    inputs = data.get("inputs")
    if isinstance(inputs, dict) or inputs is None:
        inputs = dict(inputs or {})
        for key in ("film", "substrate", "illuminant"):
            if key in data and key not in inputs:
                inputs[key] = data[key]
        data["inputs"] = inputs
    for key in ("film", "substrate", "illuminant"):
        data.pop(key, None)
    ndf = data.get("ndf")
    if isinstance(ndf, dict) and isinstance(ndf.get("mixture"), dict):
        mix = {k: v for k, v in ndf["mixture"].items() if k not in ("identified", "reason")}
        data["ndf"] = {**ndf, "mixture": mix}
    data["summary_version"] = 1
    return data


def _type_error(where, path, want, value):
    shown = repr(value)
    shown = shown if len(shown) <= 40 else shown[:37] + "..."
    return InputError(f"{where}: key '{path}': expected {want}, got {shown}")


def _load_value(tp, value, where, path):
    """``value`` checked against the type hint ``tp`` (None allowed where Optional)."""
    args = typing.get_args(tp)
    if type(None) in args:
        if value is None:
            return None
        tp = next(a for a in args if a is not type(None))
    if dataclasses.is_dataclass(tp):
        if not isinstance(value, dict):
            raise _type_error(where, path, "an object", value)
        return _load(tp, value, where, f"{path}.")
    if tp is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise _type_error(where, path, "a number", value)
        if not math.isfinite(value):
            raise _type_error(where, path, "a finite number", value)
        return float(value)
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int) or abs(value) > 2 ** 53:
            raise _type_error(where, path, "an integer", value)
        return value
    if tp in (str, bool) and not isinstance(value, tp):
        raise _type_error(where, path, "a string" if tp is str else "true or false", value)
    if tp in (list, dict) or typing.get_origin(tp) in (list, dict):
        want = typing.get_origin(tp) or tp
        if not isinstance(value, want):
            raise _type_error(where, path, "a list" if want is list else "an object", value)
        if len(value) > MAX_ITEMS:
            raise InputError(f"{where}: key '{path}': {len(value)} items, more than "
                             f"{MAX_ITEMS}")
    return value


def _load(cls, data: dict, where: str, prefix: str):
    hints = typing.get_type_hints(cls)
    kw, extra = {}, {}
    names = {f.name for f in dataclasses.fields(cls)} - {"extra"}
    for key, value in data.items():
        if key in names:
            kw[key] = _load_value(hints[key], value, where, f"{prefix}{key}")
        else:
            extra[key] = value
    out = cls(**kw)
    if extra and "extra" in {f.name for f in dataclasses.fields(cls)}:
        out.extra = extra
    return out


def _check_mixture(mix: dict, where: str, path: str) -> None:
    """A mixture's components: at most :data:`MAX_COMPONENTS`, each an object of finite
    numbers (the full check is :meth:`~microfacet.core.distributions.ThicknessMixture.from_json`
    when it is used)."""
    comps = mix.get("components", [])
    if not isinstance(comps, list):
        raise _type_error(where, f"{path}.components", "a list", comps)
    if len(comps) > MAX_COMPONENTS:
        raise InputError(f"{where}: key '{path}.components': {len(comps)} components, more "
                         f"than {MAX_COMPONENTS}")
    for i, c in enumerate(comps):
        if not isinstance(c, dict):
            raise _type_error(where, f"{path}.components[{i}]", "an object", c)
        for k, v in c.items():
            _load_value(float, v, where, f"{path}.components[{i}].{k}")
