"""What every checkpoint needs: atomic file writes, and the digest that names a configuration.

Atomic writes go beside the target, are flushed to disk, then renamed into place: a process
killed at any moment leaves the previous file or the new one, never a torn file. The file
gets the permissions `open()` would give it: those of the file it replaces, or 0o666 less the
process umask for a new file (the temporary file itself is private).

`digest` identifies a configuration by its arrays, so that a checkpoint can refuse to
continue the run of another input.
"""

from __future__ import annotations

import hashlib
import os
import stat
import tempfile
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np

__all__ = ["atomic_path", "current_umask", "digest", "save_npz_atomic"]

#: Permissions `open()` asks for when it creates a file (the umask is then taken off).
NEW_FILE_MODE = 0o666
#: Where Linux (4.7 and later) tells a process its umask, on the line `_PROC_UMASK_FIELD`.
_PROC_STATUS = "/proc/self/status"
_PROC_UMASK_FIELD = "Umask:"
#: Umask set for an instant while the current one is read where /proc cannot tell it: the
#: most restrictive, so that a file another thread creates meanwhile is never too open.
_PROBE_UMASK = 0o077
_UMASK_LOCK = threading.Lock()


def current_umask() -> int:
    """The process umask, read without changing it where /proc/self/status tells it.

    Elsewhere the umask is swapped for `_PROBE_UMASK` and put back at once (under a lock).
    """
    try:
        with open(_PROC_STATUS, encoding="ascii") as status:
            for line in status:
                if line.startswith(_PROC_UMASK_FIELD):
                    return int(line.split()[1], 8)
    except (OSError, ValueError, IndexError):
        pass
    with _UMASK_LOCK:
        mask = os.umask(_PROBE_UMASK)
        os.umask(mask)
    return mask


def _final_mode(path: Path) -> int:
    """The permissions `open()` would leave `path` with: kept if it exists, else 0o666 & ~umask."""
    try:
        return stat.S_IMODE(path.stat().st_mode)
    except FileNotFoundError:
        return NEW_FILE_MODE & ~current_umask()


@contextmanager
def atomic_path(path: Path) -> Iterator[Path]:
    """Yield a temporary path in the target's folder; rename it to `path` on success.

    A crash or an exception inside the block removes the temporary file and leaves any
    existing `path` untouched. Before the rename the file gets the permissions `open()`
    would give it (`_final_mode`), not the private mode of the temporary file.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    handle, temporary = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    os.close(handle)
    try:
        yield Path(temporary)
        os.chmod(temporary, _final_mode(path))
        os.replace(temporary, path)
    except BaseException:
        Path(temporary).unlink(missing_ok=True)
        raise


def save_npz_atomic(path: str | os.PathLike, arrays: dict[str, np.ndarray]) -> None:
    """Write `arrays` to the `.npz` file `path` atomically, flushed to disk before the rename."""
    with atomic_path(Path(path)) as temporary:
        with open(temporary, "wb") as stream:
            np.savez(stream, **arrays)
            stream.flush()
            os.fsync(stream.fileno())


def digest(*arrays: np.ndarray) -> str:
    """SHA-256 of the shapes and float64 bytes of `arrays`, in order: identifies a configuration.

    Parameters
    ----------
    *arrays : array_like
        E.g. positions (N, d), diameters (N,) and box (d,); each is read as float64.

    Returns
    -------
    str
        64 hexadecimal digits.
    """
    h = hashlib.sha256()
    for array in arrays:
        array = np.ascontiguousarray(array, dtype=np.float64)
        h.update(str(array.shape).encode())
        h.update(array.tobytes())
    return h.hexdigest()
