from . import (
    angular,
    brdf,
    compare,
    eq6,
    halfvector,
    imaging,
    material,
    relief,
    scene,
    synth,
    synth_params,
)
from .angular import display_exposure, simulate_map
from .brdf import microfacet_brdf
from .eq6 import eq6_reflectance
from .material import Material
from .synth import generate_stack, preset
from .synth_params import SynthParams

__all__ = [
    "Material",
    "SynthParams",
    "angular",
    "brdf",
    "compare",
    "display_exposure",
    "eq6",
    "eq6_reflectance",
    "generate_stack",
    "halfvector",
    "imaging",
    "material",
    "microfacet_brdf",
    "preset",
    "relief",
    "scene",
    "simulate_map",
    "synth",
    "synth_params",
]
