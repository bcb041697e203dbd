"""Uncertainty of the squareness: scatter over cycles, bootstrap, Cramér-Rao bound.

Three figures, each answering a different question:

- type A from the per-cycle scatter: the standard deviation of the paired
  per-cycle values over the square root of the number of pairs (GUM type A);
- bootstrap over cycles: resample whole cycles with replacement within each
  direction, redo the average and the fit, take the standard deviation;
- the Cramér-Rao bound ``sqrt(2) d / (A sqrt(T))`` (``docs/model.md``), the
  least standard deviation any unbiased estimator can reach with white noise
  of density ``d`` on each axis, amplitude ``A`` and analysed time ``T``.
"""

import numpy as np

from imu_square.pipeline.filter import lowpass, noise_bandwidth_hz


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


def bootstrap_means(traces, n_boot, rng):
    """Means of ``traces`` over cycles resampled with replacement.

    Parameters
    ----------
    traces : ndarray, shape (n_cycles, n_grid)
        One direction's cycles on the phi grid. [m/s^2]
    n_boot : int
        Number of resamples.
    rng : numpy.random.Generator
        Random source.

    Returns
    -------
    ndarray, shape (n_boot, n_grid)
        The resampled mean traces. [m/s^2]
    """
    n = traces.shape[0]
    counts = np.zeros((n_boot, n))
    idx = rng.integers(0, n, size=(n_boot, n))
    np.add.at(counts, (np.arange(n_boot)[:, None], idx), 1.0)
    return counts @ traces / n


def cramer_rao(density_m_s2_rthz, amplitude_m_s2, analysed_s):
    """Cramér-Rao bound on the standard deviation of ``theta_y - theta_x``.

    Parameters
    ----------
    density_m_s2_rthz : float
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
    return float(np.sqrt(2) * density_m_s2_rthz / (amplitude_m_s2 * np.sqrt(analysed_s)))


def residual_noise_density(raw, cutoff_hz, order, sample_rate_hz):
    """White-noise density of ``raw`` from what a zero-phase low-pass removes.

    Parameters
    ----------
    raw : ndarray, shape (n_samples, n_axes)
        Unfiltered samples of a stretch without gaps. [m/s^2]
    cutoff_hz : float
        Cutoff of the designed filter. [Hz]
    order : int
        Order of the designed filter.
    sample_rate_hz : float
        Sample rate. [Hz]

    Returns
    -------
    float
        Noise density averaged over the axes; an overestimate if the data hold
        vibration above the cutoff. [m/s^2/sqrt(Hz)]
    """
    high = raw - lowpass(raw, cutoff_hz, order, sample_rate_hz)
    bandwidth = noise_bandwidth_hz(cutoff_hz, order, sample_rate_hz, highpass=True)
    sd = 1.4826 * np.median(np.abs(high - np.median(high, axis=0)), axis=0)
    return float(np.sqrt(np.mean(sd**2) / bandwidth))
