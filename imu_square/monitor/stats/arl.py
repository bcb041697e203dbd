"""Average run lengths of the Shewhart, EWMA and CUSUM charts on the standardised change.

The monitor charts ``z = Delta / u``: the change of a night's squareness
against the baseline over the night's own standard uncertainty. In control,
``z`` follows :class:`NightLaw`: the standard normal, or Student's t with
``nu`` degrees of freedom when ``u`` is a type A uncertainty from ``nu + 1``
cycle pairs (the mean of normal values over its standard error). A step of
``delta`` standard deviations moves the numerator only, so ``z`` then follows
the noncentral t with noncentrality ``delta`` (``N(delta, 1)`` for the normal),
not a shifted t.

The average run length (ARL, the expected number of nights up to and
including the first alarm) of each chart solves an integral equation, which
is discretised by the Nyström method with Gauss–Legendre nodes [3]_, [4]_
(the approach of Knoth's R package ``spc``); its error falls exponentially
with the number of nodes, and :func:`quadrature_error` measures it by
doubling them:

- Shewhart, alarm when ``|z| > L``: ``ARL = 1 / P(|z| > L)``.
- EWMA, ``E_0 = 0``, ``E_t = (1 - lam) E_{t-1} + lam z_t``, alarm when
  ``|E_t| > h`` [2]_::

      L(x) = 1 + (1/lam) int_{-h}^{h} L(y) f((y - (1 - lam) x) / lam) dy,  ARL = L(0)

- one-sided CUSUM, ``C_0 = 0``, ``C_t = max(0, C_{t-1} + z_t - k)``, alarm when
  ``C_t > h`` [1]_::

      L(x) = 1 + L(0) F(k - x) + int_0^h L(y) f(y + k - x) dy,  ARL = L(0)

  (the lower half is the upper half of ``-z``). The two-sided CUSUM's ARL
  follows from the halves by ``1/ARL = 1/ARL+ + 1/ARL-`` [5]_ (Van Dobben de
  Bruyn): exact when the halves cannot be non-zero together, otherwise an
  approximation; the tests show it within Monte Carlo error of the real
  two-sided chart.

The steady-state (conditional) ARL assumes the chart has run in control for a
long time without an alarm when the step comes: the state is then distributed
as the quasi-stationary law, the left Perron eigenvector of the discretised
in-control kernel, and the ARL is that law's mean of ``L(x)``.

The baseline is the mean of a few runs, so its error ``e`` is common to every
night: given ``e``, ``z`` is noncentral with ``delta = -e / sigma``.
:func:`baseline_average` averages over ``e ~ N(0, (rho sigma)^2)`` by
Gauss–Hermite quadrature.

References
----------
.. [1] E. S. Page, "Continuous inspection schemes", Biometrika 41 (1954).
.. [2] S. V. Crowder, "A simple method for studying run-length distributions
   of exponentially weighted moving average charts", Technometrics 29 (1987).
.. [3] L. C. Vance, "Average run lengths of cumulative sum control charts
   for controlling normal means", J. Quality Technology 18 (1986).
.. [4] S. Knoth, "Accurate ARL computation for EWMA-S^2 control charts",
   Statistics and Computing 15 (2005).
.. [5] J. M. Lucas, R. B. Crosier, "Fast initial response for CUSUM
   quality-control schemes", Technometrics 24 (1982).
"""

import math
from dataclasses import dataclass, replace
from functools import lru_cache

import numpy as np
from numpy.polynomial.legendre import leggauss
from scipy import interpolate, optimize, special, stats

_SQRT_2PI = math.sqrt(2.0 * math.pi)
# Gauss-Legendre nodes each side for the baseline's error; the tests compare with 48.
_BASELINE_NODES = 16
# Gauss-Legendre nodes per kernel width (lam for the EWMA, 1 for the CUSUM)
# across the chart's range, and the bounds; the tests check doubling them.
_EWMA_NODES_PER_WIDTH = 2.5
_CUSUM_NODES_PER_WIDTH = 2.0
_MIN_NODES, _MAX_NODES = 24, 400
# The grid the noncentral t's density is interpolated from: spacing in
# u = asinh(x / scale), and the scale. [1]
_PDF_GRID, _PDF_SCALE = 0.01, 3.0
# The noncentral t's density: its integrand's window, in widths above the peak
# and at least this many nats of decay below it, and the trapezoid's step in
# widths (1e-13 of the peak against a rule of a fifth of the step).
_NCT_WINDOW, _NCT_DEPTH, _NCT_STEP = 12.0, 40.0, 0.25
# Below this the limit is 0: the chart's most sensitive setting. [1]
_MIN_LIMIT = 1e-6
# Run lengths beyond this are "never" to double precision: the linear system
# that gives them is singular to rounding. [nights]
_ARL_CAP = 1e12


@dataclass(frozen=True)
class NightLaw:
    """Law of one night's standardised change ``z``.

    Attributes
    ----------
    nu : float or None
        Degrees of freedom of Student's t; ``None`` for the normal.
    shift : float
        Noncentrality: the true change over the night's standard deviation. [1]
    """

    nu: float | None = None
    shift: float = 0.0

    def pdf(self, x):
        """Probability density of ``z``.

        Parameters
        ----------
        x : array-like
            Where to evaluate it. [1]

        Returns
        -------
        ndarray
            The density, shaped like ``x``. [1]

        Notes
        -----
        The noncentral t's density is :func:`noncentral_t_pdf`. On large
        arrays it is evaluated exactly on a grid uniform in
        ``u = asinh(x / _PDF_SCALE)`` (fine in the core, coarser in the tails
        where the density varies on a scale proportional to ``|x|``) and
        interpolated by a cubic spline in ``u``, whose error (below 1e-8 of
        the peak) is far below the quadrature's.
        """
        x = np.asarray(x, dtype=np.float64)
        if self.nu is None:
            return np.exp(-0.5 * (x - self.shift) ** 2) / _SQRT_2PI
        if self.shift == 0.0:
            return stats.t.pdf(x, self.nu)
        u = np.arcsinh(x / _PDF_SCALE)
        lo, hi = float(np.min(u, initial=0.0)), float(np.max(u, initial=0.0))
        n_grid = math.ceil((hi - lo) / _PDF_GRID) + 1
        if x.size <= 2 * n_grid:
            return noncentral_t_pdf(x, self.nu, self.shift)
        grid = np.linspace(lo, hi, n_grid)
        exact = noncentral_t_pdf(_PDF_SCALE * np.sinh(grid), self.nu, self.shift)
        return interpolate.CubicSpline(grid, exact)(u)

    def cdf(self, x):
        """Distribution function of ``z``.

        Parameters
        ----------
        x : array-like
            Where to evaluate it. [1]

        Returns
        -------
        ndarray
            ``P(z <= x)``, shaped like ``x``. [1]
        """
        x = np.asarray(x, dtype=np.float64)
        if self.nu is None:
            return special.ndtr(x - self.shift)
        if self.shift == 0.0:
            return special.stdtr(self.nu, x)
        out = np.asarray(special.nctdtr(self.nu, self.shift, x), dtype=np.float64)
        # nctdtr gives NaN where the probability underflows, far out in a tail: it is
        # 0 below the law's centre and 1 above it, to double precision.
        lost = np.isnan(out)
        if lost.any():
            out = np.where(lost, (x > self.shift).astype(np.float64), out)
        return out

    def mirrored(self):
        """The law of ``-z``."""
        return replace(self, shift=-self.shift)

    def shifted(self, by):
        """The law after the true change moves.

        Parameters
        ----------
        by : float
            The move, in the night's standard deviations. [1]

        Returns
        -------
        NightLaw
        """
        return replace(self, shift=self.shift + float(by))

    def tail(self, limit):
        """Two-sided tail probability, accurate in the far tails.

        Parameters
        ----------
        limit : float
            Threshold, ``>= 0``. [1]

        Returns
        -------
        float
            ``P(|z| > limit)``. [1]
        """
        if self.nu is None:
            return float(special.ndtr(self.shift - limit) + special.ndtr(-limit - self.shift))
        if self.shift == 0.0:
            return float(2.0 * stats.t.sf(limit, self.nu))
        upper = stats.nct.sf(limit, self.nu, self.shift)
        lower = stats.nct.cdf(-limit, self.nu, self.shift)
        # scipy gives NaN where a tail underflows; on the side away from the shift that
        # tail is 0 to double precision, and the other side is then the whole answer.
        if math.isnan(lower):
            lower = 0.0 if self.shift > -limit else 1.0
        if math.isnan(upper):
            upper = 0.0 if self.shift < limit else 1.0
        return float(upper + lower)


def noncentral_t_pdf(x, nu, shift):
    """Density of the noncentral t, finite for every ``nu`` and ``x``.

    scipy's ``stats.nct.pdf`` gives NaN, or raises ``OverflowError`` in its
    gamma function, where ``x`` and ``shift`` differ in sign and ``nu`` is a few
    hundred or more: the degrees of freedom of a test of a few hundred cycles.
    Here the density is the integral over the scaled chi ``s`` of the
    denominator, ``f(x) = int s phi(x s - shift) f_S(s) ds``, taken in
    ``u = log s`` where its logarithm is ``(nu + 1) u - nu s^2 / 2 - (x s -
    shift)^2 / 2`` plus a constant: everything stays in logarithms, and the
    integrand's peak ``s*`` (the root of a quadratic) and its curvature give the
    window and the step of a trapezoid rule, exponentially accurate for such a
    smooth integrand (within 1e-10 of the peak of scipy's density where
    scipy's is finite, ``tests/test_monitor_arl_long.py``).

    Parameters
    ----------
    x : array-like
        Where to evaluate it. [1]
    nu : float
        Degrees of freedom, > 0. [1]
    shift : float
        Noncentrality. [1]

    Returns
    -------
    ndarray
        The density, shaped like ``x``. [1]
    """
    x = np.asarray(x, dtype=np.float64)
    quad_a, cross = nu + x * x, shift * x
    peak = (cross + np.sqrt(cross * cross + 4.0 * quad_a * (nu + 1.0))) / (2.0 * quad_a)
    width = 1.0 / np.sqrt(cross * peak + 2.0 * (nu + 1.0))  # 1 / sqrt(-d2/du2) at the peak
    # Above the peak the integrand falls like exp(-e^(2u)); below it only like
    # exp((nu + 1) u), which for small nu needs a longer window.
    below = np.maximum(_NCT_WINDOW * width, _NCT_DEPTH / (nu + 1.0))
    span = below + _NCT_WINDOW * width
    n = math.ceil(float(np.max(span / (_NCT_STEP * width), initial=1.0))) + 1
    u = (np.log(peak) - below)[..., None] + span[..., None] * np.linspace(0.0, 1.0, n)
    s = np.exp(u)
    log_c = (
        math.log(2.0 * nu)
        + (0.5 * nu - 1.0) * math.log(nu)
        - 0.5 * nu * math.log(2.0)
        - special.gammaln(0.5 * nu)
        - 0.5 * math.log(2.0 * math.pi)
    )
    f = np.exp(log_c + (nu + 1.0) * u - 0.5 * nu * s * s - 0.5 * (x[..., None] * s - shift) ** 2)
    return (f.sum(axis=-1) - 0.5 * (f[..., 0] + f[..., -1])) * span / (n - 1)


@lru_cache(maxsize=64)
def _legendre(n):
    """Gauss–Legendre nodes and weights on [-1, 1] (cached: they cost an eigensolve)."""
    return leggauss(n)


def _clip_nodes(n):
    return int(min(max(math.ceil(n), _MIN_NODES), _MAX_NODES))


@dataclass(frozen=True)
class Shewhart:
    """Two-sided Shewhart chart: alarm when ``|z| > limit``.

    Attributes
    ----------
    limit : float
        Alarm limit on ``|z|``. [1]
    """

    limit: float

    def arl(self, law, nodes=None):
        """Average run length (zero-state and steady-state alike). [nights]

        Parameters
        ----------
        law : NightLaw
            Law of ``z``.
        nodes : None
            Unused (the ARL is exact); accepted for a uniform interface.
        """
        p = law.tail(self.limit)
        return math.inf if p <= 0.0 else 1.0 / p

    def steady_state_arl(self, law, in_control, nodes=None):
        """Same as :meth:`arl`: a Shewhart chart has no memory. [nights]"""
        return self.arl(law)

    def occupancy(self, law, nodes=None):
        """``P(w < |z| <= limit)`` as a function of ``w``: the nights past ``w`` without an alarm.

        Parameters
        ----------
        law : NightLaw
            Law of ``z``.
        nodes : None
            Unused; accepted for a uniform interface.

        Returns
        -------
        callable
            ``w`` in ``[0, limit]`` [1] -> fraction of nights [1].
        """
        beyond = law.tail(self.limit)
        return lambda w: law.tail(w) - beyond


@dataclass(frozen=True)
class Ewma:
    """Two-sided EWMA chart on ``z``, started at 0.

    Attributes
    ----------
    lam : float
        Smoothing constant, ``0 < lam <= 1``. [1]
    limit : float
        Alarm limit ``h`` on ``|E_t|`` (in units of ``z``, not of the EWMA's
        standard deviation). [1]
    """

    lam: float
    limit: float

    def default_nodes(self):
        """Gauss–Legendre nodes: a few per kernel width ``lam`` across ``2 h``."""
        return _clip_nodes(_EWMA_NODES_PER_WIDTH * 2.0 * self.limit / self.lam + _MIN_NODES)

    def _kernel(self, law, n):
        x, w = _legendre(n)
        y, wy = self.limit * x, self.limit * w
        lam = self.lam
        a = wy[None, :] / lam * law.pdf((y[None, :] - (1.0 - lam) * y[:, None]) / lam)
        start = wy / lam * law.pdf(y / lam)  # from E = 0 to each node
        return y, a, start

    def _solve(self, law, n):
        _, a, start = self._kernel(law, n)
        values = _run_lengths(np.eye(n) - a)
        return values, start

    def arl(self, law, nodes=None):
        """Zero-state average run length. [nights]

        Parameters
        ----------
        law : NightLaw
            Law of ``z``.
        nodes : int, optional
            Gauss–Legendre nodes; default :meth:`default_nodes`.
        """
        values, start = self._solve(law, nodes or self.default_nodes())
        return _capped(1.0 + start @ values)

    def steady_state_arl(self, law, in_control, nodes=None):
        """Conditional steady-state average run length. [nights]

        Parameters
        ----------
        law : NightLaw
            Law of ``z`` after the change.
        in_control : NightLaw
            Law of ``z`` before it, which sets the quasi-stationary state.
        nodes : int, optional
            Gauss–Legendre nodes; default :meth:`default_nodes`.
        """
        n = nodes or self.default_nodes()
        _, a0, _ = self._kernel(in_control, n)
        values, _ = self._solve(law, n)
        return _capped(_quasi_stationary(a0)[0] @ values)

    def occupancy(self, law, nodes=None):
        """``P(|E| > w)`` in the quasi-stationary state, as a function of ``w``.

        The state after a night, given no alarm so far, long after the start:
        with the quasi-stationary masses ``p_i`` at the nodes ``y_i`` and
        eigenvalue ``r``, its density is ``(1/r) sum_i p_i f((y - (1 - lam)
        y_i) / lam) / lam``, integrated exactly through ``F``.

        Parameters
        ----------
        law : NightLaw
            Law of ``z``.
        nodes : int, optional
            Gauss–Legendre nodes; default :meth:`default_nodes`.

        Returns
        -------
        callable
            ``w`` in ``[0, limit]`` [1] -> fraction of nights with ``|E| > w`` [1].
        """
        y, a, _ = self._kernel(law, nodes or self.default_nodes())
        p, r = _quasi_stationary(a)
        m, lam, h = (1.0 - self.lam) * y, self.lam, self.limit
        outer = law.cdf((h - m) / lam) - law.cdf((-h - m) / lam)

        def fraction(w):
            inner = law.cdf((w - m) / lam) - law.cdf((-w - m) / lam)
            return float(p @ (outer - inner) / r)

        return fraction


@dataclass(frozen=True)
class Cusum:
    """Two-sided CUSUM chart on ``z``, both halves started at 0.

    Attributes
    ----------
    k : float
        Reference value (allowance), ``k >= 0``. [1]
    limit : float
        Decision interval ``h``: alarm when ``C+ > h`` or ``C- > h``. [1]
    """

    k: float
    limit: float

    def default_nodes(self):
        """Gauss–Legendre nodes: a few per unit of ``z`` across ``h``."""
        return _clip_nodes(_CUSUM_NODES_PER_WIDTH * self.limit + _MIN_NODES)

    def _kernel(self, law, n):
        x, w = _legendre(n)
        h = self.limit
        y, wy = 0.5 * h * (x + 1.0), 0.5 * h * w
        points = np.concatenate([[0.0], y])  # the atom at 0, then the nodes
        a = np.empty((n + 1, n + 1))
        a[:, 0] = law.cdf(self.k - points)
        a[:, 1:] = wy[None, :] * law.pdf(y[None, :] + self.k - points[:, None])
        return a

    def _upper(self, law, n):
        return _run_lengths(np.eye(n + 1) - self._kernel(law, n))

    def one_sided_arl(self, law, nodes=None):
        """Zero-state ARL of the upper half alone (``C+``). [nights]

        Parameters
        ----------
        law : NightLaw
            Law of ``z``; the lower half's is ``law.mirrored()``.
        nodes : int, optional
            Gauss–Legendre nodes; default :meth:`default_nodes`.
        """
        return _capped(self._upper(law, nodes or self.default_nodes())[0])

    def arl(self, law, nodes=None):
        """Zero-state ARL of the two-sided chart, ``1/ARL = 1/ARL+ + 1/ARL-``. [nights]

        Parameters
        ----------
        law : NightLaw
            Law of ``z``.
        nodes : int, optional
            Gauss–Legendre nodes; default :meth:`default_nodes`.
        """
        up = self.one_sided_arl(law, nodes)
        down = up if law.shift == 0.0 else self.one_sided_arl(law.mirrored(), nodes)
        return _either(up, down)

    def steady_state_arl(self, law, in_control, nodes=None):
        """Conditional steady-state ARL, each half from its own quasi-stationary state. [nights]

        Parameters
        ----------
        law : NightLaw
            Law of ``z`` after the change.
        in_control : NightLaw
            Law of ``z`` before it.
        nodes : int, optional
            Gauss–Legendre nodes; default :meth:`default_nodes`.
        """
        n = nodes or self.default_nodes()
        halves = []
        for after, before in ((law, in_control), (law.mirrored(), in_control.mirrored())):
            start = _quasi_stationary(self._kernel(before, n))[0]
            lengths = self._upper(after, n)
            halves.append(math.inf if np.isinf(lengths).any() else _capped(start @ lengths))
        return _either(*halves)

    def occupancy(self, law, nodes=None):
        """``P(C+ > w) + P(C- > w)`` in the quasi-stationary state, as a function of ``w``.

        Each half's state long after the start, given no alarm of that half:
        the atom at 0 and the nodes carry the quasi-stationary masses, and
        the density they lead to is integrated exactly through ``F``. The two
        halves are rarely high together, so their sum is the fraction of
        nights with either past ``w`` (the Monte Carlo checks it).

        Parameters
        ----------
        law : NightLaw
            Law of ``z``.
        nodes : int, optional
            Gauss–Legendre nodes; default :meth:`default_nodes`.

        Returns
        -------
        callable
            ``w`` in ``[0, limit]`` [1] -> fraction of nights [1].
        """
        n = nodes or self.default_nodes()
        x, _ = _legendre(n)
        points = np.concatenate([[0.0], 0.5 * self.limit * (x + 1.0)])
        halves = []
        for half in (law,) if law.shift == 0.0 else (law, law.mirrored()):
            p, r = _quasi_stationary(self._kernel(half, n))
            outer = half.cdf(self.limit + self.k - points)
            halves.append((half, p / r, outer))
        twice = 2.0 if law.shift == 0.0 else 1.0

        def fraction(w):
            return twice * sum(
                float(q @ (outer - half.cdf(w + self.k - points))) for half, q, outer in halves
            )

        return fraction


def _run_lengths(system):
    """Solve ``system @ L = 1`` for the run lengths; ``inf`` where the chart never alarms
    (at a CUSUM's limit 0 with the law far below k, the system is singular)."""
    try:
        return np.linalg.solve(system, np.ones(len(system)))
    except np.linalg.LinAlgError:
        return np.full(len(system), math.inf)


def _capped(arl):
    """An ARL from a linear solve, ``inf`` where it is beyond what double precision resolves."""
    arl = float(arl)
    return arl if 1.0 <= arl <= _ARL_CAP else math.inf


def _either(up, down):
    """ARL of two one-sided halves run together, ``1/ARL = 1/ARL+ + 1/ARL-``."""
    rate = 1.0 / up + 1.0 / down
    return math.inf if rate == 0.0 else 1.0 / rate


def _quasi_stationary(kernel):
    """Left Perron eigenvector of a sub-stochastic kernel as probabilities, and its eigenvalue."""
    values, vectors = np.linalg.eig(kernel.T)
    i = np.argmax(np.real(values))
    v = np.abs(np.real(vectors[:, i]))
    return v / v.sum(), float(np.real(values[i]))


def quadrature_error(chart, law, nodes=None):
    """Relative change of the zero-state ARL when the nodes are doubled.

    Parameters
    ----------
    chart : Shewhart, Ewma or Cusum
        The chart.
    law : NightLaw
        Law of ``z``.
    nodes : int, optional
        The number of nodes to check; default the chart's own.

    Returns
    -------
    float
        ``|ARL(n) - ARL(2 n)| / ARL(2 n)``; 0 for the Shewhart chart (exact). [1]
    """
    if isinstance(chart, Shewhart):
        return 0.0
    n = nodes or chart.default_nodes()
    fine = chart.arl(law, nodes=2 * n)
    return abs(chart.arl(law, nodes=n) - fine) / fine


def _baseline_nodes(baseline_sd, nodes, symmetric):
    """Shifts ``-e / sigma`` and weights for the average over the baseline's error."""
    x, w = _legendre(nodes)
    half = 3.0 * baseline_sd  # [0, 6 baseline_sd] mapped from [-1, 1]
    e = half * (x + 1.0)
    w = half * w * np.exp(-4.5 * (x + 1.0) ** 2) / (_SQRT_2PI * baseline_sd)
    if symmetric:  # a centred law: both signs of e alike
        return e, 2.0 * w
    return np.concatenate([e, -e]), np.concatenate([w, w])


def baseline_average(chart, law, baseline_sd, nodes=_BASELINE_NODES):
    """The chart's ARL averaged over the baseline's error.

    Given the baseline's error ``e``, ``z`` has noncentrality
    ``law.shift - e / sigma``, with ``e / sigma ~ N(0, baseline_sd^2)``. The
    average is a Gauss–Legendre quadrature over ``|e / sigma| <= 6 baseline_sd``
    (the rest holds 2e-9 of the probability): the rate ``1/ARL`` rises
    steeply with ``|e|``, which Gauss–Hermite nodes resolve poorly.

    Parameters
    ----------
    chart : Shewhart, Ewma or Cusum
        The chart.
    law : NightLaw
        Law of ``z`` for a baseline without error.
    baseline_sd : float
        Standard deviation of the baseline's error over the night's ``sigma``. [1]
    nodes : int, optional
        Gauss–Legendre nodes on each side of 0.

    Returns
    -------
    dict
        ``mean_arl``: ``E[ARL]``, the unconditional ARL (``inf`` when some
        baselines never alarm to double precision) [nights];
        ``rate_arl``: ``1 / E[1/ARL]``, one over the alarm rate averaged over
        baselines [nights]; ``p10_arl`` (centred ``law`` only, else None): the
        ARL of a baseline in error by its 90th percentile ``|e|``, which one
        baseline in ten does worse than [nights].
    """
    if baseline_sd == 0.0:
        a = chart.arl(law)
        return {"mean_arl": a, "rate_arl": a, "p10_arl": a if law.shift == 0.0 else None}
    shifts, w = _baseline_nodes(baseline_sd, nodes, symmetric=law.shift == 0.0)
    arls = np.array([chart.arl(law.shifted(d)) for d in shifts])
    p10 = chart.arl(law.shifted(special.ndtri(0.95) * baseline_sd)) if law.shift == 0.0 else None
    with np.errstate(divide="ignore"):  # no baseline alarms to double precision: inf
        rate_arl = float(1.0 / (w @ (1.0 / arls)))
    return {"mean_arl": float(w @ arls), "rate_arl": rate_arl, "p10_arl": p10}


def solve_limit(chart, arl0, law, baseline_sd=0.0, guess=None):
    """The chart's limit for an in-control ARL (or rate-averaged ARL over baselines).

    Parameters
    ----------
    chart : Shewhart, Ewma or Cusum
        The chart; its own limit is ignored.
    arl0 : float
        Asked in-control ARL, > 1. With ``baseline_sd > 0`` it is the
        baseline-averaged ``rate_arl`` of :func:`baseline_average`. [nights]
    law : NightLaw
        In-control law of ``z`` (``shift`` 0).
    baseline_sd : float, optional
        Standard deviation of the baseline's error over ``sigma``. [1]
    guess : float, optional
        A limit near the answer, to start the bracket from. [1]

    Returns
    -------
    same type as ``chart``
        The chart with the limit that gives ``arl0`` (relative tolerance 1e-8
        on the limit, on top of the quadrature error).
    """
    if isinstance(chart, Shewhart) and baseline_sd == 0.0:
        # P(|z| > L) = 1/arl0 for a centred symmetric law: exact.
        q = 1.0 / (2.0 * arl0)
        limit = stats.norm.isf(q) if law.nu is None else stats.t.isf(q, law.nu)
        return replace(chart, limit=float(limit))

    def excess(limit):
        c = replace(chart, limit=float(limit))
        a = c.arl(law) if baseline_sd == 0.0 else baseline_average(c, law, baseline_sd)["rate_arl"]
        return math.log(min(a, _ARL_CAP)) - math.log(arl0)

    # A bracket: the ARL rises with the limit; widen from the guess until it holds.
    if guess:
        lo, hi = 0.8 * guess, 1.25 * guess
    elif isinstance(chart, Ewma):
        lo, hi = 1e-3 * chart.lam, 3.0 * math.sqrt(chart.lam / (2.0 - chart.lam))
    else:
        lo, hi = 1e-3, 4.0
    f_lo, f_hi = excess(lo), excess(hi)
    while f_lo > 0.0:
        if lo < _MIN_LIMIT:
            # Even at limit 0 the chart alarms less often than asked: a CUSUM whose k is
            # many sigmas (a large named step) alarms only on a night past k itself.
            return replace(chart, limit=0.0)
        lo, hi, f_hi = 0.5 * lo, lo, f_lo
        f_lo = excess(lo)
    while f_hi < 0.0:
        lo, hi, f_lo = hi, 2.0 * hi, f_hi
        f_hi = excess(hi)
    limit = optimize.brentq(excess, lo, hi, xtol=1e-10, rtol=1e-8)
    return replace(chart, limit=float(limit))


def solve_warning(chart, fraction, law, baseline_sd=0.0, nodes=_BASELINE_NODES):
    """The warning limit past which the chart's statistic spends a given fraction of nights.

    In control and in the quasi-stationary state (long after a start,
    without an alarm); with ``baseline_sd > 0`` averaged over the baseline's
    error like :func:`baseline_average`.

    Parameters
    ----------
    chart : Shewhart, Ewma or Cusum
        The chart with its alarm limit.
    fraction : float
        Fraction of in-control nights past the warning limit, in (0, 1). [1]
    law : NightLaw
        In-control law of ``z`` (``shift`` 0).
    baseline_sd : float, optional
        Standard deviation of the baseline's error over ``sigma``. [1]
    nodes : int, optional
        Gauss–Legendre nodes for the baseline's error, each side of 0.

    Returns
    -------
    float
        The warning limit, below the alarm limit. [1]
    """
    if baseline_sd == 0.0:
        parts = [(1.0, chart.occupancy(law))]
    else:
        shifts, weights = _baseline_nodes(baseline_sd, nodes, symmetric=True)
        parts = [
            (wt, chart.occupancy(law.shifted(d))) for d, wt in zip(shifts, weights, strict=True)
        ]

    def excess(w):
        return sum(wt * occ(w) for wt, occ in parts) - fraction

    hi = chart.limit * (1.0 - 1e-9)
    if excess(hi) >= 0.0:  # even the alarm limit is passed this often: warn there
        return chart.limit
    if excess(0.0) <= 0.0:  # a CUSUM of large k is at zero on most nights: warn off zero
        return 0.0
    return optimize.brentq(excess, 0.0, hi, xtol=1e-10, rtol=1e-8)
