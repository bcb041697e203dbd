"""Zero-phase low-pass filtering of the acceleration (paper, Section 4 [1]_).

The paper low-passes the raw accelerations with a "first-order low-pass
Butterworth filter (zero-phase)" at 4 Hz. We design the Butterworth filter
with :func:`scipy.signal.butter` (second-order sections) and apply it forward
and backward with :func:`scipy.signal.sosfiltfilt`, whose odd padding avoids
edge transients.

What "first order" means after forward-backward filtering: the designed
filter ``H`` has order 1, but the effective response of ``sosfiltfilt`` is
``|H(f)|**2``: zero phase at every frequency, gain 0.5 (-6 dB, not -3 dB) at
the cutoff, and a roll-off of 40 dB/decade, twice that of ``H``. The
``order`` and ``cutoff_hz`` options name the designed filter, as in the paper
and in SciPy.

Samples lost in gaps are never interpolated across: each stretch of
consecutive samples is filtered on its own.

References
----------
.. [1] K. Szipka, A. Archenti, G. W. Vogl, M. A. Donmez, "Identification of
   machine tool squareness errors via inertial measurements", CIRP Annals 68
   (2019).
"""

import itertools
from dataclasses import dataclass

import numpy as np
from scipy import signal

from imu_square.errors import AnalysisError


def design_lowpass(cutoff_hz, order, sample_rate_hz):
    """Butterworth low-pass as second-order sections.

    Parameters
    ----------
    cutoff_hz : float
        -3 dB frequency of the designed (one-pass) filter. [Hz]
    order : int
        Order of the designed (one-pass) filter.
    sample_rate_hz : float
        Sample rate. [Hz]

    Returns
    -------
    ndarray, shape (n_sections, 6)
        The filter, for :func:`scipy.signal.sosfiltfilt`.
    """
    nyquist = sample_rate_hz / 2
    if not 0 < cutoff_hz < nyquist:
        raise AnalysisError(
            f"cutoff_hz must be in (0, {nyquist:g}) (the Nyquist frequency), got {cutoff_hz!r}"
        )
    if int(order) != order or not 1 <= order <= 8:
        raise AnalysisError(f"filter order must be a whole number in [1, 8], got {order!r}")
    return signal.butter(int(order), cutoff_hz, output="sos", fs=sample_rate_hz)


def lowpass(data, cutoff_hz, order, sample_rate_hz, breaks=()):
    """Zero-phase low-pass along the first axis, stretch by stretch.

    Parameters
    ----------
    data : ndarray, shape (n_samples, ...)
        Samples, e.g. acceleration. [any unit, kept]
    cutoff_hz : float
        -3 dB frequency of the designed (one-pass) filter. [Hz]
    order : int
        Order of the designed (one-pass) filter.
    sample_rate_hz : float
        Sample rate. [Hz]
    breaks : sequence of int
        Sample indices where a new stretch begins (after a gap); the filter
        does not run across them.

    Returns
    -------
    ndarray, shape like ``data``, float64
        Filtered samples. Stretches too short to pad are returned unfiltered
        (they are dropped later as gap-adjacent).
    """
    sos = design_lowpass(cutoff_hz, order, sample_rate_hz)
    data = np.asarray(data, dtype=np.float64)
    out = data.copy()
    edges = [0, *sorted(int(b) for b in breaks), data.shape[0]]
    min_len = 3 * (2 * sos.shape[0] + 1)
    for a, b in itertools.pairwise(edges):
        if b - a > min_len:
            out[a:b] = signal.sosfiltfilt(sos, data[a:b], axis=0)
    return out


def settling_time_s(cutoff_hz, order):
    """Time after which the forward-backward impulse response has decayed below 1e-3.

    Parameters
    ----------
    cutoff_hz : float
        Cutoff of the designed filter. [Hz]
    order : int
        Order of the designed filter.

    Returns
    -------
    float
        Half-width of the effective impulse response. [s]
    """
    # A Butterworth pole sits at radius 2 pi fc; its envelope exp(-2 pi fc sin(..) t)
    # decays slowest for the pole nearest the axis. ln(1000) ~ 6.9 time constants.
    return 6.9 / (2 * np.pi * cutoff_hz * np.sin(np.pi / (2 * order)))


def passband_gain(frequency_hz, cutoff_hz, order, sample_rate_hz):
    """Gain ``|H(f)|^2`` of the forward-backward filter at one frequency.

    Parameters
    ----------
    frequency_hz : float
        Frequency, e.g. the circle's. [Hz]
    cutoff_hz : float
        Cutoff of the designed filter. [Hz]
    order : int
        Order of the designed filter.
    sample_rate_hz : float
        Sample rate. [Hz]

    Returns
    -------
    float
        Amplitude gain of :func:`lowpass` at ``frequency_hz`` (phase is zero).
    """
    sos = design_lowpass(cutoff_hz, order, sample_rate_hz)
    _, h = signal.sosfreqz(sos, worN=[frequency_hz], fs=sample_rate_hz)
    return float(np.abs(h[0]) ** 2)


def noise_bandwidth_hz(cutoff_hz, order, sample_rate_hz, highpass=False):
    """Equivalent noise bandwidth of the forward-backward filter (or of its complement).

    Parameters
    ----------
    cutoff_hz : float
        Cutoff of the designed filter. [Hz]
    order : int
        Order of the designed filter.
    sample_rate_hz : float
        Sample rate. [Hz]
    highpass : bool
        If True, the bandwidth of ``1 - |H|^2`` (what the filter removes).

    Returns
    -------
    float
        Integral of the squared effective gain from 0 to Nyquist. [Hz]
    """
    sos = design_lowpass(cutoff_hz, order, sample_rate_hz)
    f, h = signal.sosfreqz(sos, worN=1 << 16, fs=sample_rate_hz)
    g = np.abs(h) ** 2
    if highpass:
        g = 1 - g
    return float(np.trapezoid(g**2, f))


@dataclass(frozen=True)
class FilteredRecording:
    """A recording's samples as the later steps need them.

    Attributes
    ----------
    t_s : ndarray, shape (n_samples,)
        Sample times from the first sample. [s]
    raw : ndarray, shape (n_samples, 3)
        Unfiltered acceleration, float64. [m/s^2]
    xy : ndarray, shape (n_samples, 2)
        Zero-phase low-passed x and y. [m/s^2]
    breaks : tuple of int
        Indices of the first sample after each gap.
    sample_rate_hz : float
        Nominal sample rate. [Hz]
    margin_s : float
        Settling time of the filter, kept clear of gaps and block edges. [s]
    """

    t_s: np.ndarray
    raw: np.ndarray
    xy: np.ndarray
    breaks: tuple
    sample_rate_hz: float
    margin_s: float

    @property
    def gap_spans_s(self):
        """``(last sample before, first sample after)`` of each gap. [s]"""
        return [(float(self.t_s[i - 1]), float(self.t_s[i])) for i in self.breaks]


def filter_recording(recording, cutoff_hz, order):
    """Low-pass a recording's horizontal axes, stretch by stretch between gaps.

    Parameters
    ----------
    recording : Recording
        The test as recorded.
    cutoff_hz : float
        Cutoff of the designed filter. [Hz]
    order : int
        Order of the designed filter.

    Returns
    -------
    FilteredRecording
    """
    fs = recording.sample_rate_hz
    raw = recording.accel.astype(np.float64)
    bad = ~np.isfinite(raw)
    if bad.any():
        rows = np.flatnonzero(bad.any(axis=1))
        raise AnalysisError(
            f"{rows.size} sample(s) are not numbers (NaN or infinite), the first at "
            f"{recording.time_s[rows[0]]:.3f} s: the recording is damaged"
        )
    breaks = tuple(i for i, _ in recording.gaps())
    return FilteredRecording(
        t_s=recording.time_s,
        raw=raw,
        xy=lowpass(raw[:, :2], cutoff_hz, order, fs, breaks),
        breaks=breaks,
        sample_rate_hz=fs,
        margin_s=settling_time_s(cutoff_hz, order),
    )
