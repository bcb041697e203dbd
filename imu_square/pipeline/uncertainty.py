"""Uncertainty of the squareness: scatter over cycles, bootstrap, Cramér-Rao bound.

Three figures, each answering a different question:

- type A from the per-cycle scatter: the standard deviation of the paired
  per-cycle values over the square root of the number of pairs (GUM type A),
  expanded by Student's t for its degrees of freedom (:func:`coverage_factor`);
- bootstrap over cycles: resample whole cycles with replacement within each
  direction, redo the average and the fit, take the standard deviation;
- the Cramér-Rao bound ``sqrt(2) d / (A sqrt(T))`` (``docs/model.md``), the
  least standard deviation any unbiased estimator can reach with white noise
  of density ``d`` on each axis, amplitude ``A`` and analysed time ``T``
  (:mod:`imu_square.pipeline.noise_floor` estimates ``d`` and the 1/f part).
"""

import numpy as np
from scipy import stats


def type_a(values):
    """Standard uncertainty of the mean of ``values`` (GUM type A).

    Parameters
    ----------
    values : ndarray, shape (n,)
        Per-cycle values. [any unit]

    Returns
    -------
    float
        ``std(values, ddof=1) / sqrt(n)``, NaN for fewer than two values. [unit of values]
    """
    values = np.asarray(values, dtype=np.float64)
    if values.size < 2:
        return float("nan")
    return float(np.std(values, ddof=1) / np.sqrt(values.size))


def coverage_factor(dof, probability=0.95):
    """Coverage factor of a type A uncertainty with few degrees of freedom (GUM G.3).

    Parameters
    ----------
    dof : int
        Degrees of freedom of the standard uncertainty (cycle pairs minus one).
    probability : float
        Coverage probability, e.g. 0.95.

    Returns
    -------
    float
        Student's t quantile ``t_{(1 + p) / 2, dof}``: the mean lies within
        ``k u`` of the truth with probability ``p`` when the scatter is white
        and Gaussian (2.14 for 14 dof, 4.30 for 2 at 95 %); NaN below one dof.
    """
    if dof < 1:
        return float("nan")
    return float(stats.t.ppf(0.5 + probability / 2, dof))


def bootstrap_counts(n_cycles, n_boot, rng):
    """How often each cycle is drawn in each resample with replacement.

    Parameters
    ----------
    n_cycles : int
        Cycles to resample.
    n_boot : int
        Number of resamples.
    rng : numpy.random.Generator
        Random source.

    Returns
    -------
    ndarray, shape (n_boot, n_cycles)
        Draw counts; each row sums to ``n_cycles``.
    """
    counts = np.zeros((n_boot, n_cycles))
    idx = rng.integers(0, n_cycles, size=(n_boot, n_cycles))
    np.add.at(counts, (np.arange(n_boot)[:, None], idx), 1.0)
    return counts


def cramer_rao(noise_density_m_s2_rthz, amplitude_m_s2, analysed_s):
    """Cramér-Rao bound on the standard deviation of ``theta_y - theta_x``.

    Parameters
    ----------
    noise_density_m_s2_rthz : float
        White-noise density per axis (one-sided). [m/s^2/sqrt(Hz)]
    amplitude_m_s2 : float
        Amplitude of the acceleration sinusoids, ``v^2/r``. [m/s^2]
    analysed_s : float
        Analysed time, both directions together. [s]

    Returns
    -------
    float
        ``sqrt(2) d / (A sqrt(T))``. [rad]
    """
    return float(np.sqrt(2) * noise_density_m_s2_rthz / (amplitude_m_s2 * np.sqrt(analysed_s)))
