from . import (
    bsdf,
    scene,
    scene_xml,
    variants,
)
from .bsdf import PLUGIN, register
from .scene import Camera, Light, build_scene
from .scene_xml import write_scene_xml
from .variants import available_variants, choose_variant

__all__ = [
    "Camera",
    "Light",
    "PLUGIN",
    "available_variants",
    "bsdf",
    "build_scene",
    "choose_variant",
    "register",
    "scene",
    "scene_xml",
    "variants",
    "write_scene_xml",
]
