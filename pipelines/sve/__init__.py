"""The sections of the ``speed-vs-error`` study (docs/speed-vs-error.md), one module each:
``spectral`` (§1), ``table`` (§2), ``inversion`` (§3, with ``roi``, ``facet`` and ``tilt``),
section 4 in :mod:`pipelines.studies.accuracy_focus` (the focus measurement is that study's)
and ``eq6`` (§5); ``common`` holds what they share.

Each section has ``run(cfg, doc, img)`` (it writes its part of the page into ``doc`` and its
Pareto plot into ``img``, and returns its results) and ``summary_rows(result)``.
"""
