"""The noise floor: white noise with a 1/f part, carried exactly through every window.

The sensor's noise has the power spectral density (the simulator's, docs/model.md)

    S(f) = sigma^2 (1 + f_c / f)       (one-sided, per sample: sigma^2 = d^2 fs / 2)

A feature is a windowed sum ``c = (1 / sum w) sum_i w_i x_i exp(-i k phi_i)``:
a cycle or a block of ``N`` cycles (rectangular window), or a cycle through
a Hann window (the noise estimate). Over a record of ``R`` circle periods
(its frequencies ``u_j = j / R`` in harmonics of the circle), with ``K`` the
window's response (``sinc(N u)`` for ``N`` cycles, ``sinc(u) / (1 - u^2)``
for the Hann window of mean 1),

    E|c_k|^2 = sigma^2 / n * [w2 + k_c (N / R) sum_j |K(u_j - k)|^2 / |u_j|]

with ``n`` the samples summed, ``w2 = n sum w^2 / (sum w)^2`` (1, or 1.5 for
the Hann window) and ``k_c = f_c / f_circle``. For large ``k`` the bracket
tends to ``w2 + k_c / k``; at low ``k`` the window's sidelobes let the strong
low-frequency power in, which this sum counts. Two cycles ``l`` apart are
correlated through the 1/f part:

    E[c_k(m) c_k(m + l)*]
        = sigma^2 / n * [delta_l + k_c (1 / R) sum_j |K|^2 cos(2 pi u_j l) / |u_j|]

:func:`estimate_noise` fits ``sigma^2`` and ``k_c`` to the scatter of the
Hann-windowed per-cycle coefficients about their block's mean, the offset
and octave by octave of harmonics from the 2nd: anything locked to the circle (the
effects, the model's errors) is the same in every cycle, to the end samples,
and drops out of that scatter.
"""

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

# Chi-square(1) at 10 %: a 1/f part is kept when it explains the scatter this much better
# (with few cycles a strong 1/f part can hide below a stricter level).
CORNER_CRITICAL = 2.71
# Harmonics above this take the kernel sums' asymptote 1/k.
_EXACT_HARMONICS = 64
# Frequencies summed: this many harmonics either side of the window's centre.
_SPAN = 300


def _sinc(x):
    return np.sinc(x)


def _hann(x):
    with np.errstate(divide="ignore", invalid="ignore"):
        h = np.sinc(x) / (1.0 - x * x)
    return np.where(np.abs(np.abs(x) - 1.0) < 1e-9, 0.5, h)


@lru_cache(maxsize=4096)
def flicker_sum(k, record_cycles, window="rect", n_cycles=1, lag=0):
    """``(N / R) sum_j |K(u_j - k)|^2 cos(2 pi u_j l) / |u_j|`` over the record's frequencies.

    Parameters
    ----------
    k : int
        Harmonic.
    record_cycles : float
        Record length in circle periods, ``R``.
    window : {"rect", "hann"}
        A rectangular window of ``n_cycles`` cycles, or a one-cycle Hann window.
    n_cycles : int
        Cycles the rectangular window spans.
    lag : int
        Cycles between the two windows (0 for a variance).

    Returns
    -------
    float
        The 1/f part's factor (multiplying ``k_c``).
    """
    if lag == 0 and k > _EXACT_HARMONICS:
        return (1.5 if window == "hann" else 1.0) / k
    j_max = int(np.ceil((k + _SPAN / max(n_cycles, 1)) * record_cycles))
    j = np.arange(-j_max, j_max + 1)
    j = j[j != 0]
    u = j / record_cycles
    kern = _hann(u - k) if window == "hann" else _sinc(n_cycles * (u - k))
    terms = kern**2 / np.abs(u)
    if lag:
        terms = terms * np.cos(2 * np.pi * u * lag)
    return float(n_cycles / record_cycles * np.sum(terms))


@dataclass(frozen=True)
class NoiseModel:
    """The noise floor of x and y.

    Attributes
    ----------
    sigma2 : ndarray, shape (2,)
        White-noise variance per sample of x and y. [(m/s^2)^2]
    corner_harmonic : ndarray, shape (2,)
        ``k_c = f_c / f_circle`` of x and y (0: white).
    dof : int
        Degrees of freedom of the scatter the estimate comes from.
    sample_rate_hz : float
        Sample rate. [Hz]
    frequency_hz : float
        Circle frequency. [Hz]
    record_cycles : float
        Record length in circle periods (the 1/f part's lowest frequency).
    """

    sigma2: np.ndarray
    corner_harmonic: np.ndarray
    dof: int
    sample_rate_hz: float
    frequency_hz: float
    record_cycles: float

    @property
    def density_m_s2_rthz(self):
        """White-noise density of x and y, ``sigma / sqrt(fs / 2)``. [m/s^2/sqrt(Hz)]"""
        return np.sqrt(self.sigma2 / (0.5 * self.sample_rate_hz))

    @property
    def flicker_corner_hz(self):
        """1/f corner frequency of x and y. [Hz]"""
        return self.corner_harmonic * self.frequency_hz

    def coef_var(self, axis, k, n, n_cycles=1):
        """``E|c_k|^2`` of a coefficient over ``n`` samples spanning ``n_cycles`` whole cycles.

        Parameters
        ----------
        axis : int
            0 for x, 1 for y.
        k : int or ndarray of int
            Harmonic(s).
        n : float
            Samples summed.
        n_cycles : int
            Cycles the (rectangular) window spans.

        Returns
        -------
        float or ndarray
            [(m/s^2)^2]
        """
        kc = self.corner_harmonic[axis]
        k = np.asarray(k)
        if kc == 0:
            return np.full(k.shape, self.sigma2[axis] / n)
        f = np.array(
            [flicker_sum(int(v), self.record_cycles, "rect", int(n_cycles)) for v in k.ravel()]
        )
        return self.sigma2[axis] * (1.0 + kc * f.reshape(k.shape)) / n

    def cycle_cov(self, axis, k, n, positions):
        """Covariance of one harmonic over cycles of ``n`` samples at given places.

        Parameters
        ----------
        axis : int
            0 for x, 1 for y.
        k : int
            Harmonic.
        n : float
            Samples per cycle.
        positions : ndarray of int
            Each cycle's number in its block (consecutive cycles differ by 1).

        Returns
        -------
        ndarray, shape (len(positions), len(positions))
            ``E[c_k(m) c_k(m')*]`` (its real part). [(m/s^2)^2]
        """
        positions = np.asarray(positions, dtype=int)
        lag = np.abs(positions[:, None] - positions[None, :])
        kc = self.corner_harmonic[axis]
        col = np.zeros(int(lag.max()) + 1)
        col[0] = 1.0
        if kc:
            col += kc * np.array(
                [
                    flicker_sum(int(k), self.record_cycles, "rect", 1, int(v))
                    for v in range(col.size)
                ]
            )
        return self.sigma2[axis] / n * col[lag]


def _octaves(k_max):
    edges, lo = [], 2
    while lo <= k_max:
        hi = min(2 * lo - 1, k_max)
        edges.append((lo, hi))
        lo = hi + 1
    return edges


def _scatter_factor(k, record_cycles, sizes):
    """The 1/f factor of the scatter about a block's mean, Hann-windowed cycles.

    For ``N`` consecutive cycles with covariance ``F(|i - j|)`` (lags from
    :func:`flicker_sum`), ``E sum_j |c_j - mean|^2 / (N - 1) = [N F(0) - sum_ij
    F(|i - j|) / N] / (N - 1)``: neighbouring cycles share the slow part of a
    1/f noise, which the block's mean takes away. Beyond the 8th harmonic the
    cycles' correlation is negligible.
    """
    f0 = flicker_sum(int(k), record_cycles, "hann")
    if k > 8:
        return f0
    out, weight = 0.0, 0
    for n in sizes:
        lags = np.abs(np.subtract.outer(np.arange(n), np.arange(n)))
        f = np.array([flicker_sum(int(k), record_cycles, "hann", 1, int(v)) for v in range(n)])
        out += n * f0 - f[lags].sum() / n
        weight += n - 1
    return out / weight


def estimate_noise(spectra, layout, sample_rate_hz, record_s):
    """White-noise variance and 1/f corner from the cycle-to-cycle scatter.

    Per channel, for the offset (k = 0: nothing of the simulator's vocabulary
    changes it from cycle to cycle, and a 1/f part shows there most) and each
    octave of harmonics (2-3, 4-7, ...), the mean of
    ``n0 |c_k - mean_b(c_k)|^2 / (1 - 1/N_b)`` over the Hann-windowed cycles of
    each block estimates ``sigma^2 (1.5 + k_c h_k)``, ``h_k`` the Hann
    window's 1/f factor of that scatter (:func:`_scatter_factor`). A weighted least-squares fit
    over the octaves gives ``sigma^2`` and ``sigma^2 k_c``; the 1/f part is
    kept if it lowers the weighted sum of squares by more than
    :data:`CORNER_CRITICAL` (chi-square, 1 degree of freedom, at 10 %),
    white noise otherwise.
    An octave's estimate has relative variance ``2 / dof``; the weights are
    taken from the fitted values, iterated, since weights from the observed
    ones would favour the octaves that came out low and bias ``k_c`` down.

    Parameters
    ----------
    spectra : ndarray of complex, shape (n_cycles, 2, K + 1)
        Hann-windowed per-cycle harmonics (:meth:`FeatureOperator.cycle_spectra`). [m/s^2]
    layout : Layout
        Where each cycle belongs.
    sample_rate_hz : float
        Sample rate. [Hz]
    record_s : float
        Length of the recording. [s]

    Returns
    -------
    NoiseModel
    """
    k_max = spectra.shape[-1] - 1
    n0 = float(np.diff(layout.cycle_edges).min())
    record_cycles = record_s / layout.period_s
    dev = np.empty_like(spectra)
    factor = np.empty(layout.n_cycles)
    for b in range(len(layout.blocks)):
        sel = layout.cycle_block == b
        n_b = int(np.sum(sel))
        dev[sel] = spectra[sel] - spectra[sel].mean(axis=0)
        factor[sel] = 1.0 - 1.0 / n_b if n_b > 1 else np.nan
    ok = np.isfinite(factor)
    power = np.abs(dev[ok]) ** 2 * (n0 / factor[ok])[:, None, None]
    n_groups = len({int(b) for b in layout.cycle_block[ok]})
    dof_per_k = 2 * (int(np.sum(ok)) - n_groups)
    # the offset (k = 0, real: half the degrees of freedom) feels a 1/f part most, and
    # nothing of the vocabulary changes it from cycle to cycle; then octaves from k = 2
    octaves = [(0, 0), *_octaves(k_max)]
    sizes = [int(np.sum(layout.cycle_block == b)) for b in range(len(layout.blocks))]
    sizes = [n for n in sizes if n > 1]
    h = np.array(
        [
            np.mean([_scatter_factor(k, record_cycles, sizes) for k in range(lo, hi + 1)])
            for lo, hi in octaves
        ]
    )
    w = np.array([dof_per_k * (hi - lo + 1) for lo, hi in octaves], dtype=float)
    w[0] = dof_per_k / 2
    sigma2 = np.empty(2)
    corner = np.empty(2)
    for a in range(2):
        v = np.array([np.mean(power[:, a, lo : hi + 1]) for lo, hi in octaves])
        white_only = float(np.sum(w * v) / np.sum(w)) / 1.5
        white, slope = white_only, 0.0
        # weights from the predicted values (the observed ones would favour low octaves)
        predicted = v
        for _ in range(4):
            scale = np.sqrt(w / 2) / predicted
            design = np.column_stack([np.full_like(h, 1.5), h]) * scale[:, None]
            (white, slope), *_ = np.linalg.lstsq(design, v * scale, rcond=None)
            predicted = np.maximum(1.5 * white + slope * h, 1e-3 * v)
        white, slope = float(white), float(slope)
        gain = float(
            np.sum(((v - 1.5 * white_only) * scale) ** 2)
            - np.sum(((v - 1.5 * white - slope * h) * scale) ** 2)
        )
        if slope <= 0 or white <= 0 or gain < CORNER_CRITICAL:  # no 1/f part to see
            white, slope = white_only, 0.0
        sigma2[a] = white
        corner[a] = slope / white
    dof = dof_per_k * (k_max - 1)
    return NoiseModel(sigma2, corner, dof, sample_rate_hz, layout.frequency_hz, record_cycles)
