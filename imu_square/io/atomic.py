"""Atomic file replacement: a reader sees the old file or the new one, never half of one.

The new content goes to a temporary file in the same folder (a rename is only
atomic within one file system), is flushed to disk, and then replaces the
target with :func:`os.replace`; the folder is synced so the rename itself
survives a power cut. The temporary name starts with a dot and ends in
``.tmp``, so collectors that read only ``*.prom`` or ``*.json`` never pick it up.
"""

import contextlib
import os
import tempfile
from pathlib import Path


def fsync_dir(folder):
    """Flush a folder's entries (new names, renames, removals) to disk.

    Parameters
    ----------
    folder : str or Path
        The folder.
    """
    if not hasattr(os, "O_DIRECTORY"):  # Windows has no directory handles to sync
        return
    fd = os.open(folder, os.O_RDONLY | os.O_DIRECTORY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def write_atomic(path, data, mode=0o644):
    """Replace ``path`` with ``data`` atomically and durably.

    Parameters
    ----------
    path : str or Path
        The target file; its folder must exist.
    data : bytes
        The whole new content.
    mode : int
        Permission bits of the new file. The default 0o644 lets a collector
        running as another user (node_exporter, a dashboard) read it.

    Returns
    -------
    Path
        ``path``.
    """
    path = Path(path)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
            if hasattr(os, "fchmod"):
                os.fchmod(f.fileno(), mode)
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        raise
    fsync_dir(path.parent)
    return path
