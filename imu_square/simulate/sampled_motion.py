"""A motion a controller sampled: the axes' commanded positions every servo period.

The simulator takes "a motion", what the axes were commanded to do in time,
from either of two sources: our own trajectory (:mod:`.trajectory`, analytic)
or a real controller's trajectory planner (LinuxCNC, :mod:`imu_square.linuxcnc`),
whose commanded positions are sampled every servo period. :class:`SampledMotion`
gives the second the interface of the first (:class:`.trajectory.Timeline`), so
the machine and sensor models run on either through one code path:

- ``axis_path(t, axis)``: commanded position, velocity and acceleration of an
  axis at any time. Between the samples the path is the quintic spline
  through them, at rest at both ends (zero velocity and acceleration: the
  machine rests before and after the program); its velocity and acceleration
  are exact derivatives of the position that the geometry sees. A cubic
  spline would not do: on a circle sampled ``theta = omega T`` apart its
  acceleration at the samples is ``theta^2 / 12`` too large (29 ppm on a
  25 mm circle at 28 m/min and 1 ms), which a sensor sampling in step with
  the servo sees whole; the quintic's error is of order ``theta^4``. Unlike
  our own trajectory, positions are differenced here: the controller gives
  nothing else;
- ``blocks``: each block's start and end of motion, its angular speed as run
  (the median over the middle half of the block, away from the ramps) and the
  times at which it enters and leaves its analysed whole cycles (where the
  angle travelled reaches the overshoot, and the block angle less the
  overshoot);
- ``reversals(axis)``: when each axis starts moving the other way, over the
  whole motion (the approach moves included, which our own trajectory leaves
  out): where its velocity crosses zero, or where it starts again after a rest.

Which samples belong to which block is given (``spans``): the controller's
block markers say it (:func:`imu_square.linuxcnc.samples.block_spans`). Each
block is checked against the program: direction, start angle, angle travelled
and radius.
"""

import math
from dataclasses import dataclass, field, replace

import numpy as np
from scipy.interpolate import make_interp_spline

from imu_square.errors import ControllerError

# A step shorter than this is no motion: the samples' own resolution. [m]
STEP_EPS_M = 1e-11
# A block's start angle and angle travelled must match the program's to this. [rad]
ANGLE_TOL_RAD = 0.01
# Its samples must lie this close to the circle, relative to the radius.
RADIUS_TOL = 0.01
# A velocity zero crossing spans at most this many steps without motion;
# a longer pause is a rest, after which the new direction starts.
_CROSSING_STEPS = 2


@dataclass(frozen=True)
class ServoSamples:
    """Commanded positions of the X and Y axes at a controller's servo period.

    Attributes
    ----------
    period_s : float
        Servo period: sample ``k`` is at ``k * period_s``. [s]
    xy_m : ndarray, shape (n, 2)
        Commanded X and Y positions. [m]
    markers : ndarray of int, shape (n,)
        How many block markers (user M-codes) the program had run by each sample.
    source : dict
        Where the samples came from (controller, version, configuration), for
        the truth file; JSON-ready.
    """

    period_s: float
    xy_m: np.ndarray
    markers: np.ndarray
    source: dict

    @property
    def t_s(self):
        """Sample times from the first sample. [s]"""
        return np.arange(len(self.xy_m)) * self.period_s


@dataclass(frozen=True)
class SampledBlock:
    """One block as the controller ran it, on the motion's time axis.

    Attributes
    ----------
    index : int
        Block number from 0.
    direction : str
        ``"ccw"`` or ``"cw"``.
    sign : int
        +1 for CCW, -1 for CW.
    start_angle_rad : float
        Position angle at the start, as the controller ran it. [rad]
    angle_rad : float
        Angle travelled. [rad]
    omega_rad_s : float
        Angular speed as run, away from the ramps. [rad/s]
    t_start_s, t_end_s : float
        Start and end of the block's motion. [s]
    analysed_window_s : tuple of float
        Start and end of its analysed whole cycles (between the overshoots). [s]
    ramp_s : float
        Time from the start of motion to 99 % of the cruise speed. [s]
    progress_rad, progress_t_s : ndarray
        The angle travelled (never decreasing) at each servo sample of the
        block, and the sample's time. [rad, s]
    """

    index: int
    direction: str
    sign: int
    start_angle_rad: float
    angle_rad: float
    omega_rad_s: float
    t_start_s: float
    t_end_s: float
    analysed_window_s: tuple
    ramp_s: float
    progress_rad: np.ndarray = field(compare=False, repr=False)
    progress_t_s: np.ndarray = field(compare=False, repr=False)

    @property
    def duration_s(self):
        """Duration of the block's motion, ramps included. [s]"""
        return self.t_end_s - self.t_start_s

    def time_at_progress(self, s):
        """Time at which the block has travelled ``s``. [s]

        Parameters
        ----------
        s : float
            Angle travelled, in ``[0, angle_rad]``. [rad]
        """
        return float(np.interp(s, self.progress_rad, self.progress_t_s))

    def shifted(self, dt_s):
        """The same block ``dt_s`` later. [s]"""
        a, b = self.analysed_window_s
        return replace(
            self,
            t_start_s=self.t_start_s + dt_s,
            t_end_s=self.t_end_s + dt_s,
            analysed_window_s=(a + dt_s, b + dt_s),
            progress_t_s=self.progress_t_s + dt_s,
        )


def _moving(xy):
    """Whether each step between samples moves either axis."""
    step = np.abs(np.diff(xy, axis=0))
    return (step[:, 0] > STEP_EPS_M) | (step[:, 1] > STEP_EPS_M)


def _block(samples, program, plan, span):
    """Measure one block within its samples' span and check it against the program."""
    xy, dt = samples.xy_m, samples.period_s
    lo, hi = span
    moving = np.flatnonzero(_moving(xy[lo:hi]))
    where = f"block {plan.index} ({plan.direction.upper()})"
    if moving.size == 0:
        raise ControllerError(f"{where}: the controller did not move between its markers")
    i0, i1 = lo + moving[0], lo + moving[-1] + 1  # last sample at rest, first at rest again
    cx, cy = program.centre_m
    r = program.radius_m
    rel = xy[i0 : i1 + 1] - (cx, cy)
    radial = np.hypot(rel[:, 0], rel[:, 1]) - r
    worst = float(np.max(np.abs(radial)))
    if worst > RADIUS_TOL * r:
        raise ControllerError(
            f"{where}: the controller's path leaves the circle of {r * 1e3:g} mm by "
            f"{worst * 1e3:.3g} mm: it ran another program"
        )
    phi = np.unwrap(np.arctan2(rel[:, 1], rel[:, 0]))
    progress = plan.sign * (phi - phi[0])
    block_angle = program.at_feed(plan.feed).block_angle_rad
    start_off = math.remainder(phi[0] - plan.start_angle_rad, 2 * math.pi)
    if abs(start_off) > ANGLE_TOL_RAD or abs(progress[-1] - block_angle) > ANGLE_TOL_RAD:
        raise ControllerError(
            f"{where}: the controller ran {math.degrees(progress[-1]):.2f} deg from "
            f"{math.degrees(phi[0]):.2f} deg, the program {math.degrees(block_angle):.2f} deg "
            f"from {math.degrees(plan.start_angle_rad):.2f} deg: it ran another program"
        )
    t = (i0 + np.arange(len(phi))) * dt
    rate = np.abs(np.diff(phi)) / dt
    middle = (progress[1:] > 0.25 * block_angle) & (progress[1:] < 0.75 * block_angle)
    omega = float(np.median(rate[middle]))
    cruising = np.flatnonzero(rate >= 0.99 * omega)
    ramp = float(t[cruising[0]] - t[0]) if cruising.size else math.nan
    climb = np.maximum.accumulate(progress)
    overshoot = program.overshoot_rad
    window = tuple(float(np.interp(a, climb, t)) for a in (overshoot, block_angle - overshoot))
    return SampledBlock(
        index=plan.index,
        direction=plan.direction,
        sign=plan.sign,
        start_angle_rad=float(phi[0]),
        angle_rad=float(progress[-1]),
        omega_rad_s=omega,
        t_start_s=float(t[0]),
        t_end_s=float(t[-1]),
        analysed_window_s=window,
        ramp_s=ramp,
        progress_rad=climb,
        progress_t_s=t,
    )


def _reversals(x, dt):
    """Reversal times, directions after them and the first direction of one axis."""
    dx = np.diff(x)
    sign = np.where(dx > STEP_EPS_M, 1, np.where(dx < -STEP_EPS_M, -1, 0))
    steps = np.flatnonzero(sign)
    if steps.size == 0:
        return np.empty(0), np.empty(0, dtype=int), 1
    signs = sign[steps]
    change = np.flatnonzero(signs[1:] != signs[:-1]) + 1
    times = []
    for c in change:
        a, b = steps[c - 1], steps[c]
        if b - a <= _CROSSING_STEPS:  # the velocity crosses zero between step a and step b
            va, vb = dx[a], dx[b]
            times.append((a + 0.5 + (b - a) * va / (va - vb)) * dt)
        else:  # after a rest: the new direction starts at sample b
            times.append(b * dt)
    return np.asarray(times), signs[change].astype(int), int(signs[0])


class SampledMotion:
    """A controller's sampled motion, placed on the simulator's time axis.

    Parameters
    ----------
    samples : ServoSamples
        The commanded positions.
    program : TestProgram
        The program the controller ran.
    spans : sequence of (int, int)
        Per block of the program, in order: the sample indices between which
        it ran (from its markers).
    lead_in_s, lead_out_s : float
        Time on the motion's axis before the first block starts and after the
        last ends; beyond the samples the axes rest where they were. [s]

    Raises
    ------
    ControllerError
        If a block is missing or does not match the program.

    Attributes
    ----------
    blocks : tuple of SampledBlock
        On the motion's time axis.
    centre_m : tuple of float
        Circle centre. [m]
    radius_m : float
        Circle radius. [m]
    duration_s : float
        From the motion's time 0 to the end of the lead-out. [s]
    source : dict
        Where the motion came from (the samples' source with the feeds as run).
    """

    def __init__(self, samples, program, spans, lead_in_s=3.0, lead_out_s=3.0):
        plans = program.blocks()
        if len(spans) != len(plans):
            raise ControllerError(
                f"the controller ran {len(spans)} blocks, the program has {len(plans)}"
            )
        self.samples = samples
        self.program = program
        raw = [_block(samples, program, p, s) for p, s in zip(plans, spans, strict=True)]
        self._raw_blocks = tuple(raw)
        t = samples.t_s
        rest = [(1, 0.0), (2, 0.0)]
        self._splines = tuple(
            make_interp_spline(t, samples.xy_m[:, axis], k=5, bc_type=(rest, rest))
            for axis in (0, 1)
        )
        self._span_s = (0.0, float(t[-1]))
        self._reversals = tuple(_reversals(samples.xy_m[:, a], samples.period_s) for a in (0, 1))
        self.centre_m = tuple(program.centre_m)
        self.radius_m = program.radius_m
        self._place(lead_in_s, lead_out_s)

    def _place(self, lead_in_s, lead_out_s):
        self._offset_s = self._raw_blocks[0].t_start_s - lead_in_s
        self.blocks = tuple(b.shifted(-self._offset_s) for b in self._raw_blocks)
        self.duration_s = self.blocks[-1].t_end_s + lead_out_s

    def placed(self, lead_in_s, lead_out_s):
        """The same motion with another lead-in and lead-out.

        Parameters
        ----------
        lead_in_s, lead_out_s : float
            Time before the first block and after the last. [s]

        Returns
        -------
        SampledMotion
        """
        other = object.__new__(SampledMotion)
        other.__dict__.update(self.__dict__)
        other._place(lead_in_s, lead_out_s)
        return other

    @property
    def source(self):
        """Where the motion came from, and the feeds as run (JSON-ready)."""
        run = self.as_run(self.program)
        return {
            **self.samples.source,
            "feeds_run_mm_per_min": [v * 6e4 for v in run.feeds],
            "ramp_s": [b.ramp_s for b in self.blocks],
        }

    @property
    def ramp_s(self):
        """Mean time from rest to cruise speed over the blocks. [s]"""
        return float(np.mean([b.ramp_s for b in self.blocks]))

    def as_run(self, program):
        """The program at the feeds the controller ran (median over each feed's blocks).

        Parameters
        ----------
        program : TestProgram
            The program it was given.

        Returns
        -------
        TestProgram
        """
        plans = program.blocks()
        feeds = []
        for f in range(program.n_feeds):
            omegas = [b.omega_rad_s for b, p in zip(self.blocks, plans, strict=True) if p.feed == f]
            feeds.append(float(np.median(omegas)) * program.radius_m)
        if program.n_feeds == 1:
            return replace(program, feed_m_per_s=feeds[0])
        return replace(program, feeds_m_per_s=tuple(feeds))

    def axis_path(self, t, axis):
        """Commanded position, velocity and acceleration of one axis.

        Parameters
        ----------
        t : ndarray, shape (n,)
            Times on the motion's axis. [s]
        axis : int
            0 for X, 1 for Y.

        Returns
        -------
        tuple of 3 ndarray
            [m, m/s, m/s^2]
        """
        u = np.asarray(t, dtype=float) + self._offset_s
        lo, hi = self._span_s
        outside = (u < lo) | (u > hi)
        u = np.clip(u, lo, hi)
        spline = self._splines[axis]
        pos, vel, acc = spline(u), spline(u, 1), spline(u, 2)
        vel[outside] = 0.0
        acc[outside] = 0.0
        return pos, vel, acc

    def reversals(self, axis):
        """Times where one axis starts moving in the other direction.

        Parameters
        ----------
        axis : int
            0 for X, 1 for Y.

        Returns
        -------
        times : ndarray
            On the motion's axis. [s]
        directions : ndarray of int
            Direction (+1 or -1) after each reversal.
        initial : int
            Direction of the axis's first motion.
        """
        times, directions, initial = self._reversals[axis]
        return times - self._offset_s, directions, initial

    def analysed_windows(self):
        """Time windows of the analysed whole cycles of each block. [s]"""
        return [b.analysed_window_s for b in self.blocks]
