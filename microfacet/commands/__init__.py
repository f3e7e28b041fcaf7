"""Subcommands of the ``microfacet`` command line, one module each (see :mod:`microfacet.cli`)."""
