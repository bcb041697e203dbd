"""Cosine and sine of many angles at once, by a table and short Taylor series.

numpy's float64 ``cos`` and ``sin`` are vectorised only on AVX-512 machines;
elsewhere they call libm sample by sample (about 20 ns each: 9 ms for the
~190k samples of a 200 s run at 1 kHz, cosine and sine). Here an angle ``x``
is split as ``k d + r`` with ``d = 2 pi / 1024`` and ``|r| <= d / 2``
(Cody-Waite: ``k d`` in two parts, the first exact), and
``cos x = cos(k d) cos r - sin(k d) sin r`` (and the like for ``sin x``), with
``cos(k d)``, ``sin(k d)`` from a table and ``cos r``, ``sin r`` from their
Taylor series to ``r^4`` and ``r^5``, whose next terms are below 2e-18. About
twenty whole-array operations: three to four times faster than numpy's loop
here (on an AVX-512 machine numpy's own is faster). The results are within a
few ulps of numpy's (an ulp of the table entries and of the sums, and an ulp
of ``2 pi`` per whole turn of ``x``), not bit for bit.
"""

import numpy as np

_TABLE_SIZE = 1024  # a power of two: k mod the size is k & (size - 1)
_STEP = 2 * np.pi / _TABLE_SIZE  # fl(2 pi) / 1024, exactly
# The step in two parts, the first of 24 bits so that k times it is exact for |k| < 2^29,
# the second exact (Sterbenz: the two are within a factor two).
_STEP_HIGH = float(np.float32(_STEP))
_STEP_LOW = _STEP - _STEP_HIGH
_TABLE_COS = np.cos(_STEP * np.arange(_TABLE_SIZE))
_TABLE_SIN = np.sin(_STEP * np.arange(_TABLE_SIZE))


def cos_sin(x_rad, out=None):
    """``np.cos(x_rad)`` and ``np.sin(x_rad)`` to a few ulps, three to four times faster.

    Parameters
    ----------
    x_rad : ndarray, shape (n,)
        Angles, finite, ``|x| < 1e6`` (the error grows by an ulp of ``2 pi``
        per whole turn). [rad]
    out : tuple of two ndarray, shape (n,), optional
        Float64 arrays, neither of them ``x_rad``, that receive the cosine and
        the sine: a fresh array costs page faults.

    Returns
    -------
    cos, sin : ndarray, shape (n,)
        Within ``1e-15 + 2.5e-16 |x| / (2 pi)`` of numpy's. [1]
    """
    x = np.asarray(x_rad, dtype=np.float64)
    c, s = (np.empty_like(x), np.empty_like(x)) if out is None else out
    # Three temporaries besides c and s, which hold the intermediate steps: a fresh
    # array costs page faults, more than the arithmetic.
    np.multiply(x, 1.0 / _STEP, out=c)
    k = np.rint(c, out=c)
    index = k.astype(np.intp)
    index &= _TABLE_SIZE - 1
    r = np.multiply(k, _STEP_HIGH, out=s)
    np.subtract(x, r, out=r)
    r -= np.multiply(k, _STEP_LOW, out=c)  # r = x - k step, |r| <= step / 2
    r2 = np.square(r)
    # sin r = r (1 - r^2/3! + r^4/5!) into s (over r), cos r = 1 - r^2/2! + r^4/4! into c
    np.multiply(r2, 1.0 / 120.0, out=c)
    c -= 1.0 / 6.0
    c *= r2
    c += 1.0
    s *= c
    np.multiply(r2, 1.0 / 24.0, out=c)
    c -= 0.5
    c *= r2
    c += 1.0
    # cos x = Tc cos r - Ts sin r, sin x = Tc sin r + Ts cos r
    table_c = np.take(_TABLE_COS, index, out=r2, mode="wrap")  # unbuffered, unlike "raise"
    table_s = np.take(_TABLE_SIN, index, mode="wrap")
    ts_sin_r = np.multiply(table_s, s, out=index.view(np.float64))
    table_s *= c
    c *= table_c
    c -= ts_sin_r
    s *= table_c
    s += table_s
    return c, s
