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

**Cutoff.** The paper's 4 Hz serves its 0.159 Hz circle (omega = 1 rad/s):
8 pi times the circle frequency. The default cutoff keeps that ratio
(:func:`circle_cutoff_hz`), so the filter's response to the start of motion
dies out (to 1e-6) in 9 % of a period, well inside the 180 deg overshoot, and
the averaged cycle keeps tens of independent noise samples at any feed; a
fixed 4 Hz at a 2.5 Hz circle needs 0.55 s, longer than the overshoot (0.2 s),
and the start of motion leaked into the first analysed cycle.

**Clipping.** A sample at the sensor's full scale on any axis is no
measurement: it is taken out and bridged like a lost sample (below), so that
the low-pass does not spread it over its neighbours. One such spike of 2 g in
the dwell 78 ms after a stop of motion, filtered, had lifted the envelope
above the motion threshold, moved the detected stop by 0.1 s and eps_c by
4.5 deg through the time anchor (:mod:`imu_square.pipeline.segment`).

**Gaps.** Samples lost in a *short* gap (at most :data:`MAX_BRIDGED_GAP_PERIODS`
of a circle period) are bridged for the filter only: a least-squares fit of a
line plus a sinusoid at the circle frequency to the samples either side
predicts them, the whole stretch is filtered, and the bridged samples are
marked invalid so that no later step uses them (``docs/model.md``, gaps).
The fit's window shrinks until the model fits its data to the noise (near a
start or stop of motion). A longer gap, or one at the recording's edge,
breaks the data into stretches, each filtered on its own and never
interpolated across.

References
----------
.. [1] K. Szipka, A. Archenti, G. W. Vogl, M. A. Donmez, "Identification of
   machine tool squareness errors via inertial measurements", CIRP Annals 68
   (2019).
"""

import functools
import itertools
from dataclasses import dataclass

import numpy as np
from scipy import signal

from imu_square.errors import AnalysisError
from imu_square.io.recording import lost_runs

# The paper's cutoff over its circle frequency: 4 Hz / (1 / 2 pi) Hz.
CUTOFF_PER_CIRCLE_FREQUENCY = 8 * np.pi
# The cutoff tied to the circle stays below this fraction of the sample rate.
MAX_CUTOFF_OF_SAMPLE_RATE = 0.2
# Gaps up to this fraction of a circle period (45 deg of arc) are bridged.
MAX_BRIDGED_GAP_PERIODS = 0.125
# The prediction of a bridged gap starts from this many gap lengths of samples
# either side (at most a quarter period, at least _MIN_BRIDGE_WINDOW samples).
BRIDGE_WINDOW_GAPS = 4
_MIN_BRIDGE_WINDOW = 32
# Least real samples on each side of a gap to bridge it.
_MIN_BRIDGE_SAMPLES = 8
# The prediction's model must fit its window to this multiple of the noise sd.
_BRIDGE_FIT_TOLERANCE = 1.5
_MAD_TO_SD = 1.4826


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
    return _butter_sos(int(order), float(cutoff_hz), float(sample_rate_hz)).copy()


@functools.lru_cache(maxsize=32)
def _butter_sos(order, cutoff_hz, sample_rate_hz):
    # scipy's design takes a millisecond, as long as filtering 100k samples, and
    # every analysis asks for the same few filters (twice each).
    return signal.butter(order, cutoff_hz, output="sos", fs=sample_rate_hz)


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
    # Channels as contiguous rows, filtered along the last axis all at once: on (n, k)
    # along axis 0 sosfiltfilt copies and pads strided data several times, at twice
    # the cost, and one channel per call pays its overhead k times; the numbers are
    # the same. Each stretch is written straight into the output.
    rows = np.ascontiguousarray(data.reshape(data.shape[0], -1).T)
    out = np.empty(rows.shape[::-1])
    edges = [0, *sorted(int(b) for b in breaks), data.shape[0]]
    min_len = 3 * (2 * sos.shape[0] + 1)
    for a, b in itertools.pairwise(edges):
        long = b - a > min_len
        out[a:b] = (signal.sosfiltfilt(sos, rows[:, a:b], axis=-1) if long else rows[:, a:b]).T
    return out.reshape(data.shape)


def circle_cutoff_hz(circle_frequency_hz, sample_rate_hz):
    """The default cutoff: the paper's ratio to the circle frequency.

    Parameters
    ----------
    circle_frequency_hz : float
        Frequency of the circle. [Hz]
    sample_rate_hz : float
        Sample rate. [Hz]

    Returns
    -------
    float
        ``8 pi`` times the circle frequency (4 Hz for the paper's 0.159 Hz
        circle), at most :data:`MAX_CUTOFF_OF_SAMPLE_RATE` of the sample rate. [Hz]
    """
    return float(
        min(
            CUTOFF_PER_CIRCLE_FREQUENCY * circle_frequency_hz,
            MAX_CUTOFF_OF_SAMPLE_RATE * sample_rate_hz,
        )
    )


def settling_time_s(cutoff_hz, order, level=1e-3):
    """Time after which the forward-backward impulse response has decayed below ``level``.

    Parameters
    ----------
    cutoff_hz : float
        Cutoff of the designed filter. [Hz]
    order : int
        Order of the designed filter.
    level : float
        Fraction of the peak left.

    Returns
    -------
    float
        Half-width of the effective impulse response. [s]
    """
    # A Butterworth pole sits at radius 2 pi fc; its envelope exp(-2 pi fc sin(..) t)
    # decays slowest for the pole nearest the axis: ln(1 / level) time constants.
    return float(-np.log(level) / (2 * np.pi * cutoff_hz * np.sin(np.pi / (2 * order))))


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


@dataclass(frozen=True)
class FilteredRecording:
    """A recording's samples as the later steps need them.

    Short gaps are bridged (module docstring): their samples are present in
    every array, with ``valid`` False. Clipped samples count as lost.

    Attributes
    ----------
    t_s : ndarray, shape (n_samples,)
        Sample times from the first sample, bridged samples included. [s]
    raw : ndarray, shape (n_samples, 3)
        Unfiltered acceleration, float64; bridged samples hold the prediction. [m/s^2]
    xy : ndarray, shape (n_samples, 2)
        Zero-phase low-passed x and y. [m/s^2]
    valid : ndarray of bool, shape (n_samples,)
        False for bridged samples, which are no data.
    breaks : tuple of int
        Indices of the first sample after each gap that is not bridged.
    bridged_spans_s : tuple of tuple (float, float)
        ``(last sample before, first sample after)`` of each bridged gap,
        clipped samples' included. [s]
    clipped_s : ndarray, shape (n_clipped,)
        Times of the samples at the sensor's full scale, taken out as lost. [s]
    max_bridged_s : float
        Longest gap that may be bridged. [s]
    sample_rate_hz : float
        Nominal sample rate. [Hz]
    cutoff_hz : float
        Cutoff of the designed filter. [Hz]
    order : int
        Order of the designed filter.
    margin_s : float
        Settling time of the filter to 1e-3, kept clear of gaps. [s]
    """

    t_s: np.ndarray
    raw: np.ndarray
    xy: np.ndarray
    valid: np.ndarray
    breaks: tuple
    bridged_spans_s: tuple
    clipped_s: np.ndarray
    max_bridged_s: float
    sample_rate_hz: float
    cutoff_hz: float
    order: int
    margin_s: float

    @property
    def onset_margin_s(self):
        """Settling time to 1e-6, kept clear of the starts and stops of motion. [s]

        There the data step from rest to the whole circle, and what is left of
        the filter's response to that step must stay below the noise of the
        averaged cycles (6.4 m/s^2 times 1e-3 was 200 times it).
        """
        return settling_time_s(self.cutoff_hz, self.order, 1e-6)

    @property
    def reach_s(self):
        """Settling time to 5 % (three time constants): how far a short gap moves the output. [s]"""
        return settling_time_s(self.cutoff_hz, self.order, np.exp(-3.0))

    @property
    def gap_spans_s(self):
        """``(last sample before, first sample after)`` of each gap not bridged. [s]"""
        return [(float(self.t_s[i - 1]), float(self.t_s[i])) for i in self.breaks]

    @property
    def short_gap_spans_s(self):
        """Gaps no longer than :attr:`max_bridged_s`, bridged or not. [s]"""
        short = [(a, b) for a, b in self.gap_spans_s if b - a <= self.max_bridged_s]
        return sorted([*short, *self.bridged_spans_s])

    @property
    def long_gap_spans_s(self):
        """Gaps longer than :attr:`max_bridged_s`. [s]"""
        return [(a, b) for a, b in self.gap_spans_s if b - a > self.max_bridged_s]


def _noise_sd(t_s, raw):
    """Per-axis noise sd from third differences (blind to a circle's curve at 1 kHz)."""
    dt = np.median(np.diff(t_s[: min(t_s.size, 1000)]))
    even = np.diff(t_s) < 1.5 * dt
    steady = even[:-2] & even[1:-1] & even[2:]  # four consecutive samples, no gap
    d3 = np.diff(raw, n=3, axis=0)[steady]
    if d3.shape[0] == 0:
        return np.full(raw.shape[1], np.inf)
    # No prediction beats the float32 rounding the samples are stored with.
    rounding = np.finfo(np.float32).eps * np.max(np.abs(raw), axis=0)
    return np.maximum(_MAD_TO_SD * np.median(np.abs(d3), axis=0) / np.sqrt(20.0), rounding)


def _predict_gap(t_s, raw, i, t_fill, circle_frequency_hz, window_s, noise_sd):
    """Samples missing between ``i - 1`` and ``i``, or None if they cannot be predicted.

    A line plus a sinusoid at the circle frequency, fitted to the samples
    within ``window_s`` either side (at least :data:`_MIN_BRIDGE_SAMPLES` each
    side, at most a quarter period). Where that model does not fit its own data
    to the noise (a start or stop of motion, a ramp, a spike) the window is
    halved, down to that least window, whose fit is used whatever its residual:
    what it cannot follow stays local, since the bridged samples are no data
    and a start or stop of motion near them widens its uncertainty
    (:func:`imu_square.pipeline.segment.check_block`). None at the recording's
    edges or among other gaps, where a side lacks the samples.
    """
    n = _MIN_BRIDGE_SAMPLES
    if i < n or t_s.size - i < n:
        return None
    t_a, t_b = t_s[i - 1], t_s[i]
    least = max(t_a - t_s[i - n], t_s[i + n - 1] - t_b)
    widest = 0.25 / circle_frequency_hz
    if least > widest:
        return None
    w = 2 * np.pi * circle_frequency_hz
    v = t_fill - 0.5 * (t_a + t_b)
    window = min(max(window_s, least), widest)
    while True:
        lo = int(np.searchsorted(t_s, t_a - window))
        hi = int(np.searchsorted(t_s, t_b + window, side="right"))
        u = t_s[lo:hi] - 0.5 * (t_a + t_b)
        design = np.column_stack([np.ones_like(u), u, np.cos(w * u), np.sin(w * u)])
        coef = np.linalg.lstsq(design, raw[lo:hi], rcond=None)[0]
        rms = np.sqrt(np.mean((raw[lo:hi] - design @ coef)[:, :2] ** 2, axis=0))
        if window <= least or np.all(rms <= _BRIDGE_FIT_TOLERANCE * noise_sd[:2]):
            return np.column_stack([np.ones_like(v), v, np.cos(w * v), np.sin(w * v)]) @ coef
        window = max(window / 2, least)


def bridge_gaps(t_s, raw, gaps, circle_frequency_hz):
    """Insert predicted samples into the short gaps of a recording.

    Parameters
    ----------
    t_s : ndarray, shape (n_samples,)
        Sample times from the first sample. [s]
    raw : ndarray, shape (n_samples, n_axes)
        Samples. [m/s^2]
    gaps : sequence of tuple (int, int)
        ``(index, lost)`` of each gap, as :meth:`Recording.gaps` gives them.
    circle_frequency_hz : float
        Frequency of the circle, which decides what is short and shapes the
        prediction. [Hz]

    Returns
    -------
    t_s : ndarray, shape (n_bridged,)
        Times with the bridged samples inserted. [s]
    raw : ndarray, shape (n_bridged, n_axes)
        Samples with the predictions inserted. [m/s^2]
    valid : ndarray of bool, shape (n_bridged,)
        False for inserted samples.
    breaks : tuple of int
        Index (in the new arrays) of the first sample after each gap not bridged.
    bridged_spans_s : tuple of tuple (float, float)
        ``(last sample before, first sample after)`` of each bridged gap. [s]
    """
    period = 1.0 / circle_frequency_hz
    max_gap = MAX_BRIDGED_GAP_PERIODS * period
    noise_sd = _noise_sd(t_s, raw) if len(gaps) else None
    pieces_t, pieces_x, pieces_v = [], [], []
    breaks, spans = [], []
    start = 0
    inserted = 0
    for i, lost in gaps:
        t_a, t_b = float(t_s[i - 1]), float(t_s[i])
        pieces_t.append(t_s[start:i])
        pieces_x.append(raw[start:i])
        pieces_v.append(np.ones(i - start, dtype=bool))
        start = i
        t_fill = t_a + (t_b - t_a) * np.arange(1, lost + 1) / (lost + 1)
        dt = (t_b - t_a) / (lost + 1)
        window = max(min(BRIDGE_WINDOW_GAPS * (t_b - t_a), period / 4), _MIN_BRIDGE_WINDOW * dt)
        fill = None
        if 1 <= lost and t_b - t_a <= max_gap:
            fill = _predict_gap(t_s, raw, i, t_fill, circle_frequency_hz, window, noise_sd)
        if fill is None:
            breaks.append(i + inserted)
            continue
        pieces_t.append(t_fill)
        pieces_x.append(fill)
        pieces_v.append(np.zeros(lost, dtype=bool))
        spans.append((t_a, t_b))
        inserted += lost
    pieces_t.append(t_s[start:])
    pieces_x.append(raw[start:])
    pieces_v.append(np.ones(t_s.size - start, dtype=bool))
    return (
        np.concatenate(pieces_t),
        np.concatenate(pieces_x),
        np.concatenate(pieces_v),
        tuple(breaks),
        tuple(spans),
    )


def clipped_samples(accel, range_m_s2):
    """Which samples are at or beyond the sensor's full scale on any axis.

    Parameters
    ----------
    accel : ndarray, shape (n_samples, n_axes)
        Raw acceleration. [m/s^2]
    range_m_s2 : float
        Full-scale range; NaN when unknown (then nothing is flagged). [m/s^2]

    Returns
    -------
    ndarray of bool, shape (n_samples,)
        True for a clipped sample.
    """
    if not np.isfinite(range_m_s2):
        return np.zeros(accel.shape[0], dtype=bool)
    limit = 0.999 * range_m_s2
    # Column by column: np.any(..., axis=1) over 3 columns is 15 times slower.
    hit = np.abs(accel[:, 0]) >= limit
    for k in range(1, accel.shape[1]):
        hit |= np.abs(accel[:, k]) >= limit
    return hit


def filter_recording(recording, cutoff_hz, order, circle_frequency_hz):
    """Bridge short gaps, then low-pass the horizontal axes stretch by stretch.

    Parameters
    ----------
    recording : Recording
        The test as recorded.
    cutoff_hz : float or None
        Cutoff of the designed filter; None for :func:`circle_cutoff_hz`. [Hz]
    order : int
        Order of the designed filter.
    circle_frequency_hz : float
        Programmed circle frequency. [Hz]

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
    if cutoff_hz is None:
        cutoff_hz = circle_cutoff_hz(circle_frequency_hz, fs)
    t_s, gaps = recording.time_s, recording.gaps()
    clipped = clipped_samples(raw, recording.sensor.range_m_s2)
    clipped_s = t_s[clipped]
    if clipped_s.size:
        # Lost, as far as the filter and all after it know (module docstring).
        keep = ~clipped
        t_s, raw, gaps = t_s[keep], raw[keep], lost_runs(recording.seq[keep])
    t_s, raw, valid, breaks, spans = bridge_gaps(t_s, raw, gaps, circle_frequency_hz)
    return FilteredRecording(
        t_s=t_s,
        raw=raw,
        xy=lowpass(raw[:, :2], cutoff_hz, order, fs, breaks),
        valid=valid,
        breaks=breaks,
        bridged_spans_s=spans,
        clipped_s=clipped_s,
        max_bridged_s=MAX_BRIDGED_GAP_PERIODS / circle_frequency_hz,
        sample_rate_hz=fs,
        cutoff_hz=float(cutoff_hz),
        order=int(order),
        margin_s=settling_time_s(cutoff_hz, order),
    )
