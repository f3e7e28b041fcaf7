"""Hostile and absurd input, and bad days: the command line never loses data, never spends
memory on a lie in a header, and every failure is one line.

Each case asserts the exit status, one line on stderr naming the file, key or option at
fault (no traceback), that nothing was written beside ``--out``, and that the input is
unchanged (hashed). Cases whose danger is memory run in a subprocess under an address-space
cap (``resource.setrlimit``), so a regression fails here instead of exhausting the machine,
and report their peak resident memory. Only small files are made: headers are crafted, not
real bombs.
"""

from __future__ import annotations

import errno
import hashlib
import json
import os
import re
import signal
import struct
import subprocess
import sys
import textwrap
import time
import zlib
from pathlib import Path

import numpy as np
import pytest

from microfacet.cli import main
from microfacet.io.stack import read_stack, write_stack

H = W = 48
N = 5
ONE_LINE = re.compile(r"^microfacet [a-z-]+: error: [^\n]+$")


# ------------------------------------------------------------------------------- helpers
def _stack(folder: Path, *, n=N, grey=False) -> Path:
    rng = np.random.default_rng(1)
    shape = (H, W) if grey else (H, W, 3)
    write_stack(folder, [rng.integers(0, 256, shape, dtype=np.uint8) for _ in range(n)],
                z_step_um=0.5, pixel_size_um=0.25)
    return folder


def _digest(folder: Path) -> str:
    h = hashlib.sha256()
    for p in sorted(folder.rglob("*")):
        h.update(p.relative_to(folder).as_posix().encode())
        if p.is_file() and not p.is_symlink():
            h.update(p.read_bytes())
    return h.hexdigest()


def _edit(folder: Path, **changes):
    meta = json.loads((folder / "stack.json").read_text())
    meta.update(changes)
    (folder / "stack.json").write_text(json.dumps(meta))


def _err_line(capfd, status, expected_status=2):
    cap = capfd.readouterr()
    assert status == expected_status, cap.err
    assert "Traceback" not in cap.err, cap.err
    lines = cap.err.strip().splitlines()
    assert len(lines) == 1 and ONE_LINE.match(lines[0]), cap.err
    return lines[0]


def _chunk(kind: bytes, data: bytes) -> bytes:
    return (struct.pack(">I", len(data)) + kind + data
            + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF))


def _png(w, h, *, colour_type=2, bit_depth=8, rows=None) -> bytes:
    """A PNG claiming w x h; its data are ``rows`` (raw scanlines) or a token stream."""
    ihdr = struct.pack(">IIBBBBB", w, h, bit_depth, colour_type, 0, 0, 0)
    data = zlib.compress(rows if rows is not None else b"\x00" * 64)
    return (b"\x89PNG\r\n\x1a\n" + _chunk(b"IHDR", ihdr) + _chunk(b"IDAT", data)
            + _chunk(b"IEND", b""))


def _jpeg(w, h) -> bytes:
    sof = struct.pack(">BHHB", 8, h, w, 3) + b"\x01\x11\x00\x02\x11\x00\x03\x11\x00"
    return b"\xff\xd8\xff\xc0" + struct.pack(">H", len(sof) + 2) + sof + b"\x00" * 32 + b"\xff\xd9"


def _tiff(w, h, pages=1) -> bytes:
    """A little-endian TIFF whose pages claim w x h grey 8-bit, with 16 bytes of data each."""
    entries = 9
    ifd_size = 2 + entries * 12 + 4
    out = bytearray(b"II*\x00" + struct.pack("<I", 8))
    for k in range(pages):
        ifd_at = len(out)
        data_at = ifd_at + ifd_size
        nxt = data_at + 16 if k + 1 < pages else 0
        ifd = struct.pack("<H", entries)
        for tag, typ, val in ((256, 4, w), (257, 4, h), (258, 3, 8), (259, 3, 1), (262, 3, 1),
                              (273, 4, data_at), (277, 3, 1), (278, 4, h), (279, 4, 16)):
            ifd += struct.pack("<HHII", tag, typ, 1, val) if typ == 4 else \
                struct.pack("<HHIH2x", tag, typ, 1, val)
        out += ifd + struct.pack("<I", nxt) + b"\x00" * 16
    return bytes(out)


_RUNNER = textwrap.dedent("""
    import os, resource, sys
    cap = int(os.environ["MF_AS_LIMIT"])
    resource.setrlimit(resource.RLIMIT_AS, (cap, cap))
    from microfacet.cli import main

    def peak_kb():
        # VmHWM belongs to this address space (since exec); ru_maxrss on Linux also counts
        # the forking parent's pages, i.e. the whole pytest process
        try:
            with open("/proc/self/status") as fh:
                for line in fh:
                    if line.startswith("VmHWM:"):
                        return int(line.split()[1])
        except OSError:
            pass
        return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss

    try:
        status = main(sys.argv[1:])
    finally:
        with open(os.environ["MF_RSS_FILE"], "w") as fh:
            fh.write(str(peak_kb()))
    sys.exit(status)
""")
AS_LIMIT = 6 << 30      # a regression that allocates what a header claims fails fast here
RSS_BOUND_MB = 400      # numpy, OpenCV, scipy and microfacet imported: ~150-250 MB


def _run_bounded(tmp_path, argv, *, cwd=None):
    """Run the CLI in a subprocess under an address-space cap; (status, stderr, peak MB)."""
    rss_file = tmp_path / f"rss-{time.monotonic_ns()}.txt"
    env = {**os.environ, "MF_AS_LIMIT": str(AS_LIMIT), "MF_RSS_FILE": str(rss_file)}
    res = subprocess.run([sys.executable, "-c", _RUNNER, *argv], capture_output=True,
                         text=True, env=env, timeout=300, cwd=cwd)
    peak_mb = int(rss_file.read_text()) / 1024 if rss_file.exists() else float("nan")
    return res.returncode, res.stderr, peak_mb


def _assert_one_line(stderr, pattern):
    assert "Traceback" not in stderr, stderr
    lines = stderr.strip().splitlines()
    assert len(lines) == 1 and ONE_LINE.match(lines[0]), stderr
    assert re.search(pattern, lines[0]), lines[0]


# ------------------------------------------------------------------------------ data loss
@pytest.mark.parametrize("command", ["analyze", "height"])
def test_out_equal_to_the_stack_is_refused_even_with_overwrite(tmp_path, capfd, command):
    s = _stack(tmp_path / "s")
    before = _digest(s)
    line = _err_line(capfd, main([command, str(s), "--out", str(s), "--overwrite"]))
    assert "--out" in line and "is the input" in line
    assert _digest(s) == before


@pytest.mark.parametrize("command", ["analyze", "height"])
def test_out_holding_the_stack_and_its_siblings_is_refused(tmp_path, capfd, command):
    parent = tmp_path / "drawer"
    a, b = _stack(parent / "a"), _stack(parent / "b")
    before = _digest(parent)
    line = _err_line(capfd, main([command, str(a), "--out", str(parent), "--overwrite"]))
    assert "holds the input" in line
    assert _digest(parent) == before and b.exists()


def test_batch_into_the_folder_of_its_stacks_is_refused(tmp_path, capfd):
    d = tmp_path / "d"
    _stack(d / "s1"), _stack(d / "s2")
    before = _digest(d)
    line = _err_line(capfd, main(["batch", str(d / "s1"), str(d / "s2"), "--out", str(d),
                                  "--overwrite", "--jobs", "1"]))
    assert "--out" in line and "holds the input" in line
    assert _digest(d) == before


def test_out_holding_another_stack_is_never_replaced(tmp_path, capfd):
    s = _stack(tmp_path / "s")
    other = _stack(tmp_path / "other")           # a stack that is not this command's input
    before = _digest(other)
    line = _err_line(capfd, main(["height", str(s), "--out", str(other), "--overwrite"]))
    assert "focus stack folder" in line and "never replaced" in line
    assert _digest(other) == before


def test_a_users_folder_is_never_replaced_and_the_message_does_not_invite_overwrite(
        tmp_path, capfd):
    s = _stack(tmp_path / "s")
    mine = tmp_path / "thesis"
    mine.mkdir()
    (mine / "chapter1.tex").write_text("precious")
    for extra in ([], ["--overwrite"]):
        line = _err_line(capfd, main(["height", str(s), "--out", str(mine), *extra]))
        assert "never replaced" in line and "--overwrite" not in line
    assert (mine / "chapter1.tex").read_text() == "precious"


def test_simulate_never_replaces_the_results_it_reads(tmp_path, capfd):
    res = tmp_path / "res"
    res.mkdir()
    (res / "summary.json").write_text(json.dumps({
        "format": "microfacet-results/1",
        "thickness": {"mixture": {"components": [{"weight": 1, "mean_nm": 51, "sd_nm": 2}]}}}))
    before = _digest(res)
    line = _err_line(capfd, main(["simulate", "--results", str(res), "--out", str(res),
                                  "--overwrite"]))
    assert "is the input" in line
    assert _digest(res) == before


@pytest.mark.parametrize("out", [".", ".."])
def test_the_current_folder_and_its_parents_are_refused(tmp_path, capfd, monkeypatch, out):
    _stack(tmp_path / "work" / "s")    # a stack inside the current folder
    monkeypatch.chdir(tmp_path / "work")
    before = _digest(tmp_path)
    line = _err_line(capfd, main(["height", "s", "--out", out, "--overwrite"]))
    assert "current folder" in line
    assert _digest(tmp_path) == before
    assert not [p for p in tmp_path.rglob(".*old-*")]


def test_a_second_run_on_the_same_out_is_refused_while_the_first_writes(tmp_path, capfd):
    s = _stack(tmp_path / "s")
    out = tmp_path / "out"
    holder = subprocess.Popen(
        [sys.executable, "-c", textwrap.dedent(f"""
            import sys, time
            from microfacet.io.outdir import OutputFolder
            with OutputFolder({str(out)!r}, kind="height"):
                print("locked", flush=True)
                time.sleep(60)
        """)], stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "locked"
        line = _err_line(capfd, main(["height", str(s), "--out", str(out)]))
        assert "being written by another microfacet run" in line and f"pid {holder.pid}" in line
        assert not out.exists()
    finally:
        holder.kill()
        holder.wait()
    # the first run died (kill -9): its lock is free and the next run goes ahead
    assert main(["height", str(s), "--out", str(out), "-q"]) == 0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out", "s"]


def test_leftovers_of_a_killed_run_are_removed_by_the_next_run(tmp_path):
    s = _stack(tmp_path / "s")
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"],
                          capture_output=True, text=True).stdout.strip()
    (tmp_path / ".out.lock").write_text(json.dumps({"pid": int(dead), "host": "x"}))
    for tag in ("partial-abc123", "partial-zz", "old-q1"):
        junk = tmp_path / f".out.{tag}"
        junk.mkdir()
        (junk / "height_um.npy").write_bytes(b"\0" * 4096)
    assert main(["height", str(s), "--out", str(tmp_path / "out"), "-q"]) == 0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out", "s"]


def test_a_results_folder_caught_between_its_two_renames_is_put_back(tmp_path):
    s = _stack(tmp_path / "s")
    assert main(["height", str(s), "--out", str(tmp_path / "h"), "-q"]) == 0
    old = tmp_path / ".h.old-x1"
    old.mkdir()
    (tmp_path / "h").rename(old / "h")            # killed after moving the old results away
    (tmp_path / ".h.partial-y2").mkdir()          # ... before the new ones were in place
    assert main(["height", str(s), "--out", str(tmp_path / "h"), "-q"]) == 2  # exists again
    assert (tmp_path / "h" / "height.json").is_file()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["h", "s"]


@pytest.mark.slow
def test_batch_resume_sweeps_what_killed_workers_left(tmp_path):
    from microfacet.analysis.options import AnalysisOptions, RoiOptions
    from microfacet.workflow.batch import run_batch

    s = _stack(tmp_path / "a")
    out = tmp_path / "res"
    out.mkdir()
    (out / ".a.partial-k9").mkdir()
    (out / ".a.lock").write_text("{}")
    (out / ".b.old-k9").mkdir()
    result = run_batch([s], out, options=AnalysisOptions(roi=RoiOptions(size_px=16)), jobs=1,
                       report=False)
    assert len(result.rows) == 1
    assert not [p.name for p in out.iterdir() if p.name.startswith(".")]


@pytest.mark.slow
@pytest.mark.parametrize("sig, status", [(signal.SIGTERM, 143), (signal.SIGINT, 130)])
def test_signals_during_writing_leave_nothing(tmp_path, sig, status):
    out = tmp_path / "big"
    # SIGINT at its default in the child: a pytest started in the background of a
    # non-interactive shell ignores SIGINT, and its children would inherit that
    proc = subprocess.Popen([sys.executable, "-m", "microfacet", "synth", str(out),
                             "--preset", "nd", "--size", "768x768", "--slices", "200"],
                            stderr=subprocess.PIPE, text=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and not list(tmp_path.glob(".big.partial-*/slices/0*")):
        time.sleep(0.05)
    assert list(tmp_path.glob(".big.partial-*")), "the writer never started"
    proc.send_signal(sig)
    err = proc.communicate(timeout=60)[1]
    assert proc.returncode == status, err
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1, err
    assert list(tmp_path.iterdir()) == []


@pytest.mark.slow
def test_kill_9_leaves_leftovers_that_the_next_run_removes(tmp_path):
    out = tmp_path / "big"
    proc = subprocess.Popen([sys.executable, "-m", "microfacet", "synth", str(out),
                             "--preset", "nd", "--size", "512x512", "--slices", "200"],
                            stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and not list(tmp_path.glob(".big.partial-*/slices/0*")):
        time.sleep(0.05)
    proc.kill()
    proc.wait()
    assert list(tmp_path.glob(".big.*"))          # what kill -9 leaves behind
    assert main(["synth", str(out), "--preset", "sd", "--size", "64x64", "--slices", "4",
                 "-q"]) == 0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["big"]


# ------------------------------------------------------------------- resource blow-ups
@pytest.mark.parametrize("make, where", [
    (lambda: _png(30000, 30000), "png"),
    (lambda: _png(50000, 50000, colour_type=6), "png"),
    (lambda: _jpeg(40000, 40000), "jpg"),
    (lambda: _tiff(30000, 30000), "tif"),
])
@pytest.mark.slow
def test_headers_claiming_huge_images_are_refused_before_decoding(tmp_path, make, where):
    s = tmp_path / "s"
    (s / "slices").mkdir(parents=True)
    data = make()
    names = []
    for i in range(N):
        name = f"slices/{i:03d}.{where}"
        (s / name).write_bytes(data)
        names.append(name)
    (s / "stack.json").write_text(json.dumps({"format": "microfacet-stack/1",
                                              "pixel_size_um": 0.2, "z_step_um": 1,
                                              "slices": names}))
    assert sum(p.stat().st_size for p in s.rglob("*")) < 100_000   # a small file
    before = _digest(s)
    status, err, peak = _run_bounded(tmp_path, ["analyze", str(s), "--out",
                                                str(tmp_path / "out")])
    assert status == 2
    _assert_one_line(err, r"slices'\[0\] \(000\.\w+\): \d+x\d+ pixels .*limit of 50 MP.*"
                          r"--max-megapixels")
    assert peak < RSS_BOUND_MB, peak
    assert not (tmp_path / "out").exists() and _digest(s) == before


@pytest.mark.slow
def test_raising_the_pixel_limit_still_checks_memory_before_decoding(tmp_path):
    s = tmp_path / "s"
    (s / "slices").mkdir(parents=True)
    names = []
    for i in range(N):
        (s / f"slices/{i}.png").write_bytes(_png(200000, 200000))
        names.append(f"slices/{i}.png")
    (s / "stack.json").write_text(json.dumps({"format": "microfacet-stack/1",
                                              "pixel_size_um": 0.2, "z_step_um": 1,
                                              "slices": names}))
    status, err, peak = _run_bounded(tmp_path, ["analyze", str(s), "--out", str(tmp_path / "o"),
                                                "--max-megapixels", "1e6",
                                                "--max-stack-megapixels", "1e9"])
    assert status == 2
    _assert_one_line(err, r"stack\.json: analysing 200000x200000-pixel images needs about "
                          r"[\d,]+ MB of memory; this machine has")
    assert peak < RSS_BOUND_MB


def test_a_stack_over_the_stack_limit_is_refused(tmp_path, capfd):
    s = _stack(tmp_path / "s")
    line = _err_line(capfd, main(["height", str(s), "--out", str(tmp_path / "o"),
                                  "--max-stack-megapixels", "0.005"]))
    assert "5 slices of 48x48 pixels" in line and "--max-stack-megapixels" in line


def test_an_export_height_map_claiming_a_huge_shape_is_refused(tmp_path, capfd):
    s = tmp_path / "s"
    s.mkdir()
    with open(s / "h.npy", "wb") as fh:    # header + a sparse file of the claimed size
        np.lib.format.write_array_header_1_0(fh, {"descr": "<f4", "fortran_order": False,
                                                  "shape": (30000, 30000)})
        fh.truncate(fh.tell() + 30000 * 30000 * 4)
    (s / "img.png").write_bytes(_png(30000, 30000))
    (s / "stack.json").write_text(json.dumps({"format": "microfacet-stack/1",
                                              "pixel_size_um": 0.2, "height_um": "h.npy",
                                              "image": "img.png"}))
    line = _err_line(capfd, main(["analyze", str(s), "--out", str(tmp_path / "o")]))
    assert "key 'height_um' (h.npy): 30000x30000 pixels" in line


@pytest.mark.parametrize("argv, pattern", [
    (["simulate", "--thickness-mixture", "1:130:1e9", "--ndf-lobes", "1:5"],
     r"--thickness-mixture: sd_nm must be <= 1000"),
    (["simulate", "--thickness-mixture", "0.5:130:0.01,0.5:1000:1000", "--ndf-lobes", "1:5"],
     r"--thickness-mixture: the mixture spans .* quadrature nodes, more than the limit"),
    (["simulate", "--thickness-nm", "51", "--ndf-lobes", "1:5", "--spectral-step-nm", "0.001"],
     r"--spectral-step-nm: must be in \[0\.5, 20\]"),
    (["simulate", "--thickness-nm", "51", "--theta-step-deg", "1e-4"],
     r"--theta-step-deg: must be >= 0\.05"),
    (["simulate", "--thickness-nm", "51", "--ndf-lobes", "1:5", "--model", "eq6",
      "--theta-step-deg", "0.05", "--spectral-step-nm", "0.5"],
     r"1701 x 1701 angles x 801 wavelengths .*needs about [\d,]+ MB of memory"),
    (["simulate", "--thickness-nm", "51", "--exposure", "1e300"], r"--exposure: must be in"),
    (["simulate", "--thickness-nm", "51", "--exposure", "1e-300"], r"--exposure: must be in"),
    (["simulate", "--thickness-nm", "51", "--ndf-lobes", "1:5", "--model", "eq6",
      "--lobe-exponent", "1e12"], r"--lobe-exponent: must be in \[0, 1e\+06\]"),
    (["fit-spectrum", "{csv}", "--thickness-range-nm", "0:1e7"],
     r"--thickness-range-nm: need 0 <= low < high <= 10000"),
])
@pytest.mark.slow
def test_option_caps_refuse_before_allocating(tmp_path, argv, pattern):
    csv = tmp_path / "r.csv"
    csv.write_text("wavelength_nm,reflectance\n" + "".join(
        f"{w},{0.3 + 0.1 * np.sin(w / 30):.4f}\n" for w in range(400, 701, 5)))
    argv = [a.replace("{csv}", str(csv)) for a in argv]
    if argv[0] == "simulate":
        argv += ["--out", str(tmp_path / "sim")]
    status, err, peak = _run_bounded(tmp_path, argv)
    assert status == 2, err
    _assert_one_line(err, pattern)
    assert peak < RSS_BOUND_MB, peak
    assert not (tmp_path / "sim").exists()


@pytest.mark.slow
def test_a_2_million_row_spectrum_is_refused_while_reading(tmp_path):
    csv = tmp_path / "huge.csv"
    with open(csv, "w") as fh:
        fh.write("wavelength_nm,reflectance\n")
        fh.write("500,0.3\n" * 2_000_000)
    status, err, peak = _run_bounded(tmp_path, ["fit-spectrum", str(csv)])
    assert status == 2
    _assert_one_line(err, r"huge\.csv: more than 100,000 rows")
    assert peak < RSS_BOUND_MB


@pytest.mark.slow
def test_multi_page_tiff_is_read_in_one_pass(tmp_path, monkeypatch):
    """Reading every page opens the file once (``imread(key=i)`` per page re-walks the page
    chain: quadratic in the number of pages)."""
    import tifffile

    s = tmp_path / "s"
    rng = np.random.default_rng(0)
    write_stack(s, (rng.integers(0, 256, (8, 8), dtype=np.uint8) for _ in range(300)),
                z_step_um=0.1, pixel_size_um=1.0, multipage=True)
    opened = []
    real = tifffile.TiffFile.__init__

    def counting(self, *a, **k):
        opened.append(1)
        real(self, *a, **k)

    monkeypatch.setattr(tifffile.TiffFile, "__init__", counting)
    st = read_stack(s)
    images = [im for _, _, im in st.iter_slices(order="z")]
    assert len(images) == 300 and len(opened) == 2     # validation, then one reading pass
    assert images[7][0, 0] == pytest.approx(
        tifffile.imread(s / "stack.tif", key=7)[0, 0] / 255)


# --------------------------------------------------------- tracebacks instead of one line
def test_read_only_output_folder_is_one_line_before_the_work(tmp_path, capfd, monkeypatch):
    s = _stack(tmp_path / "s")
    real_open = os.open

    def ro(path, *a, **k):
        if str(path).endswith(".lock"):
            raise OSError(errno.EROFS, "Read-only file system", str(path))
        return real_open(path, *a, **k)

    import microfacet.io.outdir as outdir

    monkeypatch.setattr(outdir.os, "open", ro)
    line = _err_line(capfd, main(["analyze", str(s), "--out", str(tmp_path / "ro" / "o")]))
    assert "--out" in line and "Read-only file system" in line


def test_full_disk_is_one_line_before_the_work(tmp_path, capfd, monkeypatch):
    import shutil

    import microfacet.io.outdir as outdir

    s = _stack(tmp_path / "s")
    monkeypatch.setattr(outdir.shutil, "disk_usage",
                        lambda p: shutil._ntuple_diskusage(10 << 30, 10 << 30, 1 << 20))
    line = _err_line(capfd, main(["analyze", str(s), "--out", str(tmp_path / "o")]))
    assert "--out" in line and "MB are free on that disk" in line
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s"]


@pytest.mark.slow
def test_disk_full_while_writing_leaves_nothing(tmp_path, capfd, monkeypatch):
    import microfacet.io.results as results

    s = _stack(tmp_path / "s")
    calls = []
    real_save = np.save

    def save(path, arr, *a, **k):
        calls.append(path)
        if len(calls) == 3:
            raise OSError(errno.ENOSPC, "No space left on device", str(path))
        return real_save(path, arr, *a, **k)

    monkeypatch.setattr(results.np, "save", save)
    line = _err_line(capfd, main(["analyze", str(s), "--out", str(tmp_path / "o"),
                                  "--no-report", "--roi-size-px", "16"]))
    assert "No space left on device" in line
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s"]


def test_symlink_loop_among_the_slices(tmp_path, capfd):
    s = _stack(tmp_path / "s")
    (s / "slices/002.png").unlink()
    os.symlink("loop.png", s / "slices/002.png")
    os.symlink("002.png", s / "slices/loop.png")
    line = _err_line(capfd, main(["height", str(s), "--out", str(tmp_path / "o")]))
    assert "key 'slices'[2]" in line and "cannot be opened" in line


@pytest.mark.parametrize("text, pattern", [
    ("[" * 100_000 + "]" * 100_000, r"stack\.json: nested too deeply"),
    ('{"format": "microfacet-stack/1", "pixel_size_um": 1' + "0" * 400 + "}",
     r"key 'pixel_size_um': must be a finite number > 0, got inf"),
    ('{"format": "microfacet-stack/1", "pixel_size_um": 0.2, "pixel_size_um": 5}',
     r"stack\.json: key 'pixel_size_um' is given twice"),
])
def test_pathological_json(tmp_path, capfd, text, pattern):
    s = _stack(tmp_path / "s")
    (s / "stack.json").write_text(text)
    line = _err_line(capfd, main(["analyze", str(s), "--out", str(tmp_path / "o")]))
    assert re.search(pattern, line), line


def test_memory_error_is_one_line(tmp_path, capfd, monkeypatch):
    import microfacet.workflow.analyse as runner

    def boom(*a, **k):
        raise MemoryError()

    monkeypatch.setattr(runner, "run_stages", boom)
    s = _stack(tmp_path / "s")
    line = _err_line(capfd, main(["analyze", str(s), "--out", str(tmp_path / "o")]))
    assert "out of memory" in line
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s"]


def test_an_internal_error_is_one_line_with_exit_1_and_a_hint(tmp_path, capfd, monkeypatch):
    import microfacet.workflow.analyse as runner

    def bug(*a, **k):
        raise TypeError("unsupported operand")

    monkeypatch.setattr(runner, "run_stages", bug)
    s = _stack(tmp_path / "s")
    cap_status = main(["analyze", str(s), "--out", str(tmp_path / "o")])
    err = capfd.readouterr().err
    assert cap_status == 1 and len(err.strip().splitlines()) == 1
    assert "internal error: TypeError: unsupported operand" in err and "-v" in err
    with pytest.raises(TypeError):                        # -v shows the traceback
        main(["analyze", str(s), "--out", str(tmp_path / "o"), "-v"])


def test_bad_options_are_one_line_too(capfd):
    line = _err_line(capfd, main(["analyze", "s", "--out", "o", "--roi-size-px", "many"]))
    assert "--roi-size-px" in line and "see microfacet analyze --help" in line


# ---------------------------------------------------------------- silent wrong answers
def test_z_in_nanometres_is_warned(tmp_path, caplog):
    s = _stack(tmp_path / "s")
    _edit(s, z_step_um=500.0)
    read_stack(s)
    assert "key 'z_um': the slices span 2000 µm, more than the field of view" in caplog.text


@pytest.mark.parametrize("ps", [1e-9, 1e9])
def test_absurd_pixel_size_is_warned(tmp_path, caplog, ps):
    s = _stack(tmp_path / "s")
    _edit(s, pixel_size_um=ps)
    read_stack(s)
    assert "key 'pixel_size_um'" in caplog.text and "check the unit" in caplog.text


def test_export_height_in_nanometres_is_warned(tmp_path, caplog):
    s = tmp_path / "s"
    s.mkdir()
    yy, xx = np.mgrid[0:H, 0:W]
    np.save(s / "h.npy", (1000.0 * (0.1 * xx + 0.05 * yy)).astype(np.float32))  # nm, 0.25 µm px
    from microfacet.io.images import write_image

    write_image(s / "img.png", np.full((H, W, 3), 120, np.uint8))
    (s / "stack.json").write_text(json.dumps({"format": "microfacet-stack/1",
                                              "pixel_size_um": 0.25, "height_um": "h.npy",
                                              "image": "img.png"}))
    read_stack(s).read_export_height()
    assert "key 'height_um'" in caplog.text and "in nm" in caplog.text


def test_unknown_keys_are_warned_with_the_nearest_known_key(tmp_path, caplog):
    s = _stack(tmp_path / "s")
    _edit(s, colour_space="sRGB", illumination={"numerical_apperture": 0.5})
    read_stack(s)
    assert "unknown key 'colour_space'; did you mean 'color_space'?" in caplog.text
    assert "unknown key 'numerical_apperture'; did you mean 'numerical_aperture'?" in caplog.text


def test_spectrum_at_one_wavelength_is_refused_and_few_are_warned(tmp_path, capfd, caplog):
    csv = tmp_path / "s.csv"
    csv.write_text("wavelength_nm,reflectance\n" + "550,0.3\n" * 20)
    line = _err_line(capfd, main(["fit-spectrum", str(csv)]))
    assert re.search(r"1 distinct wavelength\(s\) in 20 rows", line), line
    from microfacet.io.spectrum import read_spectrum_csv

    csv.write_text("wavelength_nm,reflectance\n450,0.3\n550,0.2\n650,0.4\n650,0.41\n")
    assert read_spectrum_csv(csv)[0].size == 4
    assert "only 3 distinct wavelengths" in caplog.text


def test_percent_reflectances_below_1_5_are_warned(tmp_path, caplog):
    from microfacet.io.spectrum import read_spectrum_csv

    csv = tmp_path / "dark.csv"
    csv.write_text("wavelength_nm,reflectance\n" + "".join(   # 0.4-1.2, in percent
        f"{w},{0.8 + 0.4 * np.sin(w / 40):.4f}\n" for w in range(400, 701, 10)))
    wl, r = read_spectrum_csv(csv)
    assert r.max() == pytest.approx(0.012, abs=1e-4)        # read as percent: no fraction > 1
    assert "anodized titanium reflects 20-60 %" in caplog.text


@pytest.mark.parametrize("argv, pattern", [
    (["simulate", "--thickness-nm", "51", "--ndf-lobes", "1:8", "--exposure", "1e300"],
     r"--exposure: must be in \[1e-06, 1e\+06\], got 1e\+300"),
    (["simulate", "--thickness-nm", "51", "--ndf-lobes", "1:8", "--model", "eq6",
      "--lobe-exponent", "1e12"], r"--lobe-exponent: must be in \[0, 1e\+06\]"),
])
def test_values_that_make_every_output_inf_or_zero_are_refused(tmp_path, capfd, argv,
                                                                pattern):
    line = _err_line(capfd, main(argv + ["--out", str(tmp_path / "sim")]))
    assert re.search(pattern, line), line
    assert not (tmp_path / "sim").exists()


# ---------------------------------------------------- messages pointing at the culprit
def test_grey_export_image_blames_the_image_before_any_work(tmp_path, capfd):
    s = tmp_path / "s"
    s.mkdir()
    np.save(s / "h.npy", np.zeros((H, W), np.float32))
    from microfacet.io.images import write_image

    write_image(s / "img.png", np.full((H, W), 120, np.uint8))
    (s / "stack.json").write_text(json.dumps({"format": "microfacet-stack/1",
                                              "pixel_size_um": 0.25, "height_um": "h.npy",
                                              "image": "img.png"}))
    line = _err_line(capfd, main(["analyze", str(s), "--out", str(tmp_path / "o")]))
    assert "key 'image': grey images" in line


def test_grey_alpha_png_slices_are_read(tmp_path):
    s = tmp_path / "s"
    (s / "slices").mkdir(parents=True)
    names = []
    for i in range(4):
        line = bytes(v for x in range(16) for v in ((i * 40 + x) % 256, 200))  # grey, alpha
        rows = (b"\x00" + line) * 12
        (s / f"slices/{i}.png").write_bytes(_png(16, 12, colour_type=4, rows=rows))
        names.append(f"slices/{i}.png")
    (s / "stack.json").write_text(json.dumps({"format": "microfacet-stack/1",
                                              "pixel_size_um": 0.2, "z_step_um": 1,
                                              "slices": names}))
    st = read_stack(s)
    img = st.read_slice(2, np.uint8)
    assert st.channels == 1 and img.shape == (12, 16)
    assert img[0, :3].tolist() == [80, 81, 82]


def test_nul_byte_and_newline_in_paths_stay_one_line(tmp_path, capfd):
    s = _stack(tmp_path / "st\nack")
    line = _err_line(capfd, main(["height", str(tmp_path / "no\x00pe"), "--out",
                                  str(tmp_path / "o")]))
    assert "NUL byte" in line
    line = _err_line(capfd, main(["height", str(s), "--out", str(tmp_path / "o\nut")]))
    assert "--out" in line and "control character" in line and "\\n" in line
    (s / "stack.json").write_text("{")
    line = _err_line(capfd, main(["height", str(s), "--out", str(tmp_path / "o")]))
    assert "st\\nack/stack.json: invalid JSON" in line


def test_utf8_bom_in_stack_json_and_csv_is_accepted(tmp_path):
    s = _stack(tmp_path / "s")
    (s / "stack.json").write_bytes(b"\xef\xbb\xbf" + (s / "stack.json").read_bytes())
    assert read_stack(s).n_slices == N
    from microfacet.io.spectrum import read_spectrum_csv

    csv = tmp_path / "excel.csv"
    csv.write_bytes(b"\xef\xbb\xbfwavelength_nm,reflectance\r\n" + b"".join(
        f"{w},{0.3 + 0.001 * w}\r\n".encode() for w in range(400, 701, 10)))
    wl, r = read_spectrum_csv(csv)
    assert wl.size == 31 and r[0] == pytest.approx(0.7)
