"""Store colour-science's tables and weights with the package (``microfacet/data/
colour_science.npz``, :mod:`microfacet.colour.snapshot`), so that an analysis does not import
colour-science (0.78 s, docs/colour-benchmarks.md).

    python -m pipelines.colour_snapshot

Run it after upgrading colour-science when tests/colour/test_snapshot.py reports that the
stored tables differ from the installed version's; it prints what it stored.
"""

from __future__ import annotations

from microfacet.colour.snapshot import SNAPSHOT_PATH, write_snapshot


def main() -> None:
    tables = write_snapshot(SNAPSHOT_PATH)
    print(f"{SNAPSHOT_PATH}: colour-science {tables.colour_version}, "
          f"{len(tables.illuminant_names)} illuminants, {len(tables.cmf)} observers, "
          f"{len(tables.weights)} weight grids, {SNAPSHOT_PATH.stat().st_size / 1e3:.0f} kB")


if __name__ == "__main__":
    main()
