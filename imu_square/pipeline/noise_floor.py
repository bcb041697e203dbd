"""The noise the fitted model leaves, its spectrum, and the bound it sets.

The noise floor of a run is the Cramér-Rao bound on ``theta_y - theta_x``
for the noise *at the circle frequency*: a sinusoid's phase, fitted over a
time ``T`` in stationary Gaussian noise of one-sided PSD ``S(f)``, has at
least the variance ``S(f0) / (A^2 T)`` per axis (for long ``T``), so

    sd(theta_y - theta_x) >= sqrt(2 S(f0)) / (A sqrt(T)),

which is ``sqrt(2) d / (A sqrt(T))`` for white noise of density ``d``
(``docs/model.md``). A MEMS sensor's noise also has a 1/f part: with the
simulator's model ``S(f) = d^2 (1 + f_k / f)`` (:mod:`imu_square.simulate.sensor_noise`,
corner ``f_k``) the bound grows by ``sqrt(1 + f_k / f0)``: twice the white
bound for the paper's 0.16 Hz circle and a 0.5 Hz corner.
:func:`squareness_noise_floor` gives it for a planned test;
:func:`noise_floor` estimates it from a run:

- the residual: the raw samples of the analysed cycles minus the fitted
  model at their position angle (each direction's sinusoid, with the
  low-pass's gain taken out, plus what its averaged cycle holds beyond the
  sinusoid), so that neither the circle nor its harmonics count as noise,
  whatever the circle frequency (a fixed 4 Hz high-pass at a 2.5 Hz circle
  kept a third of the signal and reported a floor 300 times too high);
- the white density from its median absolute deviation over all its
  bandwidth (robust to spikes), corrected for the share of each sample's own
  noise that the averaged cycle it is compared with holds (1 % for 15 cycles
  at the default cutoff, 5 % for 3);
- the 1/f corner from its Welch spectrum below half the cutoff, by a Whittle
  fit of ``a + b / f``, kept only where ``b`` exceeds four times its standard
  error, which counts the Welch bins' correlation (a white sensor then gets
  exactly the white bound, but in about 1 run in 5000).
"""

import functools
from dataclasses import dataclass

import numpy as np
from scipy import fft as sp_fft
from scipy import linalg, signal

from imu_square.pipeline.filter import design_lowpass
from imu_square.pipeline.uncertainty import cramer_rao

_MAD_TO_SD = 1.4826
# Welch segments span this many circle periods (resolution a quarter of the circle
# frequency); shorter stretches give no 1/f estimate below one period.
_SEGMENT_PERIODS = 4
# The 1/f term counts when it exceeds this many standard errors. On white noise
# b / se(b) spreads with sd 1.03, and 1.10-1.15 on a run's residual (taking out the
# averaged cycle adds some): at 4, about 1 white run in 5000 reads as 1/f (at 3,
# 1 in 300: 2 of the 200 high-accel runs), while the paper's 1/f test (z 5-7.5)
# keeps its corner.
_FLICKER_SIGNIFICANCE = 4.0


@dataclass(frozen=True)
class NoiseSpectrum:
    """Sensor noise per axis: one-sided PSD ``d^2 (1 + f_k / f)``.

    Attributes
    ----------
    white_density_m_s2_rthz : float
        White density ``d``. [m/s^2/sqrt(Hz)]
    flicker_corner_hz : float
        1/f corner ``f_k``; 0 for white noise. [Hz]
    """

    white_density_m_s2_rthz: float
    flicker_corner_hz: float = 0.0

    def density_at(self, frequency_hz):
        """Amplitude spectral density at ``frequency_hz``. [m/s^2/sqrt(Hz)]

        Parameters
        ----------
        frequency_hz : float
            Frequency, e.g. the circle's. [Hz]
        """
        corner = self.flicker_corner_hz if np.isfinite(self.flicker_corner_hz) else 0.0
        return float(self.white_density_m_s2_rthz * np.sqrt(1.0 + corner / frequency_hz))


def squareness_noise_floor(spectrum, amplitude_m_s2, analysed_s, circle_frequency_hz):
    """Least standard deviation of ``theta_y - theta_x`` for a test in this noise.

    Parameters
    ----------
    spectrum : NoiseSpectrum
        The sensor's noise.
    amplitude_m_s2 : float
        ``v^2/r``. [m/s^2]
    analysed_s : float
        Analysed time, both directions together. [s]
    circle_frequency_hz : float
        ``v / (2 pi r)``. [Hz]

    Returns
    -------
    float
        ``sqrt(2) S(f0)^(1/2) / (A sqrt(T))``. [rad]
    """
    density = spectrum.density_at(circle_frequency_hz)
    return cramer_rao(density, amplitude_m_s2, analysed_s)


def model_residual(filtered, segmentation, cycles, mean_fit):
    """Raw samples of the analysed cycles minus the fitted model, stretch by stretch.

    Parameters
    ----------
    filtered : FilteredRecording
        The samples (raw, valid).
    segmentation : Segmentation
        Blocks and the time-to-angle map.
    cycles : CycleTraces
        The cycles kept.
    mean_fit : MeanFit
        Fits of the directions' averaged cycles.

    Returns
    -------
    list of ndarray, shape (n_i, 2)
        x and y residuals of each run of consecutive valid samples. [m/s^2]
    """
    grid = cycles.phi_grid
    turn = 2 * np.pi
    period = segmentation.period_s
    blocks = {b.plan.index: b for b in segmentation.blocks}
    t_s, raw, valid = filtered.t_s, filtered.raw, filtered.valid
    out = []
    for i, cyc in enumerate((cycles.ccw, cycles.cw)):
        params = [mean_fit.fit.x.params[i], mean_fit.fit.y.params[i]]
        means = [mean_fit.mean_x[i], mean_fit.mean_y[i]]
        has = mean_fit.counts[i] > 0
        remainders = []
        for p, m in zip(params, means, strict=True):
            rem = m - (p[0] + p[1] * np.cos(grid) + p[2] * np.sin(grid))
            remainders.append(np.interp(grid, grid[has], rem[has], period=turn))
        # Both axes' remainders as one complex table, wrapped as np.interp(period=) does:
        # one search of the table per sample for both axes.
        table_phi, table_rem = _periodic_table(grid, remainders[0] + 1j * remainders[1], turn)
        for b, t0 in _spans(cyc, period):
            block = blocks[b]
            lo, hi = np.searchsorted(t_s, t0)
            phi = segmentation.phi(block, t_s[lo:hi])
            # phi minus whole turns by floor, not np.mod (ten times slower): within an ulp
            # of [0, turn), which the table's wrapped ends cover. In place: fresh arrays
            # cost page faults.
            reduced = np.divide(phi, turn)
            np.floor(reduced, out=reduced)
            reduced *= turn
            np.subtract(phi, reduced, out=reduced)
            s = np.sin(reduced)
            c = np.cos(reduced, out=phi)
            rem = np.interp(reduced, table_phi, table_rem)
            # Residuals axis by axis into the rows of a (2, n) array, handed out as its
            # (n, 2) transpose: the noise spectrum takes the rows as they are.
            res = np.empty((2, hi - lo))
            for axis, (p, r) in enumerate(zip(params, (rem.real, rem.imag), strict=True)):
                model = np.multiply(c, p[1], out=reduced)
                model += np.multiply(s, p[2], out=res[axis])
                model /= mean_fit.gain
                model += p[0]
                model += r
                np.subtract(raw[lo:hi, axis], model, out=res[axis])
            res = res.T
            ok = valid[lo:hi]
            if ok.all():
                out.append(res)
                continue
            edges = np.flatnonzero(np.diff(np.concatenate([[0], ok.astype(np.int8), [0]])))
            out += [res[a:z] for a, z in zip(edges[::2], edges[1::2], strict=True)]
    return out


def _periodic_table(xp, fp, period):
    """``(xp, fp)`` wrapped so that ``np.interp(x % period, *table)`` is ``np.interp(x, xp, fp,
    period=period)``: what numpy does on every call, done once. The table reaches a
    grid step beyond ``[0, period)`` either side, so ``x % period`` may be off by ulps."""
    xp = np.asarray(xp, dtype=np.float64) % period
    order = np.argsort(xp)
    xp, fp = xp[order], fp[order]
    return (
        np.concatenate((xp[-1:] - period, xp, xp[0:1] + period)),
        np.concatenate((fp[-1:], fp, fp[0:1])),
    )


def _spans(cyc, period):
    """(block, (start, end)) of each run of consecutive kept cycles. [s]"""
    order = np.lexsort((cyc.t_start_s, cyc.block))
    spans = []
    for k in order:
        b, t0 = int(cyc.block[k]), float(cyc.t_start_s[k])
        if spans and spans[-1][0] == b and abs(spans[-1][1][1] - t0) < 0.01 * period:
            spans[-1] = (b, (spans[-1][1][0], t0 + period))
        else:
            spans.append((b, (t0, t0 + period)))
    return spans


def white_density(residuals, sample_rate_hz):
    """White-noise density from the median absolute deviation of the residual.

    Parameters
    ----------
    residuals : list of ndarray, shape (n_i, n_axes)
        Residual stretches. [m/s^2]
    sample_rate_hz : float
        Sample rate. [Hz]

    Returns
    -------
    float
        RMS over the axes of ``sd / sqrt(fs / 2)``; an overestimate where the
        data hold vibration the model does not. [m/s^2/sqrt(Hz)]
    """
    # One contiguous row per axis, our own copy: partitioned and overwritten in place
    # (the medians need not the order; fresh arrays cost page faults).
    r = np.concatenate([x.T for x in residuals], axis=1)
    r -= np.median(r, axis=-1, overwrite_input=True)[:, None]
    np.abs(r, out=r)
    sd = _MAD_TO_SD * np.median(r, axis=-1, overwrite_input=True)
    return float(np.sqrt(np.mean(sd**2) / (sample_rate_hz / 2)))


@dataclass(frozen=True)
class FlickerFit:
    """Whittle fit of ``a + b / f`` to a residual's Welch spectrum.

    Attributes
    ----------
    white_psd : float
        ``a``, the one-sided white PSD. [(m/s^2)^2/Hz]
    flicker_coefficient : float
        ``b``: the 1/f part is ``b / f``. [(m/s^2)^2]
    se_flicker_coefficient : float
        Standard error of ``b``, for the Welch bins' correlation. [(m/s^2)^2]
    """

    white_psd: float
    flicker_coefficient: float
    se_flicker_coefficient: float

    @property
    def z(self):
        """``b`` in standard errors: about standard normal for white noise."""
        return self.flicker_coefficient / self.se_flicker_coefficient


def flicker_fit(residuals, sample_rate_hz, circle_frequency_hz, max_frequency_hz):
    """Whittle fit of ``a + b / f`` to the residual's Welch spectrum, with the se of ``b``.

    Parameters
    ----------
    residuals : list of ndarray, shape (n_i, n_axes)
        Residual stretches. [m/s^2]
    sample_rate_hz : float
        Sample rate. [Hz]
    circle_frequency_hz : float
        Circle frequency, which sets the resolution needed: Welch segments
        of :data:`_SEGMENT_PERIODS` periods (a power of two samples). [Hz]
    max_frequency_hz : float
        Highest frequency fitted (below the low-pass's cutoff, where the
        model has removed every periodic part). [Hz]

    Returns
    -------
    FlickerFit or None
        None when no stretch spans a circle period or fewer than 4 bins lie
        between twice the resolution and ``max_frequency_hz``.
    """
    longest = max(r.shape[0] for r in residuals)
    want = _SEGMENT_PERIODS * sample_rate_hz / circle_frequency_hz
    nperseg = 1 << int(np.floor(np.log2(max(min(want, longest), 2))))
    if nperseg < sample_rate_hz / circle_frequency_hz:
        return None
    total, n_avg, n_series = 0.0, 0, 0
    window = signal.get_window("hann", nperseg)
    for r in residuals:
        if r.shape[0] < nperseg:
            continue
        p = _periodogram_sum(r, window)
        total = total + p
        n_avg += (1 + (r.shape[0] - nperseg) // (nperseg // 2)) * r.shape[1]
        n_series += r.shape[1]
    f = np.fft.rfftfreq(nperseg, 1 / sample_rate_hz)
    psd = total / (n_avg * sample_rate_hz * np.sum(window**2))
    psd[1 : (nperseg + 1) // 2] *= 2  # one-sided: all but 0 and fs / 2 twice
    band = (f >= 2 * f[1]) & (f <= max_frequency_hz)
    if np.count_nonzero(band) < 4:
        return None
    f, psd = f[band], psd[band]
    design = np.column_stack([np.ones_like(f), 1 / f])
    coef = np.array([np.median(psd), 0.0])
    nll = _whittle_nll(design @ coef, psd)
    for _ in range(20):  # Whittle: least squares weighted by the model's inverse variance
        w = 1 / (design @ coef) ** 2
        step = np.linalg.solve(design.T @ (design * w[:, None]), design.T @ (w * psd)) - coef
        if np.all(np.abs(step) <= 1e-9 * np.abs(coef).max()):
            break  # converged: what is left is rounding
        # Halved until the likelihood does not fall and the model stays positive: with
        # few Welch segments the full steps can swing ever wider (seen: b/se = -1.6e6).
        for _ in range(40):
            trial = _whittle_nll(design @ (coef + step), psd)
            if trial <= nll:
                break
            step /= 2
        else:
            break  # no step descends: at the optimum, to rounding
        coef, gain, nll = coef + step, nll - trial, trial
        if gain <= 1e-12 * abs(nll):
            break  # the likelihood has settled
    model = design @ coef
    # Sandwich covariance: the Welch bins are not independent (adjacent Hann bins
    # correlate by 4/9, overlapping segments by 1/36). Taken as independent, the
    # se of b was 0.7 of its spread, and 1 white run in 100 read as 1/f at "3 se".
    scaled = design / model[:, None]
    bread = np.linalg.inv(scaled.T @ scaled)
    # Over all series: n_avg segments at lag 0, 2 (n_avg - n_series) pairs at N / 2.
    same, neighbour = _welch_correlations(nperseg)
    lagged = same + 2 * (1 - n_series / n_avg) * neighbour
    cov = bread @ (scaled.T @ linalg.toeplitz(lagged[: f.size]) @ scaled) @ bread / n_avg
    return FlickerFit(float(coef[0]), float(coef[1]), float(np.sqrt(cov[1, 1])))


def _whittle_nll(model, psd):
    """Whittle's negative log-likelihood of a spectrum ``model`` for the estimate ``psd``."""
    if not np.all(model > 0):
        return np.inf
    return float(np.sum(np.log(model) + psd / model))


def flicker_corner(residuals, sample_rate_hz, circle_frequency_hz, max_frequency_hz):
    """1/f corner of the residual's spectrum, by a Whittle fit of ``a + b / f``.

    Parameters
    ----------
    residuals : list of ndarray, shape (n_i, n_axes)
        Residual stretches. [m/s^2]
    sample_rate_hz : float
        Sample rate. [Hz]
    circle_frequency_hz : float
        Circle frequency, which sets the resolution needed. [Hz]
    max_frequency_hz : float
        Highest frequency fitted. [Hz]

    Returns
    -------
    float
        ``b / a`` if ``b`` exceeds :data:`_FLICKER_SIGNIFICANCE` standard
        errors, else 0; NaN when no stretch spans a circle period. [Hz]
    """
    fit = flicker_fit(residuals, sample_rate_hz, circle_frequency_hz, max_frequency_hz)
    if fit is None:
        return float("nan")
    if fit.white_psd <= 0 or fit.z < _FLICKER_SIGNIFICANCE:
        return 0.0
    return fit.flicker_coefficient / fit.white_psd


@functools.lru_cache(maxsize=16)
def _welch_correlations(nperseg):
    """Squared correlations of Hann-windowed DFTs ``m`` bins apart, for white noise.

    Gaussian noise through a window ``w`` gives periodograms whose covariance at
    bins ``m`` apart, in segments ``L`` samples apart, is ``S^2 |sum_n w[n] w[n+L]
    exp(-2 pi i m n / N)|^2 / (sum w^2)^2`` (leaving out the ``k + l`` term, which
    counts only near 0 and fs / 2); half-overlapping segments meet at ``L = 0``
    and ``L = N / 2``.

    Parameters
    ----------
    nperseg : int
        Segment length ``N``, even. [samples]

    Returns
    -------
    same, neighbour : ndarray, shape (nperseg,)
        The squared correlations at ``L = 0`` (1, 4/9, 1/36, 0, ...) and at
        ``L = N / 2`` (1/36, 0.020, 0.0069, ...), by ``m``.
    """
    w = signal.get_window("hann", nperseg)
    half = nperseg // 2
    power = np.sum(w**2)
    shifted = np.zeros(nperseg)
    shifted[:half] = w[:half] * w[half:]
    same = np.abs(sp_fft.fft(w * w)) / power
    neighbour = np.abs(sp_fft.fft(shifted)) / power
    return same**2, neighbour**2


def _periodogram_sum(r, window):
    """Sum over axes and half-overlapping segments of ``|rfft(window * (segment - mean))|^2``.

    What ``scipy.signal.welch(r, nperseg=window.size, axis=0)`` averages (its
    defaults: Hann window, half overlap, constant detrend, density scaling
    applied by the caller), with every segment of every axis in one batched FFT
    instead of its per-segment detrending: a quarter of the time.
    """
    n = window.size
    by_axis = np.ascontiguousarray(r.T)  # segments contiguous: 40 times faster means
    frames = np.lib.stride_tricks.sliding_window_view(by_axis, n, axis=-1)[:, :: n // 2]
    frames = frames - frames.mean(axis=-1, keepdims=True)
    frames *= window
    spec = sp_fft.rfft(frames, axis=-1)
    return np.sum(spec.real**2 + spec.imag**2, axis=(0, 1))


def mean_removal_factor(cutoff_hz, order, sample_rate_hz, n_cycles):
    """Residual noise variance over the sensor's, after the averaged cycle is taken out.

    A sample ``e`` minus the low-passed mean of ``n`` cycles (itself among
    them) keeps ``1 - (2 h_0 - sum h^2) / n`` of its variance, with ``h``
    the forward-backward filter's impulse response: ``h_0`` and ``sum h^2``
    are the integrals of ``|H|^2`` and ``|H|^4`` over ``fs / 2``.

    Parameters
    ----------
    cutoff_hz : float
        Cutoff of the designed filter. [Hz]
    order : int
        Order of the designed filter.
    sample_rate_hz : float
        Sample rate. [Hz]
    n_cycles : float
        Cycles averaged.

    Returns
    -------
    float
    """
    h0, h2 = _response_integrals(float(cutoff_hz), int(order), float(sample_rate_hz))
    return float(1.0 - (2 * h0 - h2) / n_cycles)


@functools.lru_cache(maxsize=64)
def _response_integrals(cutoff_hz, order, sample_rate_hz):
    """``h_0`` and ``sum h^2`` of the forward-backward filter: the same for every file."""
    sos = design_lowpass(cutoff_hz, order, sample_rate_hz)
    f, h = signal.sosfreqz(sos, worN=1 << 14, fs=sample_rate_hz)
    g = np.abs(h) ** 2
    h0 = np.trapezoid(g, f) / (sample_rate_hz / 2)
    h2 = np.trapezoid(g**2, f) / (sample_rate_hz / 2)
    return float(h0), float(h2)


@dataclass(frozen=True)
class NoiseFloor:
    """The noise floor of one run.

    Attributes
    ----------
    noise_density_m_s2_rthz : float
        White density used for the bound: the sensor's stated one if known,
        else :attr:`residual_density_m_s2_rthz`. [m/s^2/sqrt(Hz)]
    source : str
        ``"sensor"`` (the recording states it) or ``"residual"`` (estimated).
    residual_density_m_s2_rthz : float
        White density of what the fitted model leaves, whatever the source. [m/s^2/sqrt(Hz)]
    flicker_corner_hz : float
        1/f corner of what the model leaves: 0 when not significant, NaN when
        the stretches are too short to tell. [Hz]
    circle_density_m_s2_rthz : float
        Noise density at the circle frequency, 1/f included. [m/s^2/sqrt(Hz)]
    analysed_s : float
        Time of data in the analysed cycles, both directions, gaps excluded. [s]
    crb_rad : float
        Cramér-Rao bound on ``theta_y - theta_x`` at :attr:`circle_density_m_s2_rthz`. [rad]
    crb_white_rad : float
        The same for the white density alone. [rad]
    """

    noise_density_m_s2_rthz: float
    source: str
    residual_density_m_s2_rthz: float
    flicker_corner_hz: float
    circle_density_m_s2_rthz: float
    analysed_s: float
    crb_rad: float
    crb_white_rad: float


def noise_floor(filtered, segmentation, cycles, mean_fit, sensor):
    """Noise density, its 1/f corner and the Cramér-Rao bound of one run.

    Parameters
    ----------
    filtered : FilteredRecording
        The samples, raw and low-passed.
    segmentation : Segmentation
        The blocks found.
    cycles : CycleTraces
        The cycles kept.
    mean_fit : MeanFit
        Fits of the directions' averaged cycles.
    sensor : SensorInfo
        What the recording says of the sensor.

    Returns
    -------
    NoiseFloor
    """
    fs = filtered.sample_rate_hz
    f0 = 1.0 / segmentation.period_s
    residuals = model_residual(filtered, segmentation, cycles, mean_fit)
    n = 0.5 * (cycles.ccw.n + cycles.cw.n)
    kept = mean_removal_factor(filtered.cutoff_hz, filtered.order, fs, n)
    residual = white_density(residuals, fs) / np.sqrt(kept)
    corner = flicker_corner(residuals, fs, f0, min(filtered.cutoff_hz / 2, fs / 4))
    stated = sensor.noise_density_m_s2_rthz
    if np.isfinite(stated) and stated > 0:
        density, source = float(stated), "sensor"
    else:
        density, source = residual, "residual"
    spectrum = NoiseSpectrum(density, corner)
    held = sum(np.count_nonzero(c.valid) for c in (cycles.ccw, cycles.cw))
    analysed_s = held / cycles.phi_grid.size * segmentation.period_s
    amplitude = mean_fit.amplitude_m_s2
    return NoiseFloor(
        noise_density_m_s2_rthz=density,
        source=source,
        residual_density_m_s2_rthz=residual,
        flicker_corner_hz=corner,
        circle_density_m_s2_rthz=spectrum.density_at(f0),
        analysed_s=analysed_s,
        crb_rad=squareness_noise_floor(spectrum, amplitude, analysed_s, f0),
        crb_white_rad=cramer_rao(density, amplitude, analysed_s),
    )
