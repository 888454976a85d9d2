"""Keep what compiled libraries print off the process's standard output.

Some compiled code writes to file descriptor 1 directly, past `sys.stdout`: highspy's banner
when the first `Highs` object is built, and the BLAS error handler that SuperLU reaches on a
numerically singular matrix ("On entry to DTRSV parameter number 6 had an illegal value";
SuperLU then fails, and `calippso.certification.sparse_lu.factorize` reports the matrix as singular). The
command line writes its results (``--json``) to standard output, which must carry nothing
else, so these calls run with descriptor 1 pointed elsewhere.
"""

from __future__ import annotations

import contextlib
import os
import sys
from collections.abc import Iterator

__all__ = ["c_stdout_to_devnull", "c_stdout_to_stderr"]


@contextlib.contextmanager
def _descriptor_1_to(target: int | None) -> Iterator[None]:
    """Point file descriptor 1 at `target` (a descriptor; None: the null device) for the
    duration; a no-op where descriptor 1 cannot be duplicated."""
    try:
        sys.stdout.flush()
        saved = os.dup(1)
    except (OSError, ValueError, AttributeError):
        yield
        return
    try:
        if target is None:
            with open(os.devnull, "w") as null:
                os.dup2(null.fileno(), 1)
        else:
            os.dup2(target, 1)
        yield
    finally:
        os.dup2(saved, 1)
        os.close(saved)


def c_stdout_to_devnull() -> contextlib.AbstractContextManager[None]:
    """Discard what compiled code prints to file descriptor 1 (a banner nobody asked for)."""
    return _descriptor_1_to(None)


def c_stdout_to_stderr() -> contextlib.AbstractContextManager[None]:
    """Send what compiled code prints to file descriptor 1 to standard error instead (its
    diagnostics stay visible, standard output stays clean)."""
    try:
        sys.stderr.flush()
    except (ValueError, AttributeError):
        pass
    return _descriptor_1_to(2)
