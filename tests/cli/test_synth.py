"""``microfacet synth``: writes a readable stack, refuses an existing folder."""

import pytest

from microfacet.cli import main
from microfacet.io.stack import read_stack


@pytest.mark.slow
def test_cli_synth(tmp_path):
    assert main(["synth", str(tmp_path / "x"), "--preset", "thin", "--seed", "1", "--size",
                 "40x50", "--slices", "3", "-q"]) == 0
    assert read_stack(tmp_path / "x").n_slices == 3
    assert main(["synth", str(tmp_path / "x"), "--preset", "thin", "-q"]) == 2
