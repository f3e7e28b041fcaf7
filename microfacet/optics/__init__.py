"""Optics: optical constants, the thin-film model and the spectrum fit (filled in below)."""

from .constants import (DEFAULT_FILM, DEFAULT_SUBSTRATE, OpticalConstantSet, known_sets, load_set,
                        optical_constants, resolve_index)
