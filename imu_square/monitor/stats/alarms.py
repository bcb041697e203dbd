"""Designed alarms on the nightly change of squareness: three charts, one asked false-alarm rate.

The statistic
-------------
Each valid night gives the change ``Delta`` of ``squareness_rad`` against the
baseline and its standard uncertainty ``u`` (the night's type A uncertainty,
``nu`` = cycle pairs - 1 degrees of freedom). The charts run on
``z = Delta / u``. In control ``z`` follows Student's t with ``nu`` degrees of
freedom (the normal when ``nu`` is None): ``u`` is itself estimated from ~15
pairs, so ``z`` is heavier-tailed than normal and a normal design would give
far more false alarms than asked (the normal's Shewhart limit for one false
alarm in 730 nights, 3.20, alarms 4.7 times as often at ``nu = 14``; the
t's is 3.98). A night whose ``nu`` differs from the design's is
mapped onto the design's law by its tail probability,
``z* = F_design^-1(F_nu(z))``, so every night the charts see has the design's
in-control law exactly.

The charts (all two-sided, run together on the same nights)
------------------------------------------------------------
- Shewhart: alarm when ``|z| > L``; finds large sudden changes.
- EWMA: ``E_t = (1 - lam) E_{t-1} + lam z_t`` from ``E_0 = 0``, alarm when
  ``|E_t| > h_E``. ``lam = 0.1`` by default, not tuned to the named step:
  the CUSUM is; a small ``lam`` makes the EWMA the chart for slow drifts and
  for steps smaller than the named one (Lucas & Saccucci [2]_ recommend
  0.05-0.25).
- CUSUM: ``C+_t = max(0, C+_{t-1} + z_t - k)``, ``C-_t = max(0, C-_{t-1} - z_t - k)``
  from 0, alarm when either exceeds ``h_C``. The reference value is half the
  named step in units of the night's sigma (the CUSUM tuned to that step
  [1]_), but at least 2.576 times the baseline's relative error (its 99 %
  bound): with a smaller ``k`` the CUSUM adds up the baseline's own error
  night after night and its limit must grow without bound.

How the limits come from the asked ARL0
---------------------------------------
The user asks for one false alarm in ``arl0_nights`` valid nights (one in
two years of nights: 730). Every limit is computed, not looked up: the
Shewhart limit from the law's quantile, the EWMA and CUSUM limits by
``brentq`` on their ARLs from the integral equations of
:mod:`imu_square.monitor.stats.arl`.

The three charts fire on partly the same nights, so the scheme's rate is
less than the sum of theirs. The split rule: chart ``i`` gets the rate
``O s_i / arl0_nights`` (shares ``s_i``, by default a third each). ``O = 1``
is the union bound (never more false alarms than asked); the overlap factor
``O`` is then measured by Monte Carlo, as the sum of the charts' computed
rates over the scheme's simulated rate, and the limits are computed again
for it. A second, independent Monte Carlo verifies the combined ARL0 and
states its standard error (it lands within a few per cent of the target;
the union bound alone gives 20-35 % fewer false alarms than asked, and
slower detection).

Warnings
--------
A night is ``warning`` when a statistic is past its warning limit and none
past its alarm limit. The warning limits are designed for the fraction of
in-control nights the user accepts in that state (``warning_fraction``,
default 2 %, about a week of nights a year): each chart gets its share of it,
computed from its statistic's quasi-stationary law (long after a start,
without an alarm; :meth:`~imu_square.monitor.stats.arl.Ewma.occupancy`), and the
overlap of the charts' warnings is measured and allowed for as for the
alarms. A warning ARL would not do: an EWMA or a CUSUM with a small ``k``
lingers past a limit once it has crossed it, and a warning ARL0 of a tenth
of the alarm's left such a CUSUM in warning one night in five. The design
also reports how many warning episodes (runs of warning nights) a year of
in-control nights brings.

After an alarm
--------------
The charts restart from zero on the night after an alarm (the zero state the
ARLs assume). A change that persists fires again after about its zero-state
ARL; a false alarm does not latch. The monitor passes the nights since the
baseline was set (or since the user last acknowledged an alarm, if it keeps
such a mark); within them this restart rule is applied night by night.

The baseline's error
--------------------
The baseline is the mean of N runs, so its error ``e`` is common to every
night: each machine's chart runs with a constant offset ``-e / sigma`` in
``z``. EWMA and CUSUM add it up night after night. For a scheme designed
as if the baseline were exact (730 nights combined), the false-alarm rate
averaged over baselines grows, at N = 20, by a factor of about 1.4
(Shewhart), 7 (EWMA, ``lam = 0.1``) and 2 to 10 (CUSUM, ``k`` = 1.25 down to
0.07); at N = 3 by 3 to 5, 45, and 19 to 28 (``benchmarks/monitor.py``
tabulates N = 3, 5, 10, 20). Dividing ``Delta``
by ``sqrt(u^2 + u_baseline^2)`` instead helps little: it treats the common
error as fresh noise each night, and the EWMA and CUSUM still accumulate the
offset (at N = 3 it cuts 10.0 false alarms a year to 6.8, where 0.5 were
asked).

The design therefore takes the baseline's relative error
``baseline_sd_ratio = u_baseline / sigma`` (``1/sqrt(N)`` for a baseline
that is the mean of N runs like tonight's) and computes every limit so that
the false-alarm rate *averaged over the baseline's error* meets the asked
one (Gauss–Legendre average over ``e``, :func:`~imu_square.monitor.stats.arl.baseline_average`).
The monitor should use this, with ``z = Delta / u``: it is the only option
that controls the rate the user asked for, and it states the price
(slower detection, and a CUSUM that cannot be tuned below the baseline's
own error). The design also reports ``E[ARL0]`` over baselines (dominated by
lucky baselines) and the ARL0 one baseline in ten falls below.

References
----------
.. [1] J. M. Lucas, R. B. Crosier, "Fast initial response for CUSUM
   quality-control schemes", Technometrics 24 (1982).
.. [2] J. M. Lucas, M. S. Saccucci, "Exponentially weighted moving average
   control schemes: properties and enhancements", Technometrics 32 (1990).
"""

import math
from dataclasses import dataclass

import numpy as np
from scipy import special, stats

from imu_square.blas import one_blas_thread
from imu_square.errors import MonitorError
from imu_square.json_values import from_json, json_safe
from imu_square.log import logger
from imu_square.monitor.stats.arl import (
    Cusum,
    Ewma,
    NightLaw,
    Shewhart,
    baseline_average,
    solve_limit,
    solve_warning,
)
from imu_square.monitor.stats.arl import quadrature_error as _quadrature_error
from imu_square.monitor.stats.charts import (
    CHARTS,
    ChartLimits,
    NightSampler,
    alarm_counts,
    chart_statistics,
    first_alarms,
)
from imu_square.units import URAD
from imu_square.validation import check_int, check_number, fail, interval, is_number

NIGHTS_PER_YEAR = 365.25
STATES = ("ok", "warning", "alarm")
# The CUSUM's k is at least this many baseline standard errors (two-sided 99 %).
_K_BASELINE_FACTOR = float(special.ndtri(0.995))
# In-control nights before the step for the steady-state Monte Carlo.
_BURN_IN = 100
# Simulated machines for the out-of-control Monte Carlo.
_OOC_PATHS = 2000


@dataclass(frozen=True)
class ChartDesign:
    """One chart of the scheme: its parameter, limits and run lengths.

    Attributes
    ----------
    name : str
        ``"shewhart"``, ``"ewma"`` or ``"cusum"``.
    parameter : float or None
        ``lam`` for the EWMA, ``k`` for the CUSUM, None for the Shewhart. [1]
    limit : float
        Alarm limit on ``|z|``, ``|EWMA|`` or ``C+/C-``. [1]
    warning_limit : float
        Warning limit on the same statistic. [1]
    arl0 : float
        This chart's own in-control ARL (rate-averaged over the baseline's
        error when the design has one). [nights]
    warning_fraction : float
        Fraction of in-control nights this chart's statistic spends past its
        warning limit (ditto). [1]
    arl0_mean : float
        ``E[ARL0]`` over the baseline's error (``inf`` when some baselines
        never alarm to double precision). [nights]
    arl0_p10 : float
        In-control ARL of a baseline in error by its 90th percentile: one
        baseline in ten does worse. [nights]
    arl1 : float
        Zero-state ARL after the named step, for a baseline without error. [nights]
    arl1_steady : float
        Conditional steady-state ARL after the named step (ditto). [nights]
    arl1_mean : float
        Zero-state ARL after the named step averaged over the baseline's error. [nights]
    quadrature_error : float
        Relative change of the in-control ARL on doubling the quadrature nodes. [1]
    """

    name: str
    parameter: float | None
    limit: float
    warning_limit: float
    arl0: float
    warning_fraction: float
    arl0_mean: float
    arl0_p10: float
    arl1: float
    arl1_steady: float
    arl1_mean: float
    quadrature_error: float


@dataclass(frozen=True)
class SchemeCheck:
    """Monte Carlo of the three charts run together.

    Attributes
    ----------
    arl0, u_arl0 : float
        In-control ARL of the scheme (restarting after each alarm, averaged
        over the baseline's error) and its standard error. [nights]
    warning_fraction, u_warning_fraction : float
        Fraction of in-control nights in the ``warning`` state, and its
        standard error. [1]
    warnings_per_year : float
        Warning episodes (runs of warning nights) per 365.25 in-control nights. [1]
    arl1, u_arl1 : float
        Zero-state ARL after the named step (``inf`` when some simulated
        machines did not find it within ten ARL0s). [nights]
    step_median, step_p90 : float
        Median and 90th percentile of the same run lengths, over machines
        (and so over the baseline's error). [nights]
    arl1_steady, u_arl1_steady : float
        ARL after the named step once the charts have run 100 nights in
        control without an alarm. [nights]
    ramp_median, ramp_p90 : float
        Median and 90th percentile of the nights from the start of the ramp
        to the alarm (``inf`` when fewer than half or 90 % are found within
        the simulated horizon). [nights]
    n_paths, n_nights : int
        Size of the in-control simulation: machines and nights each.
    seed : int
        Seed of the simulations.
    """

    arl0: float
    u_arl0: float
    warning_fraction: float
    u_warning_fraction: float
    warnings_per_year: float
    arl1: float
    u_arl1: float
    step_median: float
    step_p90: float
    arl1_steady: float
    u_arl1_steady: float
    ramp_median: float
    ramp_p90: float
    n_paths: int
    n_nights: int
    seed: int


@dataclass(frozen=True)
class AlarmDesign:
    """The designed scheme: what was asked, the three charts, and their check.

    Attributes
    ----------
    arl0_nights : float
        Asked in-control ARL of the scheme: one false alarm in this many
        valid nights. [nights]
    sigma_rad : float
        Typical standard deviation of one night's change. [rad]
    step_rad : float
        The step the user names. [rad]
    nu : float or None
        Degrees of freedom of ``z`` in control; None for the normal.
    baseline_sd_ratio : float
        Standard error of the baseline over ``sigma_rad``. [1]
    shares : tuple of 3 float
        Shares of the false-alarm rate (Shewhart, EWMA, CUSUM). [1]
    overlap : float
        Sum of the charts' own false-alarm rates over the scheme's (measured
        by Monte Carlo; 1 would be the union bound). [1]
    warning_fraction : float
        Asked fraction of in-control nights in the ``warning`` state. [1]
    warning_overlap : float
        The same overlap factor for the warnings. [1]
    ramp_rad, ramp_nights : float, int
        The ramp checked by Monte Carlo: this change over this many nights. [rad], [nights]
    shewhart, ewma, cusum : ChartDesign
        The charts.
    check : SchemeCheck
        The Monte Carlo of the scheme.
    """

    arl0_nights: float
    sigma_rad: float
    step_rad: float
    nu: float | None
    baseline_sd_ratio: float
    shares: tuple
    overlap: float
    warning_fraction: float
    warning_overlap: float
    ramp_rad: float
    ramp_nights: int
    shewhart: ChartDesign
    ewma: ChartDesign
    cusum: ChartDesign
    check: SchemeCheck

    @property
    def charts(self):
        """The three :class:`ChartDesign` in :data:`.charts.CHARTS` order."""
        return (self.shewhart, self.ewma, self.cusum)

    @property
    def limits(self):
        """The alarm limits as :class:`~imu_square.monitor.stats.charts.ChartLimits`."""
        s, e, c = self.charts
        return ChartLimits(s.limit, e.parameter, e.limit, c.parameter, c.limit)

    @property
    def warnings(self):
        """The warning limits as :class:`~imu_square.monitor.stats.charts.ChartLimits`."""
        s, e, c = self.charts
        return ChartLimits(
            s.warning_limit, e.parameter, e.warning_limit, c.parameter, c.warning_limit
        )

    @property
    def step_sd(self):
        """The named step in units of the night's sigma. [1]"""
        return self.step_rad / self.sigma_rad

    def to_json_dict(self):
        """The design as JSON-ready values (angles in µrad = µm/m, ``inf`` as None)."""
        d = json_safe(self, urad=True)
        for name in CHARTS:
            del d[name]["name"]  # the chart's key names it
        d["check"]["false_alarms_per_year"] = NIGHTS_PER_YEAR / self.check.arl0
        d["check"]["u_false_alarms_per_year"] = (
            NIGHTS_PER_YEAR * self.check.u_arl0 / self.check.arl0**2
        )
        return {
            "arl0_nights": d.pop("arl0_nights"),
            "false_alarms_per_year": NIGHTS_PER_YEAR / self.arl0_nights,
            "sigma_urad": d.pop("sigma_urad"),
            "step_urad": d.pop("step_urad"),
            "step_sd": self.step_sd,
        } | d

    @classmethod
    def from_json_dict(cls, data):
        """The design back from :meth:`to_json_dict` (e.g. as stored with the baseline).

        Parameters
        ----------
        data : dict
            Output of :meth:`to_json_dict`.

        Returns
        -------
        AlarmDesign
        """
        try:
            return from_json(cls, data | {c: data[c] | {"name": c} for c in CHARTS}, urad=True)
        except KeyError as exc:
            raise MonitorError(f"alarm design: the field {exc.args[0]!r} is missing") from exc
        except (AttributeError, TypeError, ValueError) as exc:
            raise MonitorError(f"alarm design: a field holds a wrong value: {exc}") from exc

    def _nights(self, n):
        if not math.isfinite(n):
            return f"more than {10 * self.arl0_nights:.0f} nights (not found in the simulation)"
        return f"{n:.1f} nights" if n < 10 else f"{n:.0f} nights"

    def describe(self):
        """One paragraph for people: the charts, their limits and what they find.

        Returns
        -------
        str
        """
        sig = self.sigma_rad / URAD
        law = "normal" if self.nu is None else f"Student's t with {self.nu:g} degrees of freedom"
        c = self.check
        text = (
            f"Alarm when any of three charts on z = change / its uncertainty ({law} in control) "
            f"passes its limit: Shewhart |z| > {self.shewhart.limit:.2f}; "
            f"EWMA (lambda {self.ewma.parameter:.2f}) |E| > {self.ewma.limit:.3f}; "
            f"CUSUM (k {self.cusum.parameter:.2f}) C+ or C- > {self.cusum.limit:.2f}. "
            f"Designed for one false alarm in {self.arl0_nights:g} valid nights "
            f"({NIGHTS_PER_YEAR / self.arl0_nights:.2f} a year); simulated "
            f"{c.arl0:.0f} ± {c.u_arl0:.0f} nights. "
            f"Warning when a chart passes its warning limit: {100 * c.warning_fraction:.1f} % "
            f"of nights in control, {c.warnings_per_year:.1f} episodes a year. "
            f"A step of {self.step_rad / URAD:g} µm/m ({self.step_sd:.2f} sigma, sigma "
            f"{sig:.3g} µm/m a night) is found after {self._nights(c.step_median)} (median; "
            f"90 % within {self._nights(c.step_p90)}; mean {self._nights(c.arl1)} from a fresh "
            f"start, {self._nights(c.arl1_steady)} after a long quiet run); a ramp of "
            f"{self.ramp_rad / URAD:g} µm/m over {self.ramp_nights} nights after "
            f"{self._nights(c.ramp_median)} (median; 90 % within {self._nights(c.ramp_p90)})."
        )
        if self.baseline_sd_ratio > 0.0:
            text += (
                f" The limits allow for the baseline's own error "
                f"({self.baseline_sd_ratio * sig:.3g} µm/m, {self.baseline_sd_ratio:.2f} sigma), "
                f"common to every night; one baseline in ten still gives fewer than "
                f"{min(ch.arl0_p10 for ch in self.charts):.0f} nights between false alarms "
                f"of its worst chart."
            )
        if self.check.step_median > self.arl0_nights / 4:
            text += (
                f" The step is small against a night's scatter ({self.step_sd:.2f} sigma): "
                f"finding it takes a good part of the time between false alarms; a test with "
                f"less scatter per night finds it sooner."
            )
        return text


def _check_nu(name, nu):
    if nu is None:
        return None
    within = "None (normal) or a number >= 1"
    return check_number(name, nu, 1.0, kind=within, allowed=within, error=MonitorError)


@one_blas_thread()  # integral equations of 50-400 unknowns (imu_square.blas)
def design_alarms(
    arl0_nights,
    sigma_rad,
    *,
    step_rad=10 * URAD,
    nu=None,
    baseline_sd_ratio=0.0,
    ewma_lambda=0.1,
    cusum_k=None,
    shares=(1 / 3, 1 / 3, 1 / 3),
    warning_fraction=0.02,
    ramp_rad=10 * URAD,
    ramp_nights=90,
    mc_nights=4_000_000,
    seed=0,
):
    """Design the Shewhart, EWMA and CUSUM charts for an asked false-alarm rate.

    Parameters
    ----------
    arl0_nights : float
        One false alarm in this many valid nights is accepted (two years of
        nights: 730); at least 10. [nights]
    sigma_rad : float
        Typical standard deviation of one night's change, e.g. the median
        ``u_squareness_rad`` of the baseline's runs. [rad]
    step_rad : float, optional
        The step to find; sets the CUSUM's ``k`` and the reported
        out-of-control ARLs. [rad]
    nu : float or None, optional
        Degrees of freedom of the nights' ``u`` (cycle pairs - 1), at least
        1; None for the normal.
    baseline_sd_ratio : float, optional
        Standard uncertainty of the baseline over ``sigma_rad``
        (``1/sqrt(N)`` for the mean of N such runs), within [0, 2]; 0
        designs as if the baseline were exact. [1]
    ewma_lambda : float, optional
        EWMA smoothing constant, ``0 < lam <= 1``. [1]
    cusum_k : float, optional
        CUSUM reference value, >= 0; default ``max(step / (2 sigma), 2.576
        baseline_sd_ratio)`` (module docstring). [1]
    shares : tuple of 3 float, optional
        Shares of the false-alarm rate and of the warning nights for the
        Shewhart, EWMA and CUSUM charts; positive, summing to 1. [1]
    warning_fraction : float, optional
        Fraction of in-control nights accepted in the ``warning`` state, in
        (0, 0.5). [1]
    ramp_rad, ramp_nights : float, int, optional
        The ramp whose detection delay is simulated. [rad], [nights]
    mc_nights : int, optional
        Nights simulated for each in-control Monte Carlo (the standard error
        of the combined ARL0 is about ``sqrt(arl0 / mc_nights)`` relative
        for an exact baseline), at least 100 000. [nights]
    seed : int, optional
        Seed of the Monte Carlo.

    Returns
    -------
    AlarmDesign

    Raises
    ------
    MonitorError
        When a parameter is out of its range.
    """
    arl0 = _number("arl0_nights", arl0_nights, lo=10.0, unit="nights")
    sigma = _number("sigma_rad", sigma_rad, lo=0.0, closed=False, unit="rad")
    step = _number("step_rad", step_rad, lo=0.0, closed=False, unit="rad")
    ramp = _number("ramp_rad", ramp_rad, lo=0.0, closed=False, unit="rad")
    ramp_nights = _count("ramp_nights", ramp_nights, 1)
    nu = _check_nu("nu", nu)
    rho = _number("baseline_sd_ratio", baseline_sd_ratio, lo=0.0, hi=2.0)
    lam = _number("ewma_lambda", ewma_lambda, lo=0.0, hi=1.0, closed=False)
    shares = tuple(shares)
    if not (
        len(shares) == 3
        and all(is_number(v) and 0 < v < math.inf for v in shares)
        and abs(sum(shares) - 1.0) < 1e-9
    ):
        fail("shares", "3 numbers > 0 summing to 1", shares, error=MonitorError)
    shares = tuple(float(v) for v in shares)
    wfrac = _number("warning_fraction", warning_fraction, lo=0.0, hi=0.5, closed=False)
    delta = step / sigma
    if cusum_k is None:
        k = max(0.5 * delta, _K_BASELINE_FACTOR * rho)
    else:
        k = _number("cusum_k", cusum_k, lo=0.0)
    mc_paths, mc_span = _mc_size(arl0, _count("mc_nights", mc_nights, 100_000))
    seeds = np.random.SeedSequence(seed).spawn(6)

    law = NightLaw(nu)
    sampler = NightSampler(nu, 0.0, _offsets(rho, mc_paths, seeds[0]))

    # The union bound first: each chart on its share of the rates.
    alone = [
        solve_limit(c, arl0 / s, law, rho)
        for c, s in zip((Shewhart(1.0), Ewma(lam, 1.0), Cusum(k, 1.0)), shares, strict=True)
    ]
    warn = [solve_warning(c, s * wfrac, law, rho) for c, s in zip(alone, shares, strict=True)]
    first = alarm_counts(
        _limits(alone),
        _limits(alone, warn),
        sampler,
        mc_paths,
        mc_span,
        np.random.default_rng(seeds[1]),
    )
    # Then each chart's share scaled by how much the charts overlap in the simulation.
    overlap = max(1.0, (1.0 / arl0) / _per_night(first)[0])
    warning_overlap = max(1.0, wfrac / _per_night(first, "warning_nights")[0])
    logger.debug("alarm design: overlap %.3f (alarms), %.3f (warnings)", overlap, warning_overlap)
    alarm = [
        solve_limit(c, arl0 / (overlap * s), law, rho, guess=c.limit)
        for c, s in zip(alone, shares, strict=True)
    ]
    warn = [
        solve_warning(c, warning_overlap * s * wfrac, law, rho)
        for c, s in zip(alarm, shares, strict=True)
    ]
    limits, warnings = _limits(alarm), _limits(alarm, warn)

    counts = alarm_counts(
        limits, warnings, sampler, mc_paths, mc_span, np.random.default_rng(seeds[2])
    )
    rate, u_rate = _per_night(counts)
    wf, u_wf = _per_night(counts, "warning_nights")
    episodes = counts["warning_onsets"].sum() / (mc_paths * mc_span)

    step_law = law.shifted(delta)
    designs = []
    for name, a, w, s in zip(CHARTS, alarm, warn, shares, strict=True):
        avg0 = baseline_average(a, law, rho)
        designs.append(
            ChartDesign(
                name=name,
                parameter={"shewhart": None, "ewma": lam, "cusum": k}[name],
                limit=a.limit,
                warning_limit=w,
                arl0=avg0["rate_arl"],
                warning_fraction=warning_overlap * s * wfrac,
                arl0_mean=avg0["mean_arl"],
                arl0_p10=avg0["p10_arl"],
                arl1=a.arl(step_law),
                arl1_steady=a.steady_state_arl(step_law, law),
                arl1_mean=baseline_average(a, step_law, rho)["mean_arl"],
                quadrature_error=_quadrature_error(a, law),
            )
        )

    # Out of control, the scheme by Monte Carlo: a step from a fresh start,
    # the same step after a quiet run, and the ramp.
    horizon, paths = int(10 * arl0), _OOC_PATHS
    offsets = _offsets(rho, paths, seeds[3])
    means = {
        "zero": delta,
        "steady": np.concatenate([np.zeros(_BURN_IN), [delta]]),
        "ramp": (ramp / sigma) * np.minimum(np.arange(1, ramp_nights + 1) / ramp_nights, 1.0),
    }
    rl = {}
    for (name, mean), sub in zip(means.items(), seeds[4].spawn(3), strict=True):
        rl[name] = first_alarms(
            limits,
            NightSampler(nu, mean, offsets),
            paths,
            horizon,
            np.random.default_rng(sub),
            burn_in=_BURN_IN if name == "steady" else 0,
            per_chart=False,
        )["combined"]
    check = SchemeCheck(
        arl0=1.0 / rate,
        u_arl0=u_rate / rate**2,
        warning_fraction=wf,
        u_warning_fraction=u_wf,
        warnings_per_year=float(NIGHTS_PER_YEAR * episodes),
        arl1=_mean(rl["zero"])[0],
        u_arl1=_mean(rl["zero"])[1],
        step_median=_quantile(rl["zero"], 0.5),
        step_p90=_quantile(rl["zero"], 0.9),
        arl1_steady=_mean(rl["steady"])[0],
        u_arl1_steady=_mean(rl["steady"])[1],
        ramp_median=_quantile(rl["ramp"], 0.5),
        ramp_p90=_quantile(rl["ramp"], 0.9),
        n_paths=mc_paths,
        n_nights=mc_span,
        seed=int(seed),
    )
    return AlarmDesign(
        arl0_nights=arl0,
        sigma_rad=sigma,
        step_rad=step,
        nu=nu,
        baseline_sd_ratio=rho,
        shares=shares,
        overlap=overlap,
        warning_fraction=wfrac,
        warning_overlap=warning_overlap,
        ramp_rad=ramp,
        ramp_nights=int(ramp_nights),
        shewhart=designs[0],
        ewma=designs[1],
        cusum=designs[2],
        check=check,
    )


def _number(name, value, lo, hi=math.inf, closed=True, unit=""):
    """``value`` as a finite float within ``[lo, hi]`` (``(lo, hi]`` unless ``closed``)."""
    within = f"a number within {interval(lo, hi, not closed)}{f' {unit}' if unit else ''}"
    hi = hi if math.isfinite(hi) else None  # shown as a bound, but never taken
    kw = {"kind": within, "allowed": within, "error": MonitorError}
    return check_number(name, value, lo, hi, lo_open=not closed, **kw)


def _count(name, value, lo):
    """``value`` as an int, at least ``lo``."""
    at_least = f"an integer >= {lo}"
    return check_int(name, value, lo, kind=at_least, allowed=at_least, error=MonitorError)


def _mc_size(arl0, mc_nights):
    """Paths and nights each: runs of 2 ARL0 (at least 200 nights), at least 100 paths."""
    span = int(max(200, 2 * arl0))
    return max(100, mc_nights // span), span


def _offsets(rho, n_paths, seed):
    """The baseline's error over sigma for each simulated machine, stratified over its law."""
    if rho == 0.0:
        return None
    rng = np.random.default_rng(seed)
    u = (rng.permutation(n_paths) + rng.uniform(size=n_paths)) / n_paths
    return rho * special.ndtri(u)


def _limits(alarm, warning=None):
    shewhart, ewma, cusum = alarm
    if warning is None:
        return ChartLimits(shewhart.limit, ewma.lam, ewma.limit, cusum.k, cusum.limit)
    return ChartLimits(warning[0], ewma.lam, warning[1], cusum.k, warning[2])


def _per_night(counts, key="alarms"):
    """Per-path ``key`` counts (alarms, warning nights) per night: mean and standard error."""
    per_path = counts[key] / counts["n_nights"]
    return float(per_path.mean()), float(per_path.std(ddof=1) / math.sqrt(per_path.size))


def _mean(run_lengths):
    """Mean and standard error of the run lengths kept; ``inf`` if some were censored."""
    rl = run_lengths[~np.isnan(run_lengths)]
    if not np.isfinite(rl).all():
        return math.inf, math.inf
    return float(rl.mean()), float(rl.std(ddof=1) / math.sqrt(rl.size))


def _quantile(run_lengths, q):
    """Quantile of the run lengths kept (``inf`` when censored runs reach it)."""
    rl = np.sort(run_lengths[~np.isnan(run_lengths)])
    return float(rl[min(rl.size - 1, math.ceil(q * rl.size) - 1)])


@dataclass(frozen=True)
class ChartPoint:
    """One night as the charts saw it.

    Attributes
    ----------
    night : int
        Index in the sequence given (0 = the first night after the baseline).
    change_rad, u_change_rad : float
        The change against the baseline and its standard uncertainty. [rad]
    nu : float or None
        The night's degrees of freedom.
    z : float
        The standardised change the charts use, mapped onto the design's law. [1]
    ewma, cusum_pos, cusum_neg : float
        The statistics after this night. [1]
    alarms : tuple of str
        The charts past their alarm limit.
    warnings : tuple of str
        The charts past their warning limit (and not their alarm limit).
    direction : int
        +1 when the fired (or warned) statistics point to an increase, -1 to a
        decrease, 0 when none.
    state : str
        ``"ok"``, ``"warning"`` or ``"alarm"``.
    """

    night: int
    change_rad: float
    u_change_rad: float
    nu: float | None
    z: float
    ewma: float
    cusum_pos: float
    cusum_neg: float
    alarms: tuple
    warnings: tuple
    direction: int
    state: str

    def to_json_dict(self):
        """JSON-ready values (the change in µrad = µm/m)."""
        return json_safe(self, urad=True)


@dataclass(frozen=True)
class ChartRun:
    """The charts over a machine's valid nights since the baseline.

    Attributes
    ----------
    points : tuple of ChartPoint
        One per night, in time order.
    """

    points: tuple

    @property
    def state(self):
        """The last night's state; ``"ok"`` when there is no night yet."""
        return self.points[-1].state if self.points else "ok"

    @property
    def alarm_nights(self):
        """Indices of the nights that raised an alarm."""
        return tuple(p.night for p in self.points if p.state == "alarm")

    def to_json_dict(self):
        """JSON-ready values."""
        return {"state": self.state, "points": [p.to_json_dict() for p in self.points]}


def run_charts(design, change_rad, u_change_rad, nu=None):
    """Run the designed charts over a machine's valid nights.

    Parameters
    ----------
    design : AlarmDesign
        The design.
    change_rad : array-like, shape (n_nights,)
        Each valid night's change of ``squareness_rad`` against the
        baseline, in time order since the baseline (or since an acknowledged
        alarm). [rad]
    u_change_rad : array-like, shape (n_nights,)
        The night's standard uncertainty of that change (its type A ``u``). [rad]
    nu : float, None or array-like of (float or None), optional
        Degrees of freedom of each night's ``u`` (None or NaN: normal); a
        single value applies to every night.

    Returns
    -------
    ChartRun
        Night by night: ``z`` (mapped onto the design's law when the night's
        ``nu`` differs), the statistics, the charts past their limits, and
        the state. The charts restart from zero on the night after an alarm.

    Raises
    ------
    MonitorError
        When the arrays differ in length or hold non-finite values, ``u <= 0``
        or ``nu < 1``.
    """
    change = np.asarray(change_rad, dtype=np.float64).ravel()
    u = np.asarray(u_change_rad, dtype=np.float64).ravel()
    if change.size != u.size:
        raise MonitorError(
            f"change_rad and u_change_rad must have the same length, got {change.size} and {u.size}"
        )
    nus = _night_nus(nu, change.size)
    bad = ~np.isfinite(change)
    if bad.any():
        raise MonitorError(
            f"change_rad must be finite, got {change[bad][0].item()!r} on night {np.argmax(bad)}"
        )
    bad = ~(np.isfinite(u) & (u > 0))
    if bad.any():
        raise MonitorError(
            f"u_change_rad must be finite and > 0, got {u[bad][0].item()!r} on night "
            f"{np.argmax(bad)}"
        )
    z = to_design_law(change / u, [np.nan if n is None else n for n in nus], design.nu)
    limits, warnings = design.limits, design.warnings
    points = []
    state = None  # fresh start
    for i in range(z.size):
        ewma, cpos, cneg = (
            s[0] for s in chart_statistics(z[i : i + 1], limits.ewma_lambda, limits.cusum_k, state)
        )
        signed = (z[i], ewma, cpos - cneg)
        over = limits.exceeded(z[i], ewma, cpos, cneg)
        near = warnings.exceeded(z[i], ewma, cpos, cneg) & ~over
        fired = tuple(c for c, o in zip(CHARTS, over, strict=True) if o)
        warned = tuple(c for c, o in zip(CHARTS, near, strict=True) if o)
        pointing = [s for s, o in zip(signed, over if fired else near, strict=True) if o]
        points.append(
            ChartPoint(
                night=i,
                change_rad=float(change[i]),
                u_change_rad=float(u[i]),
                nu=nus[i],
                z=float(z[i]),
                ewma=float(ewma),
                cusum_pos=float(cpos),
                cusum_neg=float(cneg),
                alarms=fired,
                warnings=warned,
                direction=int(np.sign(pointing[0])) if pointing else 0,
                state="alarm" if fired else "warning" if warned else "ok",
            )
        )
        # Restart from zero after an alarm; otherwise carry the statistics on.
        state = None if fired else (np.array(ewma), np.array(cpos), np.array(cneg))
    return ChartRun(points=tuple(points))


def _night_nus(nu, n):
    values = [nu] * n if nu is None or np.isscalar(nu) else list(nu)
    if len(values) != n:
        raise MonitorError(f"nu must be one value or one per night ({n}), got {len(values)}")
    out = []
    for i, v in enumerate(values):
        v = v.item() if isinstance(v, np.generic) else v
        if v is None or (isinstance(v, float) and math.isnan(v)):
            out.append(None)
        else:
            out.append(_check_nu(f"nu of night {i}", v))
    return out


def to_design_law(z, nu, design_nu):
    """Map standardised changes from their own law onto the design's, by tail probability.

    ``z* = sign(z) F_design^-1(1 - P_nu(|Z| > |z|) / 2)``: exact in control,
    so every night the charts see has the design's law whatever its own
    degrees of freedom.

    Parameters
    ----------
    z : array-like
        Standardised changes ``Delta / u``. [1]
    nu : float, None or array-like of float
        Each night's degrees of freedom; None or NaN for the normal.
    design_nu : float or None
        The design's degrees of freedom; None for the normal.

    Returns
    -------
    ndarray
        The mapped changes (a tail beyond double precision keeps its own
        ``z``: an alarm either way). [1]
    """
    z = np.asarray(z, dtype=np.float64)
    nu = np.broadcast_to(np.asarray(np.nan if nu is None else nu, dtype=np.float64), z.shape)
    target = np.nan if design_nu is None else float(design_nu)
    same = (nu == target) | (np.isnan(nu) & np.isnan(target))
    out = np.array(z, dtype=np.float64)
    if same.all():
        return out
    a, n = np.abs(z[~same]), nu[~same]
    normal = np.isnan(n)
    tail = np.where(normal, stats.norm.sf(a), stats.t.sf(a, np.where(normal, 1.0, n)))
    mapped = stats.norm.isf(tail) if design_nu is None else stats.t.isf(tail, design_nu)
    out[~same] = np.copysign(np.where(np.isfinite(mapped), mapped, a), z[~same])
    return out
