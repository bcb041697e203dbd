"""Plan a circle test: the radius, feed(s), cycles and dwell that resolve most in the time given.

The model of one run's standard deviation of ``theta_y - theta_x`` is the
Cramér-Rao bound of ``docs/model.md`` with the noise the sensor has *at the
circle frequency* ``f0 = v / (2 pi r)``, divided by the square root of the
estimator's measured efficiency ``e``::

    sigma_run = sqrt(2 S(f0)) / (A sqrt(T)) / sqrt(e)
    S(f)      = d^2 (1 + fc / f) + q^2 / (6 fs)

with ``A = v^2/r``, ``T`` the analysed time (whole cycles of both directions),
``d`` the white-noise density, ``fc`` the 1/f corner (the simulator's and a
MEMS sensor's spectrum ``d^2 (1 + fc/f)``, :mod:`imu_square.simulate.sensor_noise`),
``q`` the ADC step at sample rate ``fs``. For a sinusoid in stationary
Gaussian noise the bound on its phase depends on the noise spectrum at its
frequency only (Whittle); with 1/f noise the white-noise bound ``sqrt(2) d /
(A sqrt(T))`` is too low by ``sqrt(1 + fc / f0)``, a factor 2.3 for the paper's
0.16 Hz circle under a 0.7 Hz corner.

A program at several feeds of one circle separates gravity coupling
(:mod:`imu_square.pipeline.gravity`); its squareness is to first order
``sum c_i D_i`` over the feeds' plain results, so ``sigma = sqrt(sum c_i^2
sigma_i^2)``.

The change of the squareness against a baseline that is the mean of ``N``
runs has ``sigma_change = sigma_run sqrt(1 + 1/N)``. One night alone flags a
change when it exceeds ``z sigma_change``, ``z`` the two-sided normal quantile
of the confidence (a false alarm rate of ``1 - confidence`` on an unchanged
machine, 18 a year at 95 %): the smallest change that one-night test detects
(the "minimal detectable change") is ``z sigma_change`` plus a bound of the
biases that may differ between the baseline and the run; the plans are ranked
by it. The monitor itself runs designed charts at a far lower false-alarm
rate (:mod:`imu_square.monitor.stats.alarms`): ``imu-square plan`` reports, in
:class:`MonitorDetection`, how many nights those charts take to find the step.

The bias counted is the servo's amplitude leak (issue 9): first-order axis
lags ``tau`` shrink each axis's amplitude by ``1/sqrt(1 + (omega tau)^2)``,
the trace becomes an ellipse, and sensor axes turned by ``eps_c`` read
``(A_x - A_y)/A sin(2 eps_c) = omega^2 (tau_y^2 - tau_x^2) / 2 sin(2 eps_c)``
in ``theta_y - theta_x``, the same in both directions, so flipping and
averaging do not cancel it. It grows with ``omega^2 = A / r``: for a given
acceleration a large circle leaks less. It cancels in a change only while the
servo keeps its tuning; the plan counts it whole.

The plan chosen is the one with the smallest detectable change over radii
and feeds within the machine's limits (feed, centripetal acceleration, travel),
the sensor's range and the time given, with as many whole cycles as fit.
"""

import math
from dataclasses import dataclass, field, replace
from functools import partial

from scipy import stats

from imu_square.errors import ImuSquareError
from imu_square.program.ncgen import START_DWELL_S
from imu_square.program.spec import (
    MAX_CENTRIPETAL_M_S2,
    MAX_FEED_M_PER_S,
    MAX_RADIUS_M,
    MIN_CENTRIPETAL_M_S2,
    MIN_FEED_RATIO,
    TestProgram,
    program_from_mapping,
)
from imu_square.units import MM, MM_PER_MIN, SQUARENESS_UNIT, UG, URAD, G
from imu_square.validation import check_int, check_number

# The efficiency of the pipeline's estimator of theta_y - theta_x, the bound's
# variance over the estimate's: measured by ``benchmarks/planner.py
# --efficiency`` over 4 circles (0.1 to 6.4 m/s^2, 0.16 to 2.5 Hz, 5 to 40
# cycles, white and 1/f noise) x 400 independent seeds each: 0.934 +- 0.033
# (sd over the bound 0.97 to 1.08 by circle; the bisquare's asymptotic
# efficiency on Gaussian noise is 0.95).
ESTIMATOR_EFFICIENCY = 0.94

# Fewest whole cycles per block a plan uses: the type A uncertainty is the
# scatter of the cycle pairs and is itself uncertain with few.
MIN_CYCLES = 5
# Smallest radius a plan uses; the NC approach needs a few mm inside the circle. [m]
MIN_RADIUS_M = 5 * MM
# A plan's acceleration leaves this share of the sensor's range free.
RANGE_SHARE = 0.8
# Highest circle frequency of a plan, and at most this fraction of the
# sample rate (the cycles are resampled by linear interpolation). [Hz]
MAX_CIRCLE_HZ = 10.0
MAX_CIRCLE_SAMPLE_FRACTION = 1 / 50
# Dwell between blocks: at least this, and this share of the longest period
# (the analysis merges blocks that rest less than a tenth of a period). [s]
MIN_DWELL_S = 1.0
DWELL_PERIODS = 0.2
# Ratios of the slow feed's v^2/r to the fast one's tried with two feeds.
SLOW_SHARES = (0.1, 0.15, 0.2, 0.25, 0.3, 0.4, 0.5)
# Radii tried (and the largest the travel allows). [mm]
NICE_RADII_MM = (5, 6, 8, 10, 12, 15, 20, 25, 30, 40, 50, 60, 80, 100, 120, 150, 200, 250)
NICE_RADII_MM += (300, 400, 500, 600, 800, 1000)
# A plan that detects within this fraction of the best plan's detectable
# change is as good: the gentlest of them is chosen.
NEAR_BEST = 0.02
# Feeds tried at each radius, as fractions of the fastest allowed.
FEED_FRACTIONS = (1.0, 0.9, 0.8, 0.7, 0.6, 0.5, 0.4, 0.3, 0.2)


class PlanError(ImuSquareError):
    """No circle test fits the limits and the time given."""


class PlanInputError(PlanError):
    """An input outside what a plan can use.

    Attributes
    ----------
    parameter : str
        The field it came from, e.g. ``"max_feed_m_s"`` (``Limits.max_feed_m_s``).
    value : object
        What was given, in the field's SI unit.
    bounds : tuple of float
        ``(lo, hi)``, in the same unit.
    closed : tuple of bool
        Whether ``lo`` and ``hi`` are allowed.
    """

    def __init__(self, parameter, value, bounds, closed, message):
        self.parameter, self.value, self.bounds, self.closed = parameter, value, bounds, closed
        super().__init__(message)


@dataclass(frozen=True)
class SensorSpec:
    """What the planner needs of the sensor.

    Attributes
    ----------
    noise_density_m_s2_rthz : float
        White-noise density per axis. [m/s^2/sqrt(Hz)]
    flicker_corner_hz : float
        1/f corner: the noise PSD is ``d^2 (1 + fc / f)``. [Hz]
    range_m_s2 : float
        Full scale (default: an ADXL355's 2.048 g). [m/s^2]
    sample_rate_hz : float
        Sample rate. [Hz]
    resolution_m_s2 : float
        ADC step; 0 for none. [m/s^2]
    """

    noise_density_m_s2_rthz: float
    flicker_corner_hz: float = 0.0
    range_m_s2: float = 2.048 * G
    sample_rate_hz: float = 1000.0
    resolution_m_s2: float = 0.0

    def psd(self, frequency_hz):
        """One-sided noise PSD per axis at a frequency: white, 1/f and ADC steps.

        Parameters
        ----------
        frequency_hz : float
            Frequency. [Hz]

        Returns
        -------
        float
            ``d^2 (1 + fc / f) + q^2 / (6 fs)``. [(m/s^2)^2/Hz]
        """
        d2 = self.noise_density_m_s2_rthz**2
        quantisation = self.resolution_m_s2**2 / (6 * self.sample_rate_hz)
        return d2 * (1 + self.flicker_corner_hz / frequency_hz) + quantisation


@dataclass(frozen=True)
class Limits:
    """The machine's limits and what the user asks of the test.

    Attributes
    ----------
    max_feed_m_s : float
        Fastest contouring feed. [m/s]
    max_accel_m_s2 : float
        Largest centripetal acceleration the machine runs a stable circle at. [m/s^2]
    travel_m : float
        Shortest of the X and Y travels available around the circle's centre:
        the circle's diameter fits in it. [m]
    time_s : float
        Time available for the whole test, from the first motion to the last. [s]
    servo_lags_s : tuple of 2 float
        The axes' (first-order) following lags, for the amplitude leak bound. [s]
    eps_c_rad : float
        Largest rotation of the sensor on the table about Z. [rad]
    ramp_s : float
        Feed ramp at each block end, counted in the time. [s]
    """

    max_feed_m_s: float
    max_accel_m_s2: float
    travel_m: float
    time_s: float
    servo_lags_s: tuple = (2.0e-3, 2.5e-3)
    eps_c_rad: float = math.radians(2.0)
    ramp_s: float = 0.15


@dataclass(frozen=True)
class Goal:
    """What the test must detect.

    Attributes
    ----------
    change_rad : float or None
        The change of squareness to detect; None to report what is detected. [rad]
    confidence : float
        Confidence of the detection, e.g. 0.95.
    baseline_runs : int
        Runs averaged into the baseline the change is taken against.
    separate_gravity : bool
        Plan two feeds of one circle, to separate gravity coupling.
    stable_servo : bool
        The servo's tuning and the sensor's mount stay as they were for the
        baseline, so the servo's amplitude leak cancels in the change: it is
        reported but not added to the detectable change.
    """

    change_rad: float | None = None
    confidence: float = 0.95
    baseline_runs: int = 1
    separate_gravity: bool = False
    stable_servo: bool = False


@dataclass(frozen=True)
class MonitorDetection:
    """How soon the monitor's designed charts find a step, for a planned test.

    Attributes
    ----------
    false_alarm_nights : float
        The charts' design: one false alarm in this many valid nights. [nights]
    step_rad : float
        The step of squareness found. [rad]
    median_nights, p90_nights : float
        Nights from the step to the alarm: the median, and the count within
        which 90 % of machines alarm (Monte Carlo of the designed scheme,
        from a fresh start, averaged over the baseline's error). [nights]
    """

    false_alarm_nights: float
    step_rad: float
    median_nights: float
    p90_nights: float


@dataclass(frozen=True)
class Plan:
    """A planned test and what it resolves.

    Attributes
    ----------
    program : TestProgram
        The program to run.
    sigma_run_rad : float
        Predicted standard deviation of one run's ``theta_y - theta_x``. [rad]
    crb_run_rad : float
        The bound alone (efficiency 1). [rad]
    sigma_change_rad : float
        Of the change against a baseline of ``goal.baseline_runs`` runs. [rad]
    servo_leak_rad : float
        Bound of the servo's amplitude leak. [rad]
    detectable_change_rad : float
        ``z sigma_change + servo_leak`` (without the leak when
        ``goal.stable_servo``). [rad]
    z : float
        The normal quantile of the confidence (two-sided).
    duration_s : float
        Machine time: start dwell, blocks with their ramps, dwells. [s]
    analysed_s : float
        Time in the analysed whole cycles, all feeds and directions. [s]
    cutoff_hz : float
        The analysis' default low-pass cutoff for the fastest circle, 8 pi x
        its frequency, which the prediction assumes. [Hz]
    time_to_detect_s : float or None
        Machine time this circle, at these feeds, needs to detect
        ``goal.change_rad`` (more or fewer cycles); None without a goal or when
        the leak alone exceeds it. [s]
    goal : Goal
        What was asked.
    sensor : SensorSpec
        The sensor planned for.
    efficiency : float
        The estimator's efficiency used.
    separation_cost : float
        With two feeds: sigma over the best one-feed plan's in the same time; else 1.
    monitor : MonitorDetection or None
        The nights the monitor's charts take to find the step; None until
        worked out (``imu-square plan`` does, from the monitor's own design).
    """

    program: TestProgram
    sigma_run_rad: float
    crb_run_rad: float
    sigma_change_rad: float
    servo_leak_rad: float
    detectable_change_rad: float
    z: float
    duration_s: float
    analysed_s: float
    cutoff_hz: float
    time_to_detect_s: float | None
    goal: Goal
    sensor: SensorSpec
    efficiency: float = ESTIMATOR_EFFICIENCY
    separation_cost: float = field(default=1.0)
    monitor: MonitorDetection | None = None

    @property
    def detects(self):
        """Whether the planned run detects the goal's change (None without one)."""
        if self.goal.change_rad is None:
            return None
        return self.detectable_change_rad <= self.goal.change_rad

    @property
    def cycle_pairs(self):
        """CCW and CW cycle pairs of a one-feed plan's night: its ``u`` has one fewer dof."""
        return self.program.cycles_per_direction * self.program.runs

    def feed_programs(self):
        """The one-feed program of each feed."""
        return [self.program.at_feed(f) for f in range(self.program.n_feeds)]

    def to_json_dict(self):
        """The plan as JSON-ready scalars; angles in µrad (= µm/m).

        Returns
        -------
        dict
        """
        feeds = self.feed_programs()
        goal, m = self.goal, self.monitor
        return {
            "sigma_run_urad": self.sigma_run_rad / URAD,
            "sigma_change_urad": self.sigma_change_rad / URAD,
            "detectable_change_urad": self.detectable_change_rad / URAD,
            "duration_s": self.duration_s,
            "crb_run_urad": self.crb_run_rad / URAD,
            "efficiency": self.efficiency,
            "servo_leak_bound_urad": self.servo_leak_rad / URAD,
            "servo_leak_in_change": not goal.stable_servo,
            "z": self.z,
            "confidence": goal.confidence,
            "baseline_runs": goal.baseline_runs,
            "target_change_urad": None if goal.change_rad is None else goal.change_rad / URAD,
            "detects_target": self.detects,
            "time_to_detect_s": self.time_to_detect_s,
            "radius_mm": self.program.radius_m / MM,
            "feeds_mm_per_min": [p.feed_m_per_s / MM_PER_MIN for p in feeds],
            "cycles_per_direction": list(self.program.feed_cycles),
            "dwell_s": self.program.dwell_s,
            "centripetal_m_s2": [p.centripetal_m_s2 for p in feeds],
            "circle_frequency_hz": [p.frequency_hz for p in feeds],
            "noise_density_at_circle_ug_rthz": [
                math.sqrt(self.sensor.psd(p.frequency_hz)) / UG for p in feeds
            ],
            "analysed_s": self.analysed_s,
            "analysis_cutoff_hz": self.cutoff_hz,
            "separate_gravity": goal.separate_gravity,
            "separation_cost": self.separation_cost,
            "monitor_false_alarm_nights": None if m is None else m.false_alarm_nights,
            "monitor_step_urad": None if m is None else m.step_rad / URAD,
            "monitor_nights_to_detect_median": None if m is None else m.median_nights,
            "monitor_nights_to_detect_p90": None if m is None else m.p90_nights,
            "program": self.program.to_mapping(),
        }

    def summary(self):
        """Human-readable lines: the plan, what it resolves, how to analyse it.

        Returns
        -------
        str
        """
        unit = SQUARENESS_UNIT
        feeds = self.feed_programs()
        p0 = self.program
        speeds = ", ".join(
            f"{p.feed_m_per_s / MM_PER_MIN:g} mm/min x {p.cycles_per_direction} cycles "
            f"({p.centripetal_m_s2:.3g} m/s², {p.frequency_hz:.3g} Hz)"
            for p in feeds
        )
        noise = ", ".join(f"{math.sqrt(self.sensor.psd(p.frequency_hz)) / UG:.3g}" for p in feeds)
        goal = self.goal
        lines = [
            f"plan: r = {p0.radius_m / MM:g} mm, {speeds} each way, dwell {p0.dwell_s:g} s: "
            f"{self.duration_s:.0f} s on the machine, {self.analysed_s:.0f} s analysed",
            f"  one run: σ {self.sigma_run_rad / URAD:.2f} {unit} (Cramér-Rao bound "
            f"{self.crb_run_rad / URAD:.2f} at {noise} µg/√Hz at the circle frequency, over "
            f"the estimator's efficiency {self.efficiency:.2f})"
            + (f"; two feeds cost x{self.separation_cost:.2f}" if goal.separate_gravity else ""),
            f"  change against a baseline of {goal.baseline_runs} run"
            f"{'s' if goal.baseline_runs > 1 else ''}: σ {self.sigma_change_rad / URAD:.2f} "
            f"{unit}",
            *self._monitor_lines(),
            f"  one night alone, a two-sided test at {goal.confidence:.0%} (z = {self.z:.2f}, "
            f"a false alarm in {1 / (1 - goal.confidence):.0f} nights): detects "
            f"{self.detectable_change_rad / URAD:.1f} {unit}",
            f"  servo amplitude leak: up to {self.servo_leak_rad / URAD:.2f} {unit} "
            + (
                "(counted in the detectable change)"
                if not goal.stable_servo
                else "(cancels in the change: servo and mount kept)"
            ),
        ]
        if goal.change_rad is not None:
            target = f"{goal.change_rad / URAD:g} {unit}"
            test = f"one night's {goal.confidence:.0%} test"
            if self.detects:
                lines.append(f"  target {target}: {test} detects it")
            elif self.time_to_detect_s is None:
                lines.append(
                    f"  target {target}: NOT detected by {test}: the servo leak alone is larger"
                )
            else:
                lines.append(
                    f"  target {target}: NOT detected by {test}; this circle needs "
                    f"{self.time_to_detect_s:.0f} s"
                )
        lines.append(
            f"  analysed with the analysis' defaults: low-pass {self.cutoff_hz:.3g} Hz, 8 pi x "
            f"the circle frequency (the plan file's [analysis] keeps them for the monitor)"
        )
        return "\n".join(lines)

    def _monitor_lines(self):
        m = self.monitor
        if m is None:
            return []
        return [
            f"  the monitor (Shewhart, EWMA and CUSUM, one false alarm in "
            f"{m.false_alarm_nights:g} nights): a step of {m.step_rad / URAD:g} "
            f"{SQUARENESS_UNIT} alarms after {m.median_nights:g} night(s), 90 % within "
            f"{m.p90_nights:g}"
        ]

    def to_toml(self):
        """The program file, headed by comments that say what the plan predicts.

        Returns
        -------
        str
            TOML that :func:`imu_square.program.read_program` reads.
        """
        head = [
            "# Planned by imu-square plan:",
            f"#   sigma of one run {self.sigma_run_rad / URAD:.2f} um/m; of the change against "
            f"{self.goal.baseline_runs} baseline run(s) {self.sigma_change_rad / URAD:.2f} um/m",
            *(
                f"#   the monitor: a step of {m.step_rad / URAD:g} um/m alarms after "
                f"{m.median_nights:g} night(s) (median), 90 % within {m.p90_nights:g}"
                for m in [self.monitor]
                if m is not None
            ),
            f"#   one night's two-sided {self.goal.confidence:.0%} test detects "
            f"{self.detectable_change_rad / URAD:.1f} um/m; {self.duration_s:.0f} s on the machine",
        ]
        analysis = [
            "",
            "# The analysis the prediction assumes; imu-square init --program takes it into",
            "# the monitor file. cutoff_hz unset: 8 pi x the circle frequency "
            f"({self.cutoff_hz:.3g} Hz here).",
            "[analysis]",
            "order = 1",
            "bootstrap = 200",
        ]
        return "\n".join(head) + "\n" + self.program.to_toml() + "\n".join(analysis) + "\n"


def _feed_terms(program, sensor, efficiency):
    """Per feed: amplitude ``v^2/r`` [m/s^2], predicted sigma [rad], omega [rad/s]."""
    terms = []
    for f in range(program.n_feeds):
        p = program.at_feed(f)
        analysed = p.n_blocks * p.cycles_per_direction * p.period_s
        psd = sensor.psd(p.frequency_hz)
        amp = p.centripetal_m_s2
        terms.append((amp, math.sqrt(2 * psd / (analysed * efficiency)) / amp, p.omega_rad_s))
    return terms


def _weights(amps, sigmas):
    """First-order weights of the feeds' plain results in the separated squareness."""
    if len(amps) == 1:
        return [1.0]
    w = [1.0 / (a * s) ** 2 for a, s in zip(amps, sigmas, strict=True)]
    a_bar = sum(wi * a for wi, a in zip(w, amps, strict=True)) / sum(w)
    sxx = sum(wi * (a - a_bar) ** 2 for wi, a in zip(w, amps, strict=True))
    return [wi * a * (a - a_bar) / sxx for wi, a in zip(w, amps, strict=True)]


def sigma_run(program, sensor, efficiency=ESTIMATOR_EFFICIENCY):
    """Predicted standard deviation of one run's ``theta_y - theta_x``.

    Parameters
    ----------
    program : TestProgram
        The program; with several feeds, the squareness freed of gravity
        coupling (:mod:`imu_square.pipeline.gravity`).
    sensor : SensorSpec
        The sensor.
    efficiency : float
        The estimator's efficiency; 1 gives the Cramér-Rao bound.

    Returns
    -------
    float
        [rad]
    """
    amps, sigmas, _ = zip(*_feed_terms(program, sensor, efficiency), strict=True)
    weights = _weights(amps, sigmas)
    return math.sqrt(sum((c * s) ** 2 for c, s in zip(weights, sigmas, strict=True)))


def servo_leak(program, sensor, limits):
    """Bound of the servo amplitude leak into ``theta_y - theta_x``.

    Parameters
    ----------
    program : TestProgram
        The program (with several feeds, propagated through the weights).
    sensor : SensorSpec
        The sensor (the weights of several feeds depend on its noise).
    limits : Limits
        The lags and the sensor's largest rotation.

    Returns
    -------
    float
        ``|sum c_i omega_i^2| |tau_y^2 - tau_x^2| / 2 |sin(2 eps_c)|``. [rad]
    """
    tx, ty = limits.servo_lags_s
    per_omega2 = 0.5 * abs(ty * ty - tx * tx) * abs(math.sin(2 * limits.eps_c_rad))
    amps, sigmas, omegas = zip(*_feed_terms(program, sensor, 1.0), strict=True)
    weights = _weights(amps, sigmas)
    return abs(sum(c * w * w for c, w in zip(weights, omegas, strict=True))) * per_omega2


def machine_time_s(program, ramp_s):
    """Time on the machine: the rest before block 0, the blocks with their ramps, the dwells. [s]"""
    return max(program.dwell_s, START_DWELL_S) + program.duration_s + program.n_blocks * ramp_s


def analysed_time_s(program):
    """Time in the analysed whole cycles, over all feeds and blocks. [s]"""
    total = 0.0
    for f in range(program.n_feeds):
        p = program.at_feed(f)
        total += p.n_blocks * p.cycles_per_direction * p.period_s
    return total


def _cutoff(program, sensor):
    """The analysis' default low-pass for the fastest circle: the plan predicts for it."""
    from imu_square.pipeline.filter import circle_cutoff_hz

    fastest = max(program.at_feed(f).frequency_hz for f in range(program.n_feeds))
    return circle_cutoff_hz(fastest, sensor.sample_rate_hz)


def _dwell(periods):
    return math.ceil(max(MIN_DWELL_S, DWELL_PERIODS * max(periods)) * 2) / 2


def _program(radius_mm, feeds_mm_min, cycles, dwell):
    """The program, through the program file's validation: every plan is a valid file."""
    table = {"radius_mm": float(radius_mm), "dwell_s": dwell}
    if len(feeds_mm_min) == 1:
        table.update(feed_mm_per_min=float(feeds_mm_min[0]), cycles_per_direction=cycles[0])
    else:
        table.update(feeds_mm_per_min=[float(f) for f in feeds_mm_min], cycles_per_direction=cycles)
    return program_from_mapping(table, source="plan")


def _most_cycles(radius_mm, feeds_mm_min, shares, limits):
    """Cycle counts that fill the time, split between feeds as ``shares`` of it, or None."""
    periods = [2 * math.pi * radius_mm * MM / (f * MM_PER_MIN) for f in feeds_mm_min]
    dwell = _dwell(periods)
    n_blocks = 2 * len(feeds_mm_min)
    fixed = max(dwell, START_DWELL_S) + (n_blocks - 1) * dwell + n_blocks * limits.ramp_s
    # a block lasts (cycles + 1) periods with 180 deg overshoots
    free = limits.time_s - fixed - sum(2 * p for p in periods)
    if free <= 0:
        return None
    cycles = [math.floor(free * s / (2 * p)) for s, p in zip(shares, periods, strict=True)]
    if min(cycles) < MIN_CYCLES:
        return None
    return _program(radius_mm, feeds_mm_min, [min(c, 1000) for c in cycles], dwell)


def _feasible_feeds(radius_mm, limits, sensor):
    """The feeds tried on this radius, fastest first, in whole 10 mm/min. [mm/min]"""
    radius_m = radius_mm * MM
    accel = min(limits.max_accel_m_s2, MAX_CENTRIPETAL_M_S2, RANGE_SHARE * sensor.range_m_s2)
    top = min(limits.max_feed_m_s, MAX_FEED_M_PER_S, math.sqrt(accel * radius_m))
    max_hz = min(MAX_CIRCLE_HZ, MAX_CIRCLE_SAMPLE_FRACTION * sensor.sample_rate_hz)
    top = min(top, 2 * math.pi * radius_m * max_hz) / MM_PER_MIN
    out = []
    for frac in FEED_FRACTIONS:
        feed = 10 * math.floor(top * frac / 10)
        if feed > 0 and (feed * MM_PER_MIN) ** 2 / radius_m >= MIN_CENTRIPETAL_M_S2:
            if feed not in out:
                out.append(feed)
    return out


def _radii(limits):
    """The radii tried: the nice ones up to half the travel, and that. [mm]"""
    r_max = min(limits.travel_m / 2, MAX_RADIUS_M) / MM
    radii = [r for r in NICE_RADII_MM if MIN_RADIUS_M / MM <= r <= r_max]
    top = math.floor(r_max)
    if top >= MIN_RADIUS_M / MM and top not in radii:
        radii.append(top)
    return radii


def _candidates(limits, sensor, goal):
    for r in _radii(limits):
        for v in _feasible_feeds(r, limits, sensor):
            if not goal.separate_gravity:
                p = _most_cycles(r, [v], [1.0], limits)
                if p is not None:
                    yield p
                continue
            for share in SLOW_SHARES:
                slow = 10 * math.floor(v * math.sqrt(share) / 10)
                if (slow * MM_PER_MIN) ** 2 / (r * MM) < MIN_CENTRIPETAL_M_S2:
                    continue
                if v < MIN_FEED_RATIO * slow:
                    continue
                # sigma^2 = sum c_i^2 2 S_i / (A_i^2 T_i) with |c_i| / A_i = 1 / (A_1 - A_2)
                # for both feeds: least for a given total time when T_i ~ sqrt(S_i)
                freqs = [u * MM_PER_MIN / (2 * math.pi * r * MM) for u in (v, slow)]
                root = [math.sqrt(sensor.psd(f)) for f in freqs]
                shares = [x / sum(root) for x in root]
                p = _most_cycles(r, [v, slow], shares, limits)
                if p is not None:
                    yield p


def _z(confidence):
    """Two-sided normal quantile of a confidence."""
    return float(stats.norm.ppf(0.5 + confidence / 2))


def predict(program, sensor, limits, goal, efficiency=ESTIMATOR_EFFICIENCY):
    """What a given program resolves.

    Parameters
    ----------
    program : TestProgram
        The program (one feed, or several of one circle).
    sensor : SensorSpec
        The sensor.
    limits : Limits
        The machine's lags and ramps (its other limits are not checked here).
    goal : Goal
        Confidence, baseline runs and the change to detect.
    efficiency : float
        The estimator's efficiency.

    Returns
    -------
    Plan
    """
    return _predict(program, sensor, limits, goal, efficiency, _z(goal.confidence))


def _predict(program, sensor, limits, goal, efficiency, z):
    sigma = sigma_run(program, sensor, efficiency)
    crb = sigma * math.sqrt(efficiency)
    sigma_change = sigma * math.sqrt(1 + 1 / goal.baseline_runs)
    leak = servo_leak(program, sensor, limits)
    bias = 0.0 if goal.stable_servo else leak
    detectable = z * sigma_change + bias
    needed = None
    if goal.change_rad is not None and goal.change_rad > bias:
        scale = (z * sigma_change / (goal.change_rad - bias)) ** 2
        # sigma ~ 1 / sqrt(cycles)
        more = tuple(max(math.ceil(c * scale), 2) for c in program.feed_cycles)
        longer = replace(program, cycles_per_direction=more[0], cycles_per_feed=more)
        needed = machine_time_s(longer, limits.ramp_s)
    return Plan(
        program=program,
        sigma_run_rad=sigma,
        crb_run_rad=crb,
        sigma_change_rad=sigma_change,
        servo_leak_rad=leak,
        detectable_change_rad=detectable,
        z=z,
        duration_s=machine_time_s(program, limits.ramp_s),
        analysed_s=analysed_time_s(program),
        cutoff_hz=_cutoff(program, sensor),
        time_to_detect_s=needed,
        goal=goal,
        sensor=sensor,
        efficiency=efficiency,
    )


def _fastest(program, name="centripetal_m_s2"):
    return max(getattr(program.at_feed(f), name) for f in range(program.n_feeds))


def _check(parameter, label, value, lo, hi, lo_open=True, hi_open=False):
    # The error carries the bounds, for a caller that restates them in its own units.
    error = partial(PlanInputError, parameter, value, (lo, hi), (not lo_open, not hi_open))
    check_number(label, value, lo, hi, lo_open=lo_open, hi_open=hi_open, error=error)


def check_inputs(sensor, limits, goal):
    """Refuse inputs outside what a plan can use, naming the parameter.

    Raises
    ------
    PlanInputError
        Its ``parameter`` names the field, for a caller that names its own
        option in its own units.
    """
    _check(
        "noise_density_m_s2_rthz",
        "noise density [m/s^2/sqrt(Hz)]",
        sensor.noise_density_m_s2_rthz,
        0.0,
        1.0,
    )
    _check(
        "flicker_corner_hz",
        "flicker corner [Hz]",
        sensor.flicker_corner_hz,
        0.0,
        1e3,
        lo_open=False,
    )
    _check("range_m_s2", "range [m/s^2]", sensor.range_m_s2, 0.0, 1e4)
    _check("sample_rate_hz", "sample rate [Hz]", sensor.sample_rate_hz, 0.0, 1e6)
    _check("resolution_m_s2", "resolution [m/s^2]", sensor.resolution_m_s2, 0.0, 1.0, lo_open=False)
    _check("max_feed_m_s", "max feed [m/s]", limits.max_feed_m_s, 0.0, 10.0)
    _check(
        "max_accel_m_s2",
        "max centripetal acceleration [m/s^2]",
        limits.max_accel_m_s2,
        0.0,
        1e3,
    )
    _check("travel_m", "travel [m]", limits.travel_m, 2 * MIN_RADIUS_M, 10.0, lo_open=False)
    _check("time_s", "time [s]", limits.time_s, 0.0, 1e6)
    for lag in limits.servo_lags_s:
        _check("servo_lags_s", "servo lag [s]", lag, 0.0, 1.0, lo_open=False)
    _check(
        "eps_c_rad",
        "sensor rotation eps_c [rad]",
        limits.eps_c_rad,
        0.0,
        math.pi / 4,
        lo_open=False,
    )
    _check("ramp_s", "ramp [s]", limits.ramp_s, 0.0, 5.0, lo_open=False)
    _check("confidence", "confidence", goal.confidence, 0.0, 1.0, hi_open=True)
    if goal.change_rad is not None:
        _check("change_rad", "change to detect [rad]", goal.change_rad, 0.0, 1.0)
    check_int("baseline runs", goal.baseline_runs, error=PlanError)
    _check("baseline_runs", "baseline runs", goal.baseline_runs, 0, 1e6)


def plan_test(sensor, limits, goal, efficiency=ESTIMATOR_EFFICIENCY):
    """The circle test that detects the smallest change in the time given.

    Parameters
    ----------
    sensor : SensorSpec
        The sensor.
    limits : Limits
        The machine's limits and the time.
    goal : Goal
        What to detect, at what confidence, against how many baseline runs,
        and whether to separate gravity coupling (two feeds).
    efficiency : float
        The estimator's efficiency (measured, :data:`ESTIMATOR_EFFICIENCY`).

    Returns
    -------
    Plan
        Smallest detectable change; ties go to the lower acceleration, then
        the shorter test.

    Raises
    ------
    PlanError
        Bad inputs, or no circle with at least :data:`MIN_CYCLES` cycles fits.
    """
    check_inputs(sensor, limits, goal)
    z = _z(goal.confidence)
    plans = [
        _predict(program, sensor, limits, goal, efficiency, z)
        for program in _candidates(limits, sensor, goal)
    ]
    if not plans:
        raise PlanError(
            f"no circle test fits: at least {MIN_CYCLES} cycles each way"
            f"{' at each of two feeds' if goal.separate_gravity else ''} on a circle of "
            f"{MIN_RADIUS_M / MM:g} mm to half the travel ({limits.travel_m / MM / 2:g} mm) need "
            f"more than the {limits.time_s:g} s given at a feed up to "
            f"{limits.max_feed_m_s / MM_PER_MIN:g} mm/min and {limits.max_accel_m_s2:g} m/s^2"
        )
    # Of the plans within NEAR_BEST of the best, the gentlest: lowest circle
    # frequency (the machine's and the mount's dynamics), then acceleration, then time.
    best = min(p.detectable_change_rad for p in plans)
    plan = min(
        (p for p in plans if p.detectable_change_rad <= (1 + NEAR_BEST) * best),
        key=lambda p: (_fastest(p.program, "frequency_hz"), _fastest(p.program), p.duration_s),
    )
    if goal.separate_gravity:
        single = plan_test(sensor, limits, replace(goal, separate_gravity=False), efficiency)
        plan = replace(plan, separation_cost=plan.sigma_run_rad / single.sigma_run_rad)
    return plan
