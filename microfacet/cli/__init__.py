"""The ``microfacet`` command line: one module per command (see :mod:`microfacet.cli.main`)."""

from .main import main

__all__ = ["main"]
