"""The three charts run on arrays of nights: for a machine's history and for Monte Carlo.

One recursion serves both: :func:`chart_statistics` takes ``z`` of shape
``(..., n_nights)`` and returns the EWMA and both CUSUM halves night by night,
vectorised over paths and nights alike (the EWMA by a linear filter, each
CUSUM half by Lindley's solution ``C_t = S_t - min(0, min_{s <= t} S_s)`` of
``C_t = max(0, C_{t-1} + z_t - k)``, with ``S_t`` the running sum of
``z - k`` from ``C_0``).

The Monte Carlo functions draw nights from :class:`NightSampler` (normal or
Student's t, a mean that may change from night to night, and a per-path
offset for the baseline's error) and return what the tests and the benchmark
compare with the computed ARLs: first alarms without restarts
(:func:`first_alarms`), and a renewal process with restarts after every
alarm (:func:`alarm_counts`), whose long-run alarm rate is one over the ARL.
"""

from dataclasses import dataclass

import numpy as np
from scipy import signal

CHARTS = ("shewhart", "ewma", "cusum")


@dataclass(frozen=True)
class ChartLimits:
    """Parameters and limits of the three charts run together on ``z``.

    Attributes
    ----------
    shewhart : float
        Limit on ``|z|``. [1]
    ewma_lambda : float
        EWMA smoothing constant. [1]
    ewma : float
        Limit on ``|EWMA|``. [1]
    cusum_k : float
        CUSUM reference value. [1]
    cusum : float
        CUSUM decision interval (limit on ``C+`` and ``C-``). [1]
    """

    shewhart: float
    ewma_lambda: float
    ewma: float
    cusum_k: float
    cusum: float

    def exceeded(self, z, ewma, cusum_pos, cusum_neg):
        """Which chart is past its limit, night by night.

        Parameters
        ----------
        z, ewma, cusum_pos, cusum_neg : ndarray
            Statistics of the same shape. [1]

        Returns
        -------
        ndarray of bool, shape ``(3,) + z.shape``
            Shewhart, EWMA and CUSUM, in :data:`CHARTS` order.
        """
        return np.stack(
            [
                np.abs(z) > self.shewhart,
                np.abs(ewma) > self.ewma,
                np.maximum(cusum_pos, cusum_neg) > self.cusum,
            ]
        )


def chart_statistics(z, ewma_lambda, cusum_k, start=None):
    """EWMA and two-sided CUSUM of ``z`` along its last axis.

    Parameters
    ----------
    z : ndarray, shape (..., n_nights)
        Standardised changes in time order. [1]
    ewma_lambda : float
        EWMA smoothing constant. [1]
    cusum_k : float
        CUSUM reference value. [1]
    start : tuple of 3 ndarray, optional
        ``(ewma, cusum_pos, cusum_neg)`` before the first night, each of
        shape ``z.shape[:-1]``; default all zero (a fresh start). [1]

    Returns
    -------
    ewma, cusum_pos, cusum_neg : ndarray, shape of ``z``
        ``E_t = (1 - lam) E_{t-1} + lam z_t``;
        ``C+_t = max(0, C+_{t-1} + z_t - k)``; ``C-_t = max(0, C-_{t-1} - z_t - k)``. [1]
    """
    z = np.asarray(z, dtype=np.float64)
    lead = z.shape[:-1]
    e0, p0, n0 = (np.zeros(lead),) * 3 if start is None else (np.asarray(s) for s in start)
    lam = ewma_lambda
    ewma, _ = signal.lfilter([lam], [1.0, lam - 1.0], z, axis=-1, zi=((1.0 - lam) * e0)[..., None])
    return ewma, _lindley(p0, z - cusum_k), _lindley(n0, -z - cusum_k)


def _lindley(c0, steps):
    s = c0[..., None] + np.cumsum(steps, axis=-1)
    return s - np.minimum(np.minimum.accumulate(s, axis=-1), 0.0)


@dataclass(frozen=True)
class NightSampler:
    """Random nights: ``z = (Z + mean_t + offset_p) / sqrt(W / nu)``.

    Attributes
    ----------
    nu : float or None
        Degrees of freedom (``W ~ chi2(nu)``); ``None`` for the normal.
    mean : ndarray, shape (n,) or float
        True change night by night over the night's sigma; beyond the end of
        the array the last value holds. [1]
    offsets : ndarray, shape (n_paths,) or None
        Per-path constant (minus the baseline's error over sigma). [1]
    """

    nu: float | None = None
    mean: object = 0.0
    offsets: object = None

    def draw(self, rng, paths, first, n):
        """Nights ``first .. first + n - 1`` of the given paths.

        Parameters
        ----------
        rng : numpy.random.Generator
            Random source.
        paths : ndarray of int
            Path indices (for their offsets).
        first : int
            Index of the first night (0-based).
        n : int
            Number of nights.

        Returns
        -------
        ndarray, shape (len(paths), n)
            Standardised changes. [1]
        """
        z = rng.standard_normal((paths.size, n))
        mean = np.atleast_1d(np.asarray(self.mean, dtype=np.float64))
        z += mean[np.minimum(np.arange(first, first + n), mean.size - 1)]
        if self.offsets is not None:
            z += np.asarray(self.offsets)[paths][:, None]
        if self.nu is not None:
            z /= np.sqrt(rng.chisquare(self.nu, size=z.shape) / self.nu)
        return z


def first_alarms(limits, sampler, n_paths, max_nights, rng, burn_in=0, per_chart=True, block=256):
    """Night of each chart's first alarm on independent paths, without restarts.

    Parameters
    ----------
    limits : ChartLimits
        The charts.
    sampler : NightSampler
        The nights; night ``burn_in`` is the first counted one.
    n_paths : int
        Number of paths.
    max_nights : int
        Nights simulated after the burn-in; later alarms are censored.
    rng : numpy.random.Generator
        Random source.
    burn_in : int, optional
        Nights run before counting; a path whose chart alarms during them is
        dropped for that chart (the conditional steady state).
    per_chart : bool, optional
        Follow each path until every chart has fired (True) or only until
        the first alarm of any (False: only ``"combined"`` is then complete).
    block : int, optional
        Nights simulated at once.

    Returns
    -------
    dict of str to ndarray, shape (n_paths,)
        Per chart of :data:`CHARTS` and ``"combined"`` (the first of the
        three): run length counted from the first night after the burn-in
        (1 = that night) [nights]; ``inf`` if censored, ``nan`` if dropped.
    """
    total = burn_in + max_nights
    first = np.full((4, n_paths), np.inf)  # night index of the first alarm
    state = (np.zeros(n_paths),) * 3
    active = np.arange(n_paths)
    for start in range(0, total, block):
        n = min(block, total - start)
        z = sampler.draw(rng, active, start, n)
        stats = chart_statistics(z, limits.ewma_lambda, limits.cusum_k, [s[active] for s in state])
        over = limits.exceeded(z, *stats)
        over = np.concatenate([over, over.any(axis=0)[None]])
        hit = over.any(axis=2)
        idx = np.where(hit, np.argmax(over, axis=2) + start, np.inf)
        first[:, active] = np.minimum(first[:, active], idx)
        state = tuple(np.zeros(n_paths) for _ in range(3))
        for s, value in zip(state, stats, strict=True):
            s[active] = value[:, -1]
        done = (
            np.isfinite(first[:3, active]).all(axis=0)
            if per_chart
            else np.isfinite(first[3, active])
        )
        active = active[~done]
        if active.size == 0:
            break
    out = {}
    for i, name in enumerate((*CHARTS, "combined")):
        rl = first[i] - burn_in + 1.0
        out[name] = np.where(first[i] < burn_in, np.nan, rl)
    return out


def alarm_counts(limits, warnings, sampler, n_paths, n_nights, rng, block=256):
    """A renewal process: the charts restart from zero after every alarm.

    Parameters
    ----------
    limits : ChartLimits
        Alarm limits.
    warnings : ChartLimits or None
        Warning limits (same ``ewma_lambda`` and ``cusum_k``).
    sampler : NightSampler
        The nights.
    n_paths : int
        Number of independent paths (machines).
    n_nights : int
        Nights per path.
    rng : numpy.random.Generator
        Random source.
    block : int, optional
        Nights simulated at once.

    Returns
    -------
    dict
        ``alarms``: ndarray (n_paths,), alarms per path; ``by_chart``: dict of
        ndarray (n_paths,), alarms on which each chart fired (several may fire
        on one night); ``warning_nights``: ndarray (n_paths,), nights in the
        warning state (a warning limit passed, no alarm); ``warning_onsets``:
        ndarray (n_paths,), warning nights that follow a night not in
        warning; ``n_nights``.
    """
    alarms = np.zeros(n_paths, dtype=np.int64)
    by_chart = np.zeros((3, n_paths), dtype=np.int64)
    warned = np.zeros(n_paths, dtype=np.int64)
    onsets = np.zeros(n_paths, dtype=np.int64)
    last_warned = np.zeros(n_paths, dtype=bool)
    state = (np.zeros(n_paths),) * 3
    cols = np.arange(block)
    for first in range(0, n_nights, block):
        n = min(block, n_nights - first)
        z = sampler.draw(rng, np.arange(n_paths), first, n)
        alarm = np.zeros(z.shape, dtype=bool)
        warn = np.zeros(z.shape, dtype=bool)
        final = [np.zeros(n_paths) for _ in range(3)]
        # Rows still running, the night their current run starts, and their state.
        rows, begin, st = np.arange(n_paths), np.zeros(n_paths, dtype=np.int64), state
        while rows.size:
            zz = np.where(cols[None, :n] >= begin[:, None], z[rows], 0.0)
            stats = chart_statistics(zz, limits.ewma_lambda, limits.cusum_k, st)
            over = limits.exceeded(zz, *stats)
            hit = over.any(axis=0).any(axis=1)
            at = np.where(hit, np.argmax(over.any(axis=0), axis=1), n - 1)
            if warnings is not None:
                live = (cols[None, :n] >= begin[:, None]) & (cols[None, :n] <= at[:, None])
                warn[rows] |= warnings.exceeded(zz, *stats).any(axis=0) & live
            for f, value in zip(final, stats, strict=True):
                f[rows[~hit]] = value[~hit, -1]
            alarm[rows[hit], at[hit]] = True
            by_chart[:, rows[hit]] += over[:, hit, at[hit]]
            # A restart the night after the alarm: zero before it, zero state.
            again = hit & (at < n - 1)
            rows, begin = rows[again], at[again] + 1
            st = (np.zeros(rows.size),) * 3
        warn &= ~alarm
        previous = np.concatenate([last_warned[:, None], warn[:, :-1]], axis=1)
        alarms += alarm.sum(axis=1)
        warned += warn.sum(axis=1)
        onsets += (warn & ~previous).sum(axis=1)
        last_warned = warn[:, -1]
        state = tuple(final)
    return {
        "alarms": alarms,
        "by_chart": dict(zip(CHARTS, by_chart, strict=True)),
        "warning_nights": warned,
        "warning_onsets": onsets,
        "n_nights": n_nights,
    }
