"""``microfacet batch``: bad arguments exit 2 with one line and write nothing; the list of
stacks from a file. Batches themselves: tests/batch/test_runner.py."""

import csv
from pathlib import Path

import pytest

from microfacet.cli import main

FAST = ["--roi-size-px", "48", "--no-report", "-q"]


def _rows(folder):
    with open(Path(folder) / "batch_summary.csv", newline="") as fh:
        return list(csv.DictReader(fh))


@pytest.mark.slow
@pytest.mark.parametrize("argv, msg", [
    (["batch", "--out", "{tmp}/o"], "STACK"),
    (["batch", "{a}", "--out", "{tmp}/o", "--jobs", "0"], "--jobs"),
    (["batch", "{a}", "{a}", "--out", "{tmp}/o"], "more than once"),
    (["batch", "{a}", "--out", "{tmp}/o", "--roi-size-px", "0"], "--roi-size-px"),
    (["batch", "{a}", "--out", "{tmp}/o", "--film", "Nope"], "--film"),
    (["batch", "--stacks-from", "{tmp}/missing.txt", "--out", "{tmp}/o"], "--stacks-from"),
])
def test_bad_batch_arguments_exit_2_with_one_line_and_write_nothing(argv, msg, batch_drawer,
                                                                   tmp_path, capsys):
    argv = [a.format(tmp=tmp_path, a=batch_drawer / "a") for a in argv]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert msg in err and len(err.splitlines()) == 1
    assert not (tmp_path / "o").exists()


@pytest.mark.slow
def test_stacks_from_file(batch_drawer, tmp_path):
    lst = tmp_path / "list.txt"
    lst.write_text(f"# my batch_drawer\n{batch_drawer / 'a'}\n\n")
    out = tmp_path / "res"
    assert main(["batch", "--stacks-from", str(lst), "--out", str(out), "--jobs", "1",
                 *FAST]) == 0
    assert [Path(r["stack"]).name for r in _rows(out)] == ["a"]
