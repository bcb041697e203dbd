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

from dataclasses import dataclass

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


@dataclass(frozen=True)
class NoiseFloor:
    """The white-noise floor of one run.

    Attributes
    ----------
    noise_density_m_s2_rthz : float
        Density used for the bound. [m/s^2/sqrt(Hz)]
    source : str
        ``"sensor"`` (the recording states it) or ``"residual"`` (estimated).
    residual_density_m_s2_rthz : float
        Density estimated from the data, whatever the source. [m/s^2/sqrt(Hz)]
    crb_rad : float
        Cramér-Rao bound on ``theta_y - theta_x`` at that density. [rad]
    """

    noise_density_m_s2_rthz: float
    source: str
    residual_density_m_s2_rthz: float
    crb_rad: float


def noise_floor(filtered, segmentation, sensor, amplitude_m_s2, analysed_s, cutoff_hz, order):
    """Noise density and Cramér-Rao bound of one run.

    The density is the sensor's stated one when the recording knows it, else
    the one estimated from what the low-pass removes in the steady middle of
    the first block (away from the ramps' transients).

    Parameters
    ----------
    filtered : FilteredRecording
        The samples, raw and low-passed.
    segmentation : Segmentation
        The blocks found.
    sensor : SensorInfo
        What the recording says of the sensor.
    amplitude_m_s2 : float
        Amplitude of the acceleration sinusoids. [m/s^2]
    analysed_s : float
        Analysed time, both directions together. [s]
    cutoff_hz : float
        Cutoff of the designed low-pass. [Hz]
    order : int
        Order of the designed low-pass.

    Returns
    -------
    NoiseFloor
    """
    prog = segmentation.program
    first = segmentation.blocks[0]
    t_s = filtered.t_s
    half = 0.45 * prog.cycles_per_direction * segmentation.period_s
    sel = np.abs(t_s - first.t_mid_s) < half
    residual = residual_noise_density(
        filtered.raw[sel, :2], cutoff_hz, order, filtered.sample_rate_hz
    )
    stated = sensor.noise_density_m_s2_rthz
    if np.isfinite(stated) and stated > 0:
        density, source = float(stated), "sensor"
    else:
        density, source = residual, "residual"
    return NoiseFloor(density, source, residual, cramer_rao(density, amplitude_m_s2, analysed_s))
