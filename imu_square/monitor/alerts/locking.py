"""Advisory file locks (``flock``) between monitor processes on one machine.

Two ``nightly`` jobs may run at once on the same monitor file. The locks keep
them from appending to one JSON Lines file at the same time and from
delivering the same pending alert twice. They are released by the kernel when
a process dies, so a ``kill -9`` never leaves a stale lock. Where ``fcntl`` does
not exist (Windows) the locks do nothing: a pending alert may then be sent
twice, and receivers dedupe on its ``alert_id``.
"""

import contextlib
import os

try:
    import fcntl
except ImportError:  # Windows
    fcntl = None


def try_lock(fd):
    """Take an exclusive lock on an open file without waiting.

    Parameters
    ----------
    fd : int
        Open file descriptor.

    Returns
    -------
    bool
        True if this process now holds the lock, False if another one does.
    """
    if fcntl is None:
        return True
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        return False
    return True


@contextlib.contextmanager
def locked(path):
    """Hold an exclusive lock on ``path`` (created if missing), waiting for it.

    Parameters
    ----------
    path : str or Path
        The lock file.
    """
    fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
    try:
        if fcntl is not None:
            fcntl.flock(fd, fcntl.LOCK_EX)
        yield
    finally:
        os.close(fd)
