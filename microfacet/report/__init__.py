"""The analysis report of a results folder, and the figures of ``microfacet simulate``.

:func:`write_report` draws the five pages of :data:`PAGES` into a PDF (and PNGs) from a
results folder; :func:`parameter_tables` returns the tables of page 4 as strings;
:func:`plot_maps` draws angular maps for ``microfacet simulate``.

Modules: :mod:`~microfacet.report.writer` (the entry point, header and footer),
:mod:`~microfacet.report.context` (the folder opened for the report),
:mod:`~microfacet.report.layout` (page geometry and drawing helpers),
:mod:`~microfacet.report.arrays` (maps reduced for display, colour limits, histograms), one
module per page (``page_overview``, ``page_maps``, ``page_distributions``, ``page_parameters``,
``page_angular``, each with ``draw(page, ctx)``) and :mod:`~microfacet.report.figures`.

Names load on first use: ``import microfacet.report`` imports neither matplotlib nor the
modules.
"""

from ..core.lazy import attach_stub

__getattr__, __dir__, __all__ = attach_stub(__name__, __file__)
