"""BLAS on one thread while the analysis runs.

The analysis solves many small systems (robust fits of a few parameters, 6 x 6
normal equations, integral equations of 50-400 unknowns for the alarm
design): OpenBLAS's threads only add overhead there, and on a loaded machine
far more (two replay workers on two cores, each with a thread per core: 1.9
instead of 3.2 files a second; ``benchmarks/per_file.py --trick blas``).
:func:`one_blas_thread` limits every BLAS library loaded (numpy's and scipy's
own OpenBLAS) by ``threadpoolctl`` for the span of a call, and gives the
caller's setting back afterwards.
"""

import contextlib
import functools


@functools.cache
def _controller():
    # threadpoolctl sees only the libraries loaded when it looks: load both first.
    import numpy  # noqa: F401
    import scipy.linalg  # noqa: F401
    from threadpoolctl import ThreadpoolController

    return ThreadpoolController()


@contextlib.contextmanager
def one_blas_thread():
    """Run the body (a ``with`` block, or a function so decorated) with single-threaded BLAS.

    Every BLAS library is limited to one thread on entry and given its
    setting back on exit.
    """
    with _controller().limit(limits=1, user_api="blas"):
        yield
