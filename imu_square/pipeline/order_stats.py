"""Medians and quantiles by one partial sort, equal to numpy's.

``np.median`` and ``np.quantile`` partition around extra positions (the last
one, to detect NaN) and, along axis 0 of an ``(n, 2)`` array, work on strided
data; on the pipeline's 100k-sample records that makes them 5 to 30 times
slower than one ``np.partition``. These give the same numbers, bit for bit
(the same order statistics, averaged or interpolated by the same formulas as
numpy 2: ``tests/test_pipeline_speedups.py`` holds them to it), NaN included.
"""

import numpy as np


def median(values):
    """Median of a 1-D array, as ``np.median``.

    Parameters
    ----------
    values : ndarray, shape (n,)
        Any values. [any unit]

    Returns
    -------
    float
        The middle value, or the mean of the two middle ones; NaN if any is NaN
        or none is given. [same unit]
    """
    a = np.asarray(values, dtype=np.float64)
    if a.size == 0:
        return float("nan")
    k = a.size // 2
    part = np.partition(a, k)
    if np.isnan(part[k:]).any():  # NaN sorts last: any one lies at or above k
        return float("nan")
    if a.size % 2:
        return float(part[k])
    return float(np.mean([part[:k].max(), part[k]]))


def column_medians(values):
    """Median of each column of a 2-D array, as ``np.median(values, axis=0)``.

    Parameters
    ----------
    values : ndarray, shape (n, n_columns)
        Any values, at least one row. [any unit]

    Returns
    -------
    ndarray, shape (n_columns,)
        [same unit]
    """
    a = np.asarray(values, dtype=np.float64)
    return np.array([median(a[:, j]) for j in range(a.shape[1])])


def row_medians(values, overwrite_input=False):
    """Median of each row of a 2-D array, as ``np.median(values, axis=-1)``.

    One partition around the upper middle and the maximum below it: numpy
    partitions every row around two or three positions, six times slower.

    Parameters
    ----------
    values : ndarray, shape (n_rows, n)
        Any values, at least one per row. [any unit]
    overwrite_input : bool
        Partition ``values`` itself (a float64 array; its order is lost, not
        its values), as ``np.median``'s option: no copy.

    Returns
    -------
    ndarray, shape (n_rows,)
        NaN for a row holding a NaN. [same unit]
    """
    a = np.asarray(values, dtype=np.float64)
    k = a.shape[-1] // 2
    if overwrite_input:
        a.partition(k, axis=-1)
        part = a
    else:
        part = np.partition(a, k, axis=-1)
    upper = part[..., k]
    mid = upper if a.shape[-1] % 2 else (part[..., :k].max(axis=-1) + upper) / 2
    # NaN sorts last, and max propagates it: one reduction, no boolean temporary
    return np.where(np.isnan(part[..., k:].max(axis=-1)), np.nan, mid)


def quantile(values, q):
    """The ``q`` quantile of a 1-D array, as ``np.quantile(values, q)`` (linear method).

    Parameters
    ----------
    values : ndarray, shape (n,)
        Any values, at least one. [any unit]
    q : float
        Probability, in [0, 1].

    Returns
    -------
    float
        Linear interpolation between the order statistics around ``q (n - 1)``;
        NaN if any value is NaN. [same unit]
    """
    a = np.asarray(values, dtype=np.float64)
    virtual = (a.size - 1) * q
    lo = int(np.floor(virtual))
    hi = min(lo + 1, a.size - 1)
    part = np.partition(a, lo)
    if np.isnan(part[lo:]).any():
        return float("nan")
    below, above = part[lo], part[lo:][1:].min() if hi > lo else part[lo]
    gamma = virtual - lo
    diff = above - below
    # numpy's _lerp: from the nearer end, so that gamma = 1 gives ``above`` exactly
    return float(above - diff * (1 - gamma) if gamma >= 0.5 else below + diff * gamma)
