"""`python -m calippso`: the ``calippso`` command; with no arguments, the demo."""

from __future__ import annotations

import sys

from .cli import main

if __name__ == "__main__":
    sys.exit(main(sys.argv[1:] or ["demo"]))
