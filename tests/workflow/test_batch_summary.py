"""The batch summary (microfacet.workflow.batch_summary): short, unique result folder names."""

import pytest

from microfacet.workflow.batch_summary import result_names


def test_result_names_are_unique_and_short():
    assert result_names(["x/a", "y/b"]) == ["a", "b"]
    assert result_names(["p/x/s", "p/y/s", "q/t"]) == ["x_s", "y_s", "t"]
    with pytest.raises(ValueError, match="stacks: given more than once"):
        result_names(["x/a", "x/a"])
