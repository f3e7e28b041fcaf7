from . import (
    arrays,
    context,
    figures,
    layout,
    page_angular,
    page_distributions,
    page_maps,
    page_overview,
    page_parameters,
    writer,
)
from .arrays import MAX_MAP_PX
from .figures import plot_maps
from .layout import NO_VALUE
from .page_parameters import parameter_tables
from .writer import PAGES, write_report

__all__ = [
    "MAX_MAP_PX",
    "NO_VALUE",
    "PAGES",
    "arrays",
    "context",
    "figures",
    "layout",
    "page_angular",
    "page_distributions",
    "page_maps",
    "page_overview",
    "page_parameters",
    "parameter_tables",
    "plot_maps",
    "write_report",
    "writer",
]
