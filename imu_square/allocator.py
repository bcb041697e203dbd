"""glibc's malloc told to keep freed memory for reuse, in the processes that analyse files.

The analysis of one recording makes hundreds of temporary arrays of 0.1-5 MB.
glibc serves such blocks with ``mmap`` and gives them back with ``munmap``
when they are freed (above ``M_MMAP_THRESHOLD``, 128 kB at first, raised as
blocks are freed), and trims the heap's free top (above ``M_TRIM_THRESHOLD``),
so the next array's pages fault in afresh: about a tenth of the per-file time
on a virtual machine (``benchmarks/per_file.py --allocator``). With both
thresholds raised (32 MB and 128 MB) freed blocks stay in the heap and the
next array reuses their pages; a process then holds up to 128 MB of freed
memory more than it would, which a worker busy with files uses again at once.

:func:`tune_allocator` does it once, for glibc only (``mallopt``, through
``ctypes``), in the processes the package runs files in: the ``analyze`` and
``replay`` commands, the replay's worker processes and its Dask tasks. The
library never calls it on import: a user's own process keeps its allocator.
``IMU_SQUARE_MALLOC_TUNING=0`` (or ``false``, ``no``, ``off``) in the environment
leaves glibc's defaults, and so does a value that is none of these nor ``1``
(with a warning).
"""

import ctypes
import os

from imu_square.log import logger

MMAP_THRESHOLD_BYTES = 32 * 1024 * 1024
TRIM_THRESHOLD_BYTES = 128 * 1024 * 1024
_M_TRIM_THRESHOLD = -1  # <malloc.h>
_M_MMAP_THRESHOLD = -3
_OPT_OUT = "IMU_SQUARE_MALLOC_TUNING"
_OFF = ("0", "false", "no", "off")
_ON = ("1", "true", "yes", "on", "")

_state = {"applied": None}


def tune_allocator():
    """Raise glibc's mmap and trim thresholds in this process, once.

    Returns
    -------
    bool
        True if the thresholds are set (now or by an earlier call); False on
        another C library, where ``mallopt`` refuses, or when
        ``IMU_SQUARE_MALLOC_TUNING=0``.
    """
    if _state["applied"] is not None:
        return _state["applied"]
    _state["applied"] = _apply()
    return _state["applied"]


def _apply():
    setting = os.environ.get(_OPT_OUT, "1").strip().lower()
    if setting in _OFF:
        logger.debug("allocator: %s=%s, glibc's defaults kept", _OPT_OUT, setting)
        return False
    if setting not in _ON:  # set, so meant to change something: the safe side is no change
        logger.warning(
            "allocator: %s must be 0 or 1, got %r: glibc's defaults kept",
            _OPT_OUT,
            os.environ[_OPT_OUT],
        )
        return False
    if not _is_glibc():
        return False
    try:
        mallopt = ctypes.CDLL(None).mallopt
    except (OSError, AttributeError):
        return False
    mallopt.argtypes = (ctypes.c_int, ctypes.c_int)
    mallopt.restype = ctypes.c_int
    # mallopt returns 1 on success, 0 on error
    ok = mallopt(_M_MMAP_THRESHOLD, MMAP_THRESHOLD_BYTES) == 1
    ok = ok and mallopt(_M_TRIM_THRESHOLD, TRIM_THRESHOLD_BYTES) == 1
    logger.debug(
        "allocator: glibc mmap threshold %d B, trim threshold %d B: %s",
        MMAP_THRESHOLD_BYTES,
        TRIM_THRESHOLD_BYTES,
        "set" if ok else "refused",
    )
    return ok


def _is_glibc():
    try:
        return bool(os.confstr("CS_GNU_LIBC_VERSION"))  # glibc's own name; None or error elsewhere
    except (AttributeError, ValueError, OSError):
        return False
