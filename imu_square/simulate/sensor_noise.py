"""Sensor noise and digitisation: white plus 1/f noise, ADC steps, clipping, float32.

White noise of one-sided density ``d`` at sample rate ``fs`` has a per-sample
standard deviation ``d sqrt(fs / 2)``. The 1/f part shapes the same white
noise in the frequency domain by ``sqrt(1 + fc / f)``, so the one-sided PSD is
``d^2 (1 + fc / f)``; the zero-frequency bin (the mean) is left white.
Shaped over the FFT of the whole record, the 1/f part is periodic over the
record length ``T`` (its end joins its start) and has no power below
``1/T``: a real sensor's slower wander, beyond the record, is not modelled.
"""

import numpy as np


def sensor_noise(n, sample_rate_hz, density, corner_hz, rng, n_axes=3):
    """Noise samples with PSD ``density^2 (1 + corner_hz / f)`` on each axis.

    Parameters
    ----------
    n : int
        Number of samples.
    sample_rate_hz : float
        Sample rate. [Hz]
    density : float
        White-noise density d. [m/s^2/sqrt(Hz)]
    corner_hz : float
        1/f corner frequency fc; 0 for white noise only. [Hz]
    rng : numpy.random.Generator
        Random source.
    n_axes : int
        Number of independent channels.

    Returns
    -------
    ndarray, shape (n, n_axes)
        [m/s^2]
    """
    sigma = density * np.sqrt(0.5 * sample_rate_hz)
    white = rng.standard_normal((n, n_axes)) * sigma
    if corner_hz <= 0 or n < 2:
        return white
    spectrum = np.fft.rfft(white, axis=0)
    f = np.fft.rfftfreq(n, d=1.0 / sample_rate_hz)
    shape = np.ones_like(f)
    shape[1:] = np.sqrt(1.0 + corner_hz / f[1:])
    return np.fft.irfft(spectrum * shape[:, None], n=n, axis=0)


def digitise(f, resolution, full_scale):
    """ADC steps and clipping, then float32 as the sensor delivers it.

    Parameters
    ----------
    f : ndarray, shape (n, 3)
        Readings. [m/s^2]
    resolution : float
        ADC step; 0 for none. [m/s^2]
    full_scale : float
        Readings are clipped to +-full_scale. [m/s^2]

    Returns
    -------
    ndarray of float32, shape (n, 3)
        [m/s^2]
    """
    if resolution > 0:
        f = np.round(f / resolution) * resolution
    if np.isfinite(full_scale):
        f = np.clip(f, -full_scale, full_scale)
    return f.astype(np.float32)
