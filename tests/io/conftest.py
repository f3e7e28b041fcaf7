"""Fixtures of the io tests: small random slices and a valid stack written in tmp_path."""

from __future__ import annotations

import subprocess
import sys
import textwrap

import numpy as np
import pytest

from microfacet.io.stack import write_stack

#: (H, W) of the images of :func:`random_images` (the test modules use 12 × 17 too).
SHAPE = (12, 17)


@pytest.fixture(scope="session")
def random_images():
    """``random_images(n, *, dtype=np.uint8, rgb=False, seed=0)``: ``n`` random 12×17 slices
    (grey or RGB) spanning the full range of ``dtype``."""
    def make(n, *, dtype=np.uint8, rgb=False, seed=0):
        rng = np.random.default_rng(seed)
        hi = 255 if dtype == np.uint8 else 65535
        shape = SHAPE + (3,) if rgb else SHAPE
        return [rng.integers(0, hi + 1, shape).astype(dtype) for _ in range(n)]
    return make


@pytest.fixture
def good_stack(tmp_path, random_images):
    """``good_stack(n=3, **write_stack_options)``: a valid stack ``tmp_path / "s"`` of ``n``
    random grey 8-bit slices, z step 1 µm, pixel 1 µm."""
    def make(n=3, **kw):
        d = tmp_path / "s"
        write_stack(d, random_images(n), z_step_um=1.0, pixel_size_um=1.0, **kw)
        return d
    return make


_HOLDER = textwrap.dedent("""
    import sys
    from pathlib import Path
    from microfacet.io.lock import acquire
    acquire(Path(sys.argv[1]), shown="the output")
    print("held", flush=True)
    sys.stdin.readline()        # hold until told (or killed)
""")


@pytest.fixture
def lock_holder():
    """``lock_holder(lock_path)``: start a live process that holds the lock of
    :mod:`microfacet.io.lock` at ``lock_path`` and return its ``Popen`` (write a line to its
    stdin to end it normally; killed at the end of the test)."""
    procs = []

    def start(path):
        p = subprocess.Popen([sys.executable, "-c", _HOLDER, str(path)], stdin=subprocess.PIPE,
                             stdout=subprocess.PIPE, text=True)
        procs.append(p)
        assert p.stdout.readline().strip() == "held"
        return p
    yield start
    for p in procs:
        if p.poll() is None:
            p.kill()
        p.wait(timeout=30)
