"""Find the CCW and CW blocks in the data and map time to position angle.

The recording's own signal decides where the machine moved: the magnitude of
the horizontal acceleration about its median (the rest level, which holds a
static tilt's share of gravity) rises to ``v^2/r`` while the table runs a
circle. Motion intervals are matched to the program's blocks by their
nominal duration and spacing, or by the block markers in the recording's
events when present. Idle lead-in and lead-out, dwells, unknown feed ramps and
the overshoots need no special case: only the cycles after the overshoot are
analysed (:mod:`imu_square.pipeline.align`).

For each block the direction and the actual circle frequency come from the
data: the unwrapped phase of ``a_x + i a_y`` turns at ``+omega`` for CCW and
``-omega`` for CW (the acceleration vector points at the centre and follows the
tool). Its slope gives the period actually run, which the pipeline compares
with the program (a disagreement means a feed override or a sample clock
error).

Time maps to commanded position angle by ``phi(t) = phi_mid + sign * omega *
(t - t_mid)``, anchored at the middle of the detected motion, ``t_mid``, the
mean of the threshold crossings at the start and the end of the block, which
corresponds to ``phi_start + sign * block_angle / 2`` when the acceleration and
deceleration ramps mirror each other (``docs/model.md``, eps_c).
"""

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from imu_square.errors import AnalysisError

# Motion intervals closer than this fraction of a period are one interval.
_MERGE_PERIODS = 0.1
# Accepted detected duration of a block, relative to the nominal one (ramps lengthen it).
_DURATION_RANGE = (0.7, 1.5)
# A circle's phase is linear in time: samples departing by more than this are off it, [rad]
_MAX_PHASE_DEVIATION = 0.5
# and a block with a larger fraction of such samples is not a circle.
_MAX_OFF_CIRCLE = 0.2
# A circle's acceleration magnitude is constant; a robust spread above this is not a circle.
_MAX_ENVELOPE_SPREAD = 0.25
# Below this share of v^2/r the envelope's highest level is no circle but rest.
_REST_SHARE = 0.2
# Samples kept away from motion when estimating the rest level.
_REST_PAD = 50
# Above this condition number of its Gram matrix the phase fit is solved by lstsq:
# the normal equations lose cond * 1e-16 of relative precision.
_MAX_GRAM_CONDITION = 1e6


@dataclass(frozen=True)
class Block:
    """One block as found in the data.

    Attributes
    ----------
    plan : BlockPlan
        The program's plan of this block.
    t_start_s, t_stop_s : float
        Detected start and end of motion, from the first sample. [s]
        Where a gap hides one of them, it is the other one minus or plus the
        length of motion of the blocks without such a gap.
    u_t_mid_s : float
        Standard uncertainty of the motion midpoint from the envelope noise
        (and, for a block anchored by one end, from the length taken). [s]
    omega_rad_s : float
        Signed angular speed from the phase slope (+ CCW, - CW). [rad/s]
    lost_end : tuple or None
        ``(label, (gap_start_s, gap_end_s))`` when a gap hides the block's
        ``"start"`` or ``"stop"`` of motion; None when both were seen.
    """

    plan: object
    t_start_s: float
    t_stop_s: float
    u_t_mid_s: float
    omega_rad_s: float
    lost_end: tuple | None = None

    @property
    def t_mid_s(self):
        """Middle of the detected motion. [s]"""
        return 0.5 * (self.t_start_s + self.t_stop_s)

    @property
    def direction(self):
        """``"ccw"`` or ``"cw"``."""
        return self.plan.direction

    @property
    def sign(self):
        """+1 for CCW, -1 for CW."""
        return self.plan.sign


@dataclass(frozen=True)
class Segmentation:
    """The blocks found in a recording and the measured circle frequency.

    Attributes
    ----------
    program : TestProgram
        The program the blocks were matched to.
    blocks : tuple of Block
        Blocks in execution order.
    omega_rad_s : float
        Measured angular speed, pooled over blocks. [rad/s]
    baseline_m_s2 : ndarray, shape (2,)
        Rest level of x and y (median). [m/s^2]
    threshold_m_s2 : float
        Envelope level that separates motion from rest. [m/s^2]
    """

    program: object
    blocks: tuple
    omega_rad_s: float
    baseline_m_s2: np.ndarray
    threshold_m_s2: float

    @property
    def period_s(self):
        """Measured period of one circle. [s]"""
        return 2 * np.pi / self.omega_rad_s

    @property
    def period_disagreement(self):
        """Measured period over the program's, minus 1 (positive: slower than programmed)."""
        return self.period_s / self.program.period_s - 1

    def phi(self, block, t_s):
        """Commanded position angle at ``t_s`` within ``block``.

        Parameters
        ----------
        block : Block
            The block.
        t_s : float or ndarray
            Time from the first sample. [s]

        Returns
        -------
        float or ndarray
            Position angle, unwrapped along the block. [rad]
        """
        prog = self.program
        phi_mid = block.plan.start_angle_rad + block.sign * prog.block_angle_rad / 2
        return phi_mid + block.sign * self.omega_rad_s * (np.asarray(t_s) - block.t_mid_s)

    def anchor_uncertainty_rad(self, direction):
        """Standard uncertainty of the anchor angle, averaged over one direction's blocks.

        Parameters
        ----------
        direction : {"ccw", "cw"}
            The direction.

        Returns
        -------
        float
            ``omega`` times the midpoint timing uncertainty of the mean over
            that direction's blocks. [rad]
        """
        u = [b.u_t_mid_s for b in self.blocks if b.direction == direction]
        return self.omega_rad_s * float(np.sqrt(np.sum(np.square(u)))) / len(u)

    def time_at(self, block, phi_rad):
        """Inverse of :meth:`phi`: time at which ``block`` is at ``phi_rad``. [s]"""
        prog = self.program
        phi_mid = block.plan.start_angle_rad + block.sign * prog.block_angle_rad / 2
        return block.t_mid_s + (np.asarray(phi_rad) - phi_mid) / (block.sign * self.omega_rad_s)


def _runs(mask):
    """Start (inclusive) and stop (exclusive) indices of True runs."""
    d = np.diff(np.concatenate([[0], mask.astype(np.int8), [0]]))
    return np.flatnonzero(d == 1), np.flatnonzero(d == -1)


def _minus_row(a, row, out=None):
    """``a - row`` for an (n, k) array and a (k,) row, column by column. [unit of a]

    numpy broadcasts ``a - row`` with an inner loop of k elements, eight times
    slower for k = 2; the numbers are the same, bit for bit. ``out`` (float64,
    shape of ``a``) receives it.
    """
    out = np.empty(a.shape) if out is None else out
    for j in range(a.shape[1]):
        np.subtract(a[:, j], row[j], out=out[:, j])
    return out


def _magnitude(rel, out=None):
    """Length of each row's (x, y): within an ulp of ``np.hypot``, six times faster. [m/s^2]

    ``out`` (shape (n,)) receives it, so that a second pass reuses the first's array.
    """
    x, y = rel[:, 0], rel[:, 1]
    out = np.multiply(x, x, out=out)
    out += y * y
    return np.sqrt(out, out=out)


def _crossing(t, env, i, thr):
    """Time where env crosses thr between samples i - 1 and i (linear)."""
    if i <= 0 or i >= t.size:  # motion runs into the start or end of the recording
        return float(t[min(max(i, 0), t.size - 1)]), 0.0
    e0, e1 = env[i - 1], env[i]
    frac = (thr - e0) / (e1 - e0)  # e0 and e1 straddle thr, so they differ
    slope = abs(e1 - e0) / (t[i] - t[i - 1])
    return float(t[i - 1] + frac * (t[i] - t[i - 1])), slope


def _rotation(t, rel, period):
    """Angular speed of the acceleration vector and the fraction of samples off a circle.

    A first guess from the median phase step over an eighth of a period (no
    unwrapping, robust to spikes), refined by a least-squares fit of the phase
    left after removing it, on the samples within 0.5 rad of uniform rotation.
    The fit has a line and a ripple at twice the circle frequency: any ellipse
    (a sensor's non-orthogonality, gain or scale mismatch, squareness) makes the
    vector turn unevenly at 2 omega, and a line alone over a window that is not
    a whole number of half-turns would take part of that ripple for a change
    of speed (6 ppm for beta = 5 mrad at eps_c = 8 deg, enough to move
    theta_y - theta_x by 2.6 µrad through the phase map). The ripple at omega
    comes from a circle whose centre is off the rest level the vector is taken
    about: a tilt that changes with position (gravity coupling) reads
    differently at rest on the start point than on average over the circle
    (k r g / A of ripple: 33 ppm of speed, 3 µrad of theta_y - theta_x, for
    100 µrad/m on r = 100 mm at 0.025 m/s^2).
    """
    # Phases as arctan2 once, their differences wrapped: the same as the angles of
    # z[lag:] conj(z[:-lag]) and of z exp(-i omega0 t) without complex arithmetic.
    angle = np.arctan2(rel[:, 1], rel[:, 0])
    dt = float(np.median(np.diff(t)))
    lag = max(1, round(period / 8 / dt))
    if angle.size <= lag + 2:
        return 0.0, 1.0
    # Steps over `lag` samples, each over its own time: across a gap it is longer.
    # Each step in place on the previous temporary (fresh arrays cost page faults).
    rates = _wrap(angle[lag:] - angle[:-lag], inplace=True)
    rates /= t[lag:] - t[:-lag]
    omega0 = float(np.median(rates))
    tm = 0.5 * (t[0] + t[-1])
    u = t - tm
    resid = np.multiply(omega0, u)
    resid = _wrap(np.subtract(angle, resid, out=resid), inplace=True)
    dev = _wrap(resid - float(np.median(resid)), inplace=True)
    good = np.abs(dev) < _MAX_PHASE_DEVIATION
    n_good = np.count_nonzero(good)
    if n_good < 3:
        return omega0, 1.0
    slope = _phase_slope(u[good], dev[good], omega0)
    return omega0 + slope, 1.0 - float(n_good) / good.size


def _wrap(angle, inplace=False):
    """Angles wrapped into [-pi, pi]; into ``angle`` itself if ``inplace``. [rad]"""
    turns = np.rint(angle / (2 * np.pi))
    turns *= 2 * np.pi
    return np.subtract(angle, turns, out=angle if inplace else None)


def _phase_slope(u, dev, omega):
    """Slope of a least-squares line plus ripples at omega and 2 omega through ``dev``. [rad/s]

    By the normal equations of the basis with time scaled to [-1, 1] (a 6 x 6
    Gram matrix, condition about 3 over whole circles): a quarter of the cost of
    ``np.linalg.lstsq``, which solves it where the Gram matrix is too
    ill-conditioned for that (a window of a fraction of a period).
    """
    half = max(abs(u[0]), abs(u[-1]), np.finfo(float).tiny)
    # The rows [1, u / half, c, s, c^2 - s^2, 2 c s] written in place: no temporaries.
    basis = np.empty((6, u.size))
    basis[0] = 1.0
    np.divide(u, half, out=basis[1])
    c, s, c2, s2 = basis[2], basis[3], basis[4], basis[5]
    np.multiply(omega, u, out=c2)
    np.cos(c2, out=c)
    np.sin(c2, out=s)
    np.multiply(s, s, out=s2)
    np.multiply(c, c, out=c2)
    c2 -= s2
    np.multiply(2, c, out=s2)
    s2 *= s
    gram = basis @ basis.T
    if np.linalg.cond(gram) < _MAX_GRAM_CONDITION:
        return float(np.linalg.solve(gram, basis @ dev)[1] / half)
    w = omega * u
    design = np.column_stack(
        [np.ones_like(u), u, np.cos(w), np.sin(w), np.cos(2 * w), np.sin(2 * w)]
    )
    return float(np.linalg.lstsq(design, dev, rcond=None)[0][1])


def _sense(t, rel, t0, t1, period):
    """Rotation sense (+1 CCW, -1 CW, 0 none) of the acceleration in the middle half."""
    lo = np.searchsorted(t, 0.75 * t0 + 0.25 * t1, side="right")
    hi = np.searchsorted(t, 0.25 * t0 + 0.75 * t1, side="left")
    return int(np.sign(_rotation(t[lo:hi], rel[lo:hi], period)[0]))


def _motion_intervals(t, env, thr, period):
    starts, stops = _runs(env > thr)
    if starts.size == 0:
        return []
    merged = [[starts[0], stops[0]]]
    for a, b in zip(starts[1:], stops[1:], strict=True):
        if t[a] - t[merged[-1][1] - 1] < _MERGE_PERIODS * period:
            merged[-1][1] = b
        else:
            merged.append([a, b])
    return [(a, b) for a, b in merged if t[b - 1] - t[a] > 0.5 * period]


def _select(motion, blocks, events_t, nominal):
    """Pick one interval per planned block, by events or by the nominal spacing."""
    intervals, t_start, t_stop = motion.intervals, motion.t_start, motion.t_stop
    lo, hi = _DURATION_RANGE
    cands = [
        j for j in range(len(intervals)) if lo * nominal <= t_stop[j] - t_start[j] <= hi * nominal
    ]
    n = len(blocks)
    mids = np.array([0.5 * (t_start[j] + t_stop[j]) for j in cands])
    if events_t:
        chosen = []
        for plan in blocks:
            if plan.index not in events_t:
                break
            if mids.size == 0:
                return None
            k = int(np.argmin(np.abs(mids - events_t[plan.index])))
            if abs(mids[k] - events_t[plan.index]) > 0.5 * nominal:
                return None
            chosen.append(cands[k])
        else:
            return chosen
    if len(cands) < n:
        return None
    offsets = np.array([p.t_start_s for p in blocks])
    signs = np.array([p.sign for p in blocks])
    starts = np.array([t_start[j] for j in cands])
    turns = np.array([motion.senses[j] for j in cands])
    best, best_cost = None, (np.inf, np.inf)
    for w in range(len(cands) - n + 1):
        s = starts[w : w + n]
        # Prefer windows whose rotation senses match the program, then the spacing.
        cost = (
            int(np.sum(turns[w : w + n] != signs)),
            float(np.sum((s - s[0] - (offsets - offsets[0])) ** 2)),
        )
        if cost < best_cost:
            best, best_cost = cands[w : w + n], cost
    return best


def gap_spans(t_s):
    """``(last sample before, first sample after)`` of each gap in sample times.

    Parameters
    ----------
    t_s : ndarray, shape (n_samples,)
        Sample times. [s]

    Returns
    -------
    list of tuple (float, float)
        Every step longer than 1.5 nominal sample spacings. [s]
    """
    dt = float(np.median(np.diff(t_s[: min(t_s.size, 1000)])))
    big = np.flatnonzero(np.diff(t_s) > 1.5 * dt)
    return [(float(t_s[i]), float(t_s[i + 1])) for i in big]


def _gap_near(spans, tc, guard_s):
    """The first gap ``(start, end)`` within ``guard_s`` of ``tc``, or None."""
    for a, b in spans:
        if a <= tc + guard_s and b >= tc - guard_s:
            return (a, b)
    return None


@dataclass(frozen=True)
class Motion:
    """Where the table moved: the envelope of the horizontal acceleration and its intervals.

    Attributes
    ----------
    t_s : ndarray, shape (n_samples,)
        Sample times from the first sample. [s]
    rel : ndarray, shape (n_samples, 2)
        Low-passed x and y about the rest level. [m/s^2]
    env : ndarray, shape (n_samples,)
        Magnitude of ``rel``. [m/s^2]
    baseline_m_s2 : ndarray, shape (2,)
        Rest level of x and y. [m/s^2]
    threshold_m_s2 : float
        Envelope level that separates motion from rest. [m/s^2]
    intervals : list of tuple (int, int)
        Start (inclusive) and stop (exclusive) sample of each motion interval.
    crossings : list of tuple
        ``((t_start, slope), (t_stop, slope))`` of each interval's threshold
        crossings ([s], [m/s^3]); a slope of 0 means cut by the recording's edge.
    period_s : float
        The program's circle period. [s]
    """

    t_s: np.ndarray
    rel: np.ndarray
    env: np.ndarray
    baseline_m_s2: np.ndarray
    threshold_m_s2: float
    intervals: list
    crossings: list
    period_s: float

    @property
    def t_start(self):
        """Start of motion of each interval. [s]"""
        return [c[0][0] for c in self.crossings]

    @property
    def t_stop(self):
        """End of motion of each interval. [s]"""
        return [c[1][0] for c in self.crossings]

    @cached_property
    def sample_step_s(self):
        """Median step between samples, found once for all blocks. [s]"""
        return float(np.median(np.diff(self.t_s)))

    @cached_property
    def senses(self):
        """Rotation sense of each interval (+1 CCW, -1 CW, 0 none).

        Found when first asked: block markers, when the recording has them,
        pick the intervals without it.
        """
        return [_sense(self.t_s, self.rel, c[0][0], c[1][0], self.period_s) for c in self.crossings]


def find_motion(t_s, accel_xy, program):
    """Motion intervals in low-passed horizontal acceleration.

    Parameters
    ----------
    t_s : ndarray, shape (n_samples,)
        Sample times from the first sample. [s]
    accel_xy : ndarray, shape (n_samples, 2)
        Low-passed sensor x and y acceleration. [m/s^2]
    program : TestProgram
        The program the machine ran (how much of the recording is motion).

    Returns
    -------
    Motion
    """
    t_s = np.asarray(t_s, dtype=np.float64)
    baseline = np.median(accel_xy, axis=0)
    rel = _minus_row(accel_xy, baseline)
    env = _magnitude(rel)
    plans = program.blocks()
    nominal = program.block_duration_s
    duration = t_s[-1] - t_s[0] if t_s.size > 1 else 0.0
    fraction = np.clip(len(plans) * nominal / max(duration, 1e-9), 0.02, 0.98)
    level = float(np.quantile(env, 1 - fraction / 2))
    thr = 0.5 * level
    intervals = _motion_intervals(t_s, env, thr, program.period_s)
    rest = np.ones(t_s.size, dtype=bool)
    for a, b in intervals:
        rest[max(a - _REST_PAD, 0) : b + _REST_PAD] = False
    if np.count_nonzero(rest) > _REST_PAD:
        # Re-centre on the rest level alone: the median over the whole recording
        # is pulled by the circles, which would make start and stop asymmetric.
        baseline = np.median(accel_xy[rest], axis=0)
        # Into the first pass's arrays: a fresh allocation costs more than the arithmetic.
        rel = _minus_row(accel_xy, baseline, out=rel)
        env = _magnitude(rel, out=env)
        intervals = _motion_intervals(t_s, env, thr, program.period_s)
    crossings = [(_crossing(t_s, env, a, thr), _crossing(t_s, env, b, thr)) for a, b in intervals]
    return Motion(t_s, rel, env, baseline, thr, intervals, crossings, program.period_s)


def match_blocks(motion, program, events=()):
    """Pick the motion interval of each planned block.

    Parameters
    ----------
    motion : Motion
        The motion intervals found.
    program : TestProgram
        The program the machine ran.
    events : sequence of tuple (float, str, int)
        ``(time_s, kind, block)`` of ``block_start`` / ``block_end`` markers,
        time from the first sample; optional.

    Returns
    -------
    list of int
        Index into ``motion.intervals`` of each planned block, in order.

    Raises
    ------
    AnalysisError
        If no set of intervals matches the program.
    """
    plans = program.blocks()
    nominal = program.block_duration_s
    events_t = {}
    starts_ev = {b: t for t, kind, b in events if kind == "block_start"}
    for t, kind, b in events:
        if kind == "block_end" and b in starts_ev:
            events_t[b] = 0.5 * (starts_ev[b] + t)
    t_start, t_stop = motion.t_start, motion.t_stop
    chosen = _select(motion, plans, events_t, nominal)
    if chosen is None:
        # The threshold is half the envelope's level where it is highest: a table at
        # rest reaches only its noise there, far below the circles' v^2/r.
        level = 2 * motion.threshold_m_s2
        if level < _REST_SHARE * program.centripetal_m_s2:
            raise AnalysisError(
                f"no motion: the horizontal acceleration stays within {level:.2g} m/s^2 of "
                f"its rest level, while the program's circles reach v^2/r = "
                f"{program.centripetal_m_s2:.3g} m/s^2: the table did not move during the "
                f"recording (was the program run, at this feed?)"
            )
        longest = max((b - a for a, b in zip(t_start, t_stop, strict=True)), default=0.0)
        raise AnalysisError(
            f"no circular motion matching the program: expected {len(plans)} blocks of about "
            f"{nominal:.1f} s (period {program.period_s:.2f} s, v^2/r = "
            f"{program.centripetal_m_s2:.3g} m/s^2), found {len(motion.intervals)} motion "
            f"interval(s) longer than half a period, the longest {longest:.1f} s"
        )
    return chosen


@dataclass(frozen=True)
class _Ends:
    """A block's start and stop of motion as seen, each None where a gap hides it."""

    plan: object
    t_s: tuple  # (start, stop) [s]
    u_s: tuple  # their standard uncertainties [s]
    gaps_s: tuple  # the gap hiding each, or None
    omega_rad_s: float


def measure_block(motion, j, plan, program, guard_s=0.0, gaps_s=None, short_gaps_s=(), reach_s=0.0):
    """The ends of the block found in interval ``j``, refused unless it is a trustworthy circle.

    Parameters
    ----------
    motion : Motion
        The motion intervals found.
    j : int
        Index of the block's interval in ``motion.intervals``.
    plan : BlockPlan
        The program's plan of the block.
    program : TestProgram
        The program the machine ran.
    guard_s : float
        A gap within this time of the start or stop of motion hides it. [s]
    gaps_s : sequence of tuple (float, float), optional
        ``(last sample before, first sample after)`` of each long gap (not
        bridged, :func:`imu_square.pipeline.filter.bridge_gaps`): one within
        ``guard_s`` plus a tenth of a period hides the end; found from the
        steps of ``motion.t_s`` if None. [s]
    short_gaps_s : sequence of tuple (float, float)
        The same for each short gap: one that holds the start or stop of
        motion hides it; those within ``reach_s`` of it widen its uncertainty
        by their total length over sqrt(12). [s]
    reach_s : float
        How far the filter carries what a short gap changes. [s]

    Returns
    -------
    _Ends

    Raises
    ------
    AnalysisError
        The motion is not a circle, turns the wrong way, or is cut by the
        recording's edge.
    """
    t_s, rel, env = motion.t_s, motion.rel, motion.env
    (t0, s0), (t1, s1) = motion.crossings[j]
    mid = 0.5 * (t0 + t1)
    half = 0.45 * program.cycles_per_direction * program.period_s
    sel = slice(np.searchsorted(t_s, mid - half), np.searchsorted(t_s, mid + half, side="right"))
    env_s = env[sel]
    level_s = float(np.median(env_s))
    spread = 1.4826 * float(np.median(np.abs(env_s - level_s))) / level_s
    if spread > _MAX_ENVELOPE_SPREAD:
        raise AnalysisError(
            f"block {plan.index} ({plan.direction}) is not a circle: the horizontal "
            f"acceleration's magnitude varies by {spread:.0%} (robust sd; a circle keeps it "
            f"constant at v^2/r; below {_MAX_ENVELOPE_SPREAD:.0%})"
        )
    omega, off = _rotation(t_s[sel], rel[sel], program.period_s)
    if off > _MAX_OFF_CIRCLE:
        raise AnalysisError(
            f"block {plan.index} ({plan.direction}) is not a circle: the direction of the "
            f"horizontal acceleration departs from uniform rotation by more than "
            f"{_MAX_PHASE_DEVIATION} rad for {off:.0%} of the samples (a circle: none)"
        )
    if np.sign(omega) != plan.sign:
        sense = "clockwise" if omega < 0 else "counter-clockwise"
        raise AnalysisError(
            f"block {plan.index} should run {plan.direction} but the data turn {sense}: "
            f"check the program's order, or the sensor's mounting (upside down or "
            f"x and y swapped)"
        )
    if s0 == 0.0 or s1 == 0.0:
        raise AnalysisError(
            f"block {plan.index} ({plan.direction}) is cut off by the "
            f"{'start' if s0 == 0.0 else 'end'} of the recording: its motion midpoint, "
            f"which anchors the position angle, is unknown"
        )
    spans = gap_spans(t_s) if gaps_s is None else gaps_s
    # Envelope noise over its slope at each crossing, and the sampling grid
    # (an onset between two samples is placed uniformly within dt); short gaps
    # within the filter's reach move a crossing, taken as uniform over their
    # total length (over 24 runs with 3 and 10 % lost the error was 0.4 of it).
    sd = spread * level_s  # robust sd of the envelope [m/s^2]
    quant = motion.sample_step_s / np.sqrt(12)
    hidden, u = [], []
    for tc, slope in ((t0, s0), (t1, s1)):
        hidden.append(
            _gap_near(spans, tc, guard_s + 0.1 * program.period_s)
            or _gap_near(short_gaps_s, tc, 0.0)
        )
        near = sum(b - a for a, b in short_gaps_s if a <= tc + reach_s and b >= tc - reach_s)
        u.append(float(np.hypot(np.hypot(sd / slope, quant), near / np.sqrt(12))))
    return _Ends(plan, (t0, t1), tuple(u), tuple(hidden), omega)


def _anchored(ends, length_s, u_length_s):
    """The block of ``ends``, a hidden end placed by the length of motion of the others."""
    (t0, t1), (u0, u1), gaps = ends.t_s, ends.u_s, ends.gaps_s
    lost = None
    if gaps[0] is not None:
        t0, u_mid, lost = t1 - length_s, float(np.hypot(u1, 0.5 * u_length_s)), ("start", gaps[0])
    elif gaps[1] is not None:
        t1, u_mid, lost = t0 + length_s, float(np.hypot(u0, 0.5 * u_length_s)), ("stop", gaps[1])
    else:
        u_mid = 0.5 * float(np.hypot(u0, u1))
    return Block(ends.plan, t0, t1, u_mid, ends.omega_rad_s, lost)


def _length_of_motion(seen):
    """Mean length of motion of fully seen blocks, and its uncertainty for another block.

    One block's length varies from the mean by the blocks' scatter, or, with
    too few to show one, by the timing uncertainty of a length measured. [s]
    """
    lengths = np.array([e.t_s[1] - e.t_s[0] for e in seen])
    timing = float(np.mean([u0**2 + u1**2 for u0, u1 in (e.u_s for e in seen)]))
    scatter = float(np.var(lengths, ddof=1)) if lengths.size > 1 else 0.0
    return float(np.mean(lengths)), float(np.sqrt(max(scatter, timing) * (1 + 1 / lengths.size)))


def segment(
    t_s, accel_xy, program, events=(), guard_s=0.0, gaps_s=None, short_gaps_s=(), reach_s=0.0
):
    """Find the program's blocks in low-passed horizontal acceleration.

    Parameters
    ----------
    t_s : ndarray, shape (n_samples,)
        Sample times from the first sample. [s]
    accel_xy : ndarray, shape (n_samples, 2)
        Low-passed sensor x and y acceleration. [m/s^2]
    program : TestProgram
        The program the machine ran.
    events : sequence of tuple (float, str, int)
        ``(time_s, kind, block)`` of ``block_start`` / ``block_end`` markers,
        time from the first sample; optional.
    guard_s : float
        A gap in the samples within this time of a block's start or stop of
        motion hides it: the block is then anchored by its other end and the
        length of motion of the blocks whose ends were both seen. [s]
    gaps_s, short_gaps_s, reach_s
        Gaps not bridged and bridged, and the filter's reach: see :func:`measure_block`.

    Returns
    -------
    Segmentation

    Raises
    ------
    AnalysisError
        If the data hold no circle matching the program, or a block turns the
        wrong way, or its motion is not a circle, or gaps hide both ends of a
        block's motion, or one end of every block's.
    """
    motion = find_motion(t_s, accel_xy, program)
    chosen = match_blocks(motion, program, events)
    ends = [
        measure_block(motion, j, plan, program, guard_s, gaps_s, short_gaps_s, reach_s)
        for plan, j in zip(program.blocks(), chosen, strict=True)
    ]
    seen = [e for e in ends if e.gaps_s == (None, None)]
    for e in ends:
        hidden = [
            (label, tc, g)
            for label, tc, g in zip(("start", "stop"), e.t_s, e.gaps_s, strict=True)
            if g
        ]
        if len(hidden) == 2 or (hidden and not seen):
            label, tc, gap = hidden[0]
            why = "its stop too" if len(hidden) == 2 else "so is an end of every other block's"
            raise AnalysisError(
                f"block {e.plan.index} ({e.plan.direction}): its {label} of motion at "
                f"{tc:.2f} s is next to a gap in the data ({gap[0]:.2f}-{gap[1]:.2f} s), and "
                f"{why}, so the motion midpoint that anchors the position angle is unknown"
            )
    length = _length_of_motion(seen) if len(seen) < len(ends) else (0.0, 0.0)
    blocks = tuple(_anchored(e, *length) for e in ends)
    weights = np.array([b.t_stop_s - b.t_start_s for b in blocks])
    omega = float(np.sum(np.abs([b.omega_rad_s for b in blocks]) * weights) / np.sum(weights))
    return Segmentation(
        program=program,
        blocks=blocks,
        omega_rad_s=omega,
        baseline_m_s2=motion.baseline_m_s2,
        threshold_m_s2=motion.threshold_m_s2,
    )


def block_events(recording):
    """The block markers of a recording, as :func:`segment` takes them.

    Parameters
    ----------
    recording : Recording
        The recording.

    Returns
    -------
    list of tuple (float, str, int)
        ``(time_s, kind, block)`` from the first sample. [s]
    """
    t0 = int(recording.time_ns[0])
    return [
        ((e.time_ns - t0) * 1e-9, e.kind, e.block)
        for e in recording.events
        if e.kind in ("block_start", "block_end")
    ]
