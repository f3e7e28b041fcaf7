"""Output folders (microfacet.io.outdir): never an input, only its own kind replaced, whole or
not at all. Unit tests of the rules; the same end to end through every command:
tests/cli/test_hostile_input.py."""

from __future__ import annotations

import pytest

from microfacet.core.errors import InputError
from microfacet.io import lock as lk
from microfacet.io.outdir import (
    KINDS,
    OutputFolder,
    atomic_output_dir,
    check_output,
    output_kind,
    sweep_stale,
)


def _files(folder):
    """{relative path: bytes} of everything under ``folder``."""
    return {p.relative_to(folder).as_posix(): (p.read_bytes() if p.is_file() else None)
            for p in sorted(folder.rglob("*"))}


def _write_kind(folder, kind):
    """The marker file(s) by which ``kind`` is recognised (and nothing else)."""
    folder.mkdir(parents=True, exist_ok=True)
    if kind == "results":
        (folder / "summary.json").write_text('{"format": "microfacet-results/1"}')
    elif kind == "height":
        (folder / "height.json").write_text('{"format": "microfacet-height/1"}')
    elif kind == "simulate":
        (folder / "simulate.json").write_text('{"format": "microfacet-simulate/2"}')
    elif kind == "render":
        (folder / "render.json").write_text('{"format": "microfacet-render/1"}')
    elif kind == "batch":
        (folder / "batch_summary.csv").write_text("stack,results,status,reason\n")
    elif kind == "synthetic stack":
        (folder / "stack.json").write_text('{"format": "microfacet-stack/1"}')
        (folder / "truth").mkdir()
        (folder / "truth" / "params.json").write_text(
            '{"format": "microfacet-synth-truth/1"}')
    return folder


# ---------------------------------------------------------------------------- output_kind


@pytest.mark.parametrize("kind", sorted(KINDS))
def test_each_kind_is_recognised_by_its_content(tmp_path, kind):
    folder = _write_kind(tmp_path / "anything", kind)
    (folder / "other.txt").write_text("x")
    assert output_kind(folder) == kind


@pytest.mark.parametrize("files", [
    {},                                                          # empty
    {"summary.json": '{"format": "somebody-else/1"}'},           # another format
    {"summary.json": "{not json"},
    {"summary.json": '["microfacet-results/1"]'},                # not an object
    {"height.json": '{"format": "microfacet-results/1"}'},       # marker in the wrong file
    {"batch_summary.csv": "name,value\n"},
    {"stack.json": '{"format": "microfacet-stack/1"}'},          # a real stack: no truth
    {"truth/params.json": '{"format": "microfacet-synth-truth/1"}'},   # truth, no stack
    {"notes.txt": "microfacet-results/1"},
])
def test_other_folders_are_no_kind(tmp_path, files):
    folder = tmp_path / "results"                               # the name does not count
    folder.mkdir()
    for name, text in files.items():
        (folder / name).parent.mkdir(parents=True, exist_ok=True)
        (folder / name).write_text(text)
    assert output_kind(folder) is None


def test_a_utf8_bom_is_accepted_in_the_markers(tmp_path):
    folder = tmp_path / "r"
    folder.mkdir()
    (folder / "summary.json").write_bytes(b"\xef\xbb\xbf" + b'{"format": "microfacet-results/1"}')
    assert output_kind(folder) == "results"


# --------------------------------------------------------------------------- check_output


def test_a_new_folder_is_accepted_as_an_absolute_path(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert check_output("new/out", kind="results") == tmp_path / "new" / "out"


def _refused(out, *, match, **kw):
    with pytest.raises(InputError, match=match) as err:
        check_output(out, **kw)
    assert err.value.param == "out" and "\n" not in str(err.value)
    return err.value


def test_an_input_and_a_folder_holding_an_input_are_refused(tmp_path):
    stack = tmp_path / "drawer" / "s1"
    stack.mkdir(parents=True)
    (stack / "stack.json").write_text("{}")
    csv = tmp_path / "drawer" / "spectrum.csv"
    csv.write_text("x")
    for overwrite in (False, True):
        _refused(stack, kind="results", inputs=[stack], overwrite=overwrite,
                 match="is the input")
        _refused(tmp_path / "drawer", kind="batch", inputs=[stack], overwrite=overwrite,
                 match="holds the input")
        _refused(tmp_path / "drawer", kind="simulate", inputs=[csv], overwrite=overwrite,
                 match="holds the input")
        _refused(tmp_path, kind="results", inputs=[stack], overwrite=overwrite,
                 match="holds the input")


def test_an_input_reached_through_a_symlink_is_still_the_input(tmp_path):
    real = tmp_path / "real"
    real.mkdir()
    (tmp_path / "link").symlink_to(real)
    _refused(tmp_path / "link" / "..", kind="results", inputs=[real / "s"],
             match="holds the input")
    _refused(tmp_path / "link", kind="results", inputs=[real], match="is the input")


@pytest.mark.parametrize("out, what", [(".", "is the current folder"),
                                       ("..", "holds the current folder")])
def test_the_current_folder_and_its_ancestors_are_refused(tmp_path, monkeypatch, out, what):
    (tmp_path / "work").mkdir()
    monkeypatch.chdir(tmp_path / "work")
    for overwrite in (False, True):
        _refused(out, kind="results", overwrite=overwrite, match=what)


def test_a_folder_holding_a_focus_stack_is_never_replaced(tmp_path):
    s = tmp_path / "s"
    s.mkdir()
    (s / "stack.json").write_text("{}")
    for kind in ("results", "height", "batch"):
        for overwrite in (False, True):
            _refused(s, kind=kind, overwrite=overwrite, match="is a focus stack folder")
    # deeper inside an output of the right kind: refused before replacing it
    res = _write_kind(tmp_path / "res", "results")
    (res / "inner").mkdir()
    (res / "inner" / "stack.json").write_text("{}")
    _refused(res, kind="results", overwrite=True, match="holds a focus stack")


def test_a_foreign_folder_is_never_replaced(tmp_path):
    mine = tmp_path / "photos"
    mine.mkdir()
    (mine / "cat.jpg").write_bytes(b"\xff\xd8")
    for overwrite in (False, True):
        e = _refused(mine, kind="results", overwrite=overwrite,
                     match="is not an analysis results folder written by microfacet; it is "
                           "never replaced")
        assert "overwrite" not in str(e)          # no invitation to force it
    assert (mine / "cat.jpg").read_bytes() == b"\xff\xd8"


@pytest.mark.parametrize("found", ["height", "simulate", "batch"])
def test_another_kind_is_not_replaced(tmp_path, found):
    folder = _write_kind(tmp_path / "out", found)
    for overwrite in (False, True):
        _refused(folder, kind="results", overwrite=overwrite,
                 match=f"is {KINDS[found]}, not an analysis results folder")


@pytest.mark.parametrize("kind", sorted(KINDS))
def test_the_same_kind_needs_overwrite(tmp_path, kind):
    folder = _write_kind(tmp_path / "out", kind)
    _refused(folder, kind=kind, match=r"already exists .*overwrite replaces it")
    assert check_output(folder, kind=kind, overwrite=True) == folder


def test_an_empty_folder_and_one_of_leftovers_only_are_used(tmp_path):
    empty = tmp_path / "e"
    empty.mkdir()
    assert check_output(empty, kind="results") == empty
    left = tmp_path / "l"
    left.mkdir()
    (left / ".x.partial-abc").mkdir()
    (left / ".x.old-1").mkdir()
    (left / ".x.lock").write_text("")
    assert check_output(left, kind="height") == left
    (left / ".hidden").write_text("")              # not a microfacet name: the user's
    _refused(left, kind="height", match="is not a height-from-focus folder")


def test_a_file_a_symlink_and_unprintable_paths_are_refused(tmp_path):
    (tmp_path / "f").write_text("x")
    _refused(tmp_path / "f", kind="results", match="exists and is not a folder")
    (tmp_path / "d").mkdir()
    (tmp_path / "ln").symlink_to(tmp_path / "d")
    _refused(tmp_path / "ln", kind="results", match="is a symbolic link")
    _refused(str(tmp_path / "a\nb"), kind="results", match="control character")
    _refused(str(tmp_path / "a\x00b"), kind="results", match="NUL byte")
    _refused("", kind="results", match="empty path")
    with pytest.raises(ValueError, match="kind: expected one of"):
        check_output(tmp_path / "x", kind="photos")


# -------------------------------------------------------------------------- OutputFolder


def test_writing_appears_whole_and_leaves_nothing_else(tmp_path):
    with OutputFolder(tmp_path / "res", kind="results") as claim:
        assert (tmp_path / ".res.lock").exists()
        with claim.writing() as tmp:
            assert tmp.parent == tmp_path and tmp.name.startswith(".res.partial-")
            assert not (tmp_path / "res").exists()         # nothing at out while writing
            _write_kind(tmp, "results")
            (tmp / "a.npy").write_bytes(b"1")
        assert output_kind(tmp_path / "res") == "results"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["res"]       # lock released


@pytest.mark.parametrize("exc", [RuntimeError("boom"), KeyboardInterrupt()])
def test_an_exception_inside_leaves_nothing_new(tmp_path, exc):
    with pytest.raises(type(exc)):
        with atomic_output_dir(tmp_path / "res", kind="results") as tmp:
            _write_kind(tmp, "results")
            raise exc
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("exc", [RuntimeError("boom"), KeyboardInterrupt()])
def test_an_exception_inside_leaves_the_old_folder_intact(tmp_path, exc):
    old = _write_kind(tmp_path / "res", "results")
    (old / "old.txt").write_text("old")
    before = _files(old)
    with pytest.raises(type(exc)):
        with atomic_output_dir(old, kind="results", overwrite=True) as tmp:
            _write_kind(tmp, "results")
            (tmp / "new.txt").write_text("new")
            raise exc
    assert _files(old) == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["res"]


def test_overwrite_replaces_the_old_folder_only_when_the_new_one_is_complete(tmp_path):
    old = _write_kind(tmp_path / "res", "results")
    (old / "old.txt").write_text("old")
    with atomic_output_dir(old, kind="results", overwrite=True) as tmp:
        _write_kind(tmp, "results")
        (tmp / "new.txt").write_text("new")
        assert (old / "old.txt").read_text() == "old"          # still there meanwhile
    assert sorted(p.name for p in old.iterdir()) == ["new.txt", "summary.json"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["res"]


def test_an_empty_existing_folder_is_filled(tmp_path):
    (tmp_path / "res").mkdir()
    with atomic_output_dir(tmp_path / "res", kind="results") as tmp:
        _write_kind(tmp, "results")
    assert output_kind(tmp_path / "res") == "results"


def test_the_folder_is_checked_again_when_the_block_completes(tmp_path):
    """Someone else's files appear at ``out`` while writing: they are not replaced and the
    new output is discarded."""
    with pytest.raises(InputError, match="never replaced"):
        with atomic_output_dir(tmp_path / "res", kind="results") as tmp:
            _write_kind(tmp, "results")
            (tmp_path / "res").mkdir()
            (tmp_path / "res" / "theirs.txt").write_text("x")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["res"]
    assert [p.name for p in (tmp_path / "res").iterdir()] == ["theirs.txt"]


def test_writing_outside_the_with_block_is_an_error(tmp_path):
    claim = OutputFolder(tmp_path / "res", kind="results")
    with pytest.raises(RuntimeError, match="outside its with-block"):
        with claim.writing():
            pass


def test_the_claim_is_checked_before_any_work(tmp_path):
    """The rules apply when the claim is made (the constructor), before the command works."""
    (tmp_path / "photos").mkdir()
    (tmp_path / "photos" / "cat.jpg").write_bytes(b"x")
    with pytest.raises(InputError, match="never replaced"):
        OutputFolder(tmp_path / "photos", kind="height")
    with pytest.raises(InputError, match=r"needs about [\d,]+ MB"):
        with OutputFolder(tmp_path / "big", kind="height", expected_bytes=1 << 60):
            pass
    assert sorted(p.name for p in tmp_path.iterdir()) == ["photos"]


def test_leftovers_of_a_killed_run_are_removed_by_the_next_claim(tmp_path):
    (tmp_path / ".res.partial-dead").mkdir()
    (tmp_path / ".res.partial-dead" / "x.npy").write_bytes(b"1")
    (tmp_path / ".res.old-dead").mkdir()
    (tmp_path / ".other.partial-1").mkdir()             # another output's: not touched
    with OutputFolder(tmp_path / "res", kind="results") as claim:
        assert sorted(p.name for p in claim.removed) == [".res.old-dead", ".res.partial-dead"]
    assert sorted(p.name for p in tmp_path.iterdir()) == [".other.partial-1"]


def test_an_output_caught_between_its_two_renames_is_put_back(tmp_path):
    """Killed after moving the old output aside and before moving the new one in: the old
    output, complete, is in ``.res.old-*/res``; the next claim restores it."""
    aside = _write_kind(tmp_path / ".res.old-dead" / "res", "results")
    (aside / "old.txt").write_text("old")
    with OutputFolder(tmp_path / "res", kind="results", overwrite=True):
        assert (tmp_path / "res" / "old.txt").read_text() == "old"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["res"]


# ---------------------------------------------------------------------------- sweep_stale


def test_sweep_removes_what_dead_runs_left_and_skips_live_runs(tmp_path, lock_holder):
    for name in (".a.partial-1", ".a.old-2", ".b.partial-3", ".c.partial-4"):
        (tmp_path / name).mkdir()
        (tmp_path / name / "x").write_text("x")
    (tmp_path / ".a.lock").write_text("")                # unheld: a dead run's
    (tmp_path / ".d.lock").write_text("")                # a lock file alone
    (tmp_path / "a").mkdir()                             # outputs themselves stay
    (tmp_path / "keep.txt").write_text("x")
    lock_holder(lk.lock_path(tmp_path, "b"))             # b: a live run in another process
    removed = sweep_stale(tmp_path)
    assert sorted(p.name for p in removed) == [".a.old-2", ".a.partial-1", ".c.partial-4"]
    assert sorted(p.name for p in tmp_path.iterdir()) == [".b.lock", ".b.partial-3", "a",
                                                          "keep.txt"]
    assert sweep_stale(tmp_path / "missing") == []


def test_sweep_skips_a_write_in_progress_in_this_process(tmp_path):
    """A live run is one that holds its lock, whichever process it is in: a sweep of the
    parent (e.g. a second run_batch on the same folder from another thread) must leave the
    temporary folder of a write in progress alone, so that the write can complete."""
    with OutputFolder(tmp_path / "res", kind="results") as claim:
        with claim.writing() as tmp:
            _write_kind(tmp, "results")
            removed = sweep_stale(tmp_path)
            assert tmp.is_dir(), f"the sweep removed the write in progress: {removed}"
    assert output_kind(tmp_path / "res") == "results"
