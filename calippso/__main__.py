"""`python -m calippso`: jam the built-in example and print a summary."""

from __future__ import annotations

import sys
from importlib.resources import files


def main(argv: list[str] | None = None) -> int:
    """Jam the packaged example configuration (d = 3) and print what the jammed packing says."""
    import calippso

    example = files("calippso") / "data" / "example_d3_n512_ls.npz"
    packing = calippso.read(str(example))
    print(f"Input: {packing} (Lubachevsky-Stillinger at reduced pressure 1e5, built in)")
    result = calippso.jam(packing, verbose=True)
    print(result.summary())
    return 0 if result.converged and result.isostatic else 1


if __name__ == "__main__":
    sys.exit(main())
