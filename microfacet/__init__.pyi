from .analysis.options import AnalysisOptions
from .analysis.output import write_results
from .analysis.pipeline import analyse_stack
from .colour.difference import delta_e
from .colour.model import FilmColourModel
from .colour.table import build_colour_table
from .core.distributions import NDFMixture, ThicknessMixture
from .core.errors import InputError
from .forward.brdf import microfacet_brdf
from .forward.synth import generate_stack
from .io.results import Results
from .optics.constants import optical_constants
from .optics.thinfilm import reflectance
from .report.writer import write_report
from .workflow.analyse import analyse_to_folder
from .workflow.batch import run_batch
from .workflow.height import height_to_folder
from .workflow.simulate import simulate_to_folder

__version__: str

__all__ = [
    "AnalysisOptions",
    "FilmColourModel",
    "InputError",
    "NDFMixture",
    "Results",
    "ThicknessMixture",
    "analyse_stack",
    "analyse_to_folder",
    "build_colour_table",
    "delta_e",
    "generate_stack",
    "height_to_folder",
    "microfacet_brdf",
    "optical_constants",
    "reflectance",
    "run_batch",
    "simulate_to_folder",
    "write_report",
    "write_results",
]
