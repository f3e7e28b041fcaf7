from . import (
    angular_map,
    height_folder,
    images,
    instruments,
    jsonfile,
    limits,
    lock,
    material_file,
    outdir,
    results,
    simulation,
    spectrum,
    stack,
    stack_checks,
    stack_schema,
    stack_write,
    summary,
    tiff_meta,
    vendor,
    x3p,
)
from .instruments import read_height_map
from .limits import Limits
from .outdir import OutputFolder, atomic_output_dir
from .results import Results
from .spectrum import Spectrum, read_spectrum
from .stack import Stack, find_images, read_stack, stack_from_images
from .stack_write import write_stack, write_stack_json
from .summary import Summary
from .x3p import HeightMap, read_x3p, write_x3p

__all__ = [
    "HeightMap",
    "Limits",
    "OutputFolder",
    "Results",
    "Spectrum",
    "Stack",
    "Summary",
    "angular_map",
    "atomic_output_dir",
    "find_images",
    "height_folder",
    "images",
    "instruments",
    "jsonfile",
    "limits",
    "lock",
    "material_file",
    "outdir",
    "read_height_map",
    "read_spectrum",
    "read_stack",
    "read_x3p",
    "results",
    "simulation",
    "spectrum",
    "stack",
    "stack_checks",
    "stack_from_images",
    "stack_schema",
    "stack_write",
    "summary",
    "tiff_meta",
    "vendor",
    "write_stack",
    "write_stack_json",
    "write_x3p",
    "x3p",
]
