"""The ND fixture stack as napari sample data (npe2 ``sample_data`` contribution).

``fixtures/stacks/nd-fixture`` lives in the source tree, not in the installed package: a
source checkout or an editable install opens it where it is; a regular install (a wheel,
no ``fixtures/``) makes the same stack once with the package's own generator — the command
fixtures/stacks/README.md records, ``microfacet synth --preset nd --seed 0 --size 256x256
--slices 20``, which rebuilds the fixture exactly — into the user's cache folder
(``$XDG_CACHE_HOME/microfacet/nd-fixture``, else ``~/.cache/microfacet/nd-fixture``).

Examples
--------
>>> (fixture_path(generate=False) / "stack.json").is_file()   # in the source tree
True
"""

from __future__ import annotations

import os
from pathlib import Path

from ..forward.synth import generate_stack, preset
from .reader import stack_layers

__all__ = ["FIXTURE_SOURCE", "fixture_path", "nd_fixture"]

#: The fixture in the source tree (present in a checkout and an editable install).
FIXTURE_SOURCE = Path(__file__).resolve().parents[2] / "fixtures" / "stacks" / "nd-fixture"
#: How fixtures/stacks/README.md says the fixture was made (``microfacet synth``).
FIXTURE_RECIPE = {"name": "nd", "seed": 0, "height_px": 256, "width_px": 256, "n_slices": 20}


def _cache_dir() -> Path:
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "microfacet" / "nd-fixture"


def fixture_path(*, generate: bool = True) -> Path:
    """The ND fixture stack folder: the source tree's, else the cached copy, else (with
    ``generate``) a copy made now with :data:`FIXTURE_RECIPE` into the cache folder.

    Raises
    ------
    FileNotFoundError
        Neither exists and ``generate`` is false.
    """
    for folder in (FIXTURE_SOURCE, _cache_dir()):
        if (folder / "stack.json").is_file():
            return folder
    if not generate:
        raise FileNotFoundError(f"{FIXTURE_SOURCE}: not found, and no cached copy")
    recipe = dict(FIXTURE_RECIPE)
    out = _cache_dir()
    out.parent.mkdir(parents=True, exist_ok=True)
    generate_stack(out, preset(recipe.pop("name"), **recipe))
    return out


def nd_fixture() -> list[tuple]:
    """The ND fixture as a z-stack layer (:func:`microfacet.napari.reader.stack_layers`)."""
    return stack_layers(fixture_path())
