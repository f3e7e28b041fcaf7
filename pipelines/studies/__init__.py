"""The studies: one module per study, each with ``STUDY`` and ``run`` (see :mod:`pipelines`).

Modules whose name starts with ``_`` are helpers, not studies.
"""
