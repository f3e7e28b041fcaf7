from . import (
    reader,
    sample_data,
    widget,
)
from .reader import get_results_reader, get_stack_reader, results_layers, stack_layers
from .sample_data import fixture_path, nd_fixture
from .widget import analysis_widget

__all__ = [
    "analysis_widget",
    "fixture_path",
    "get_results_reader",
    "get_stack_reader",
    "nd_fixture",
    "reader",
    "results_layers",
    "sample_data",
    "stack_layers",
    "widget",
]
