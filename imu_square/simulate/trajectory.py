"""The commanded path in time: blocks with feed ramps, dwells, idle lead-in/out.

Each block travels ``Theta = block_angle`` at the programmed angular speed
``omega = v / r``. The feed rises from 0 to ``v`` over ``ramp_s`` at the start
and falls mirror-symmetrically at the end, so the block's motion lasts
``Theta / omega + ramp_s`` and its middle maps exactly to ``Theta / 2``. The
ramp's velocity fraction ``f(u)``, ``u = t / ramp_s`` in [0, 1], is:

- ``"trapezoid"`` (constant acceleration): ``f = u``;
- ``"s_curve"`` (jerk-limited, constant jerk then constant negative jerk):
  ``f = 2 u^2`` for ``u <= 1/2``, ``1 - 2 (1 - u)^2`` after.

Both integrate to ``1/2`` over the ramp. The progress angle ``s(t)`` and its
first two derivatives are exact piecewise polynomials. Axis reversals (``x``
reverses where ``sin(phi) = 0``, ``y`` where ``cos(phi) = 0``, and at block
starts that move an axis the other way than it last moved) are found on this
timeline analytically.
"""

import math
import warnings
from dataclasses import dataclass

import numpy as np

from imu_square.errors import ConfigError, ImuSquareWarning

RAMP_PROFILES = ("trapezoid", "s_curve")


def ramp_fraction(u, profile):
    """Velocity fraction of a feed ramp and its integral and derivative.

    Parameters
    ----------
    u : ndarray
        Time from the ramp start in units of the ramp duration, in [0, 1].
    profile : str
        One of :data:`RAMP_PROFILES`.

    Returns
    -------
    F, f, df : ndarray
        Integral of the velocity fraction from 0 to ``u``, the fraction
        itself, and its derivative by ``u``.
    """
    u = np.asarray(u, dtype=float)
    if profile == "trapezoid":
        return 0.5 * u * u, u.copy(), np.ones_like(u)
    w = 1.0 - u
    first = u <= 0.5
    F = np.where(first, 2.0 * u**3 / 3.0, u - 0.5 + 2.0 * w**3 / 3.0)
    f = np.where(first, 2.0 * u * u, 1.0 - 2.0 * w * w)
    df = np.where(first, 4.0 * u, 4.0 * w)
    return F, f, df


def _ramp_inverse(q, profile):
    """``u`` in [0, 1] with ``F(u) = q`` (``q`` clamped to ``[0, 1/2]`` against rounding)."""
    q = min(max(q, 0.0), 0.5)
    if profile == "trapezoid":
        return math.sqrt(2.0 * q)
    if q <= 0.0:
        return 0.0
    from scipy.optimize import brentq  # here: the CLI's start-up never needs scipy.optimize

    return brentq(lambda u: float(ramp_fraction(u, profile)[0]) - q, 0.0, 1.0, xtol=1e-15)


@dataclass(frozen=True)
class BlockMotion:
    """One block on the true timeline.

    Attributes
    ----------
    index : int
        Block number from 0.
    direction : str
        ``"ccw"`` or ``"cw"``.
    sign : int
        +1 for CCW, -1 for CW.
    start_angle_rad : float
        Commanded position angle at the start. [rad]
    angle_rad : float
        Angle travelled, overshoots included. [rad]
    overshoot_rad : float
        Overshoot at each end. [rad]
    omega_rad_s : float
        Programmed angular speed. [rad/s]
    ramp_s : float
        Duration of each feed ramp. [s]
    profile : str
        Ramp profile, one of :data:`RAMP_PROFILES`.
    t_start_s : float
        True start of the commanded motion, from the first sample. [s]
    """

    index: int
    direction: str
    sign: int
    start_angle_rad: float
    angle_rad: float
    overshoot_rad: float
    omega_rad_s: float
    ramp_s: float
    profile: str
    t_start_s: float

    @property
    def duration_s(self):
        """Duration of the motion, ramps included. [s]"""
        return self.angle_rad / self.omega_rad_s + self.ramp_s

    @property
    def t_end_s(self):
        """True end of the commanded motion. [s]"""
        return self.t_start_s + self.duration_s

    @property
    def end_angle_rad(self):
        """Commanded position angle at the end. [rad]"""
        return self.start_angle_rad + self.sign * self.angle_rad

    def progress(self, t):
        """Angle travelled since the block start and its time derivatives.

        Parameters
        ----------
        t : ndarray
            Times within ``[t_start_s, t_end_s]``. [s]

        Returns
        -------
        s, ds, dds : ndarray
            Progress angle, angular speed and angular acceleration (all
            non-negative-going, independent of the direction). [rad, rad/s, rad/s^2]
        """
        w, tr, total = self.omega_rad_s, self.ramp_s, self.angle_rad
        tau = np.asarray(t, dtype=float) - self.t_start_s
        s = w * (tau - 0.5 * tr)
        ds = np.full_like(tau, w)
        dds = np.zeros_like(tau)
        if tr > 0:
            head = tau < tr
            F, f, df = ramp_fraction(np.clip(tau[head] / tr, 0.0, 1.0), self.profile)
            s[head], ds[head], dds[head] = w * tr * F, w * f, w * df / tr
            tail = tau > self.duration_s - tr
            F, f, df = ramp_fraction(
                np.clip((self.duration_s - tau[tail]) / tr, 0.0, 1.0), self.profile
            )
            s[tail], ds[tail], dds[tail] = total - w * tr * F, w * f, -w * df / tr
        return s, ds, dds

    def time_at_progress(self, s):
        """True time at which the block has travelled ``s``. [s]

        Parameters
        ----------
        s : float
            Progress angle in ``[0, angle_rad]``; clamped to it against
            rounding. [rad]
        """
        w, tr = self.omega_rad_s, self.ramp_s
        s = min(max(s, 0.0), self.angle_rad)
        half = 0.5 * w * tr
        if s < half:
            return self.t_start_s + tr * _ramp_inverse(s / (w * tr), self.profile)
        if s > self.angle_rad - half:
            u = _ramp_inverse((self.angle_rad - s) / (w * tr), self.profile)
            return self.t_end_s - tr * u
        return self.t_start_s + s / w + 0.5 * tr

    @property
    def analysed_window_s(self):
        """True start and end of the analysed whole cycles (between the overshoots). [s]"""
        return (
            self.time_at_progress(self.overshoot_rad),
            self.time_at_progress(self.angle_rad - self.overshoot_rad),
        )


@dataclass(frozen=True)
class Timeline:
    """All blocks of a program on the true time axis, with idle lead-in and lead-out.

    Attributes
    ----------
    blocks : tuple of BlockMotion
        In execution order.
    centre_m : tuple of float
        Circle centre. [m]
    radius_m : float
        Circle radius. [m]
    duration_s : float
        Total true duration, lead-in and lead-out included. [s]
    """

    blocks: tuple
    centre_m: tuple
    radius_m: float
    duration_s: float

    def angle(self, t):
        """Commanded position angle and its derivatives at true times ``t``.

        Parameters
        ----------
        t : ndarray, shape (n,)
            True times from the first sample, increasing. [s]

        Returns
        -------
        phi, dphi, ddphi : ndarray, shape (n,)
            [rad, rad/s, rad/s^2]
        """
        t = np.asarray(t, dtype=float)
        phi = np.empty_like(t)
        dphi = np.zeros_like(t)
        ddphi = np.zeros_like(t)
        idle_from, idle_angle = 0, self.blocks[0].start_angle_rad
        for b in self.blocks:
            i0, i1 = np.searchsorted(t, (b.t_start_s, b.t_end_s), side="left")
            phi[idle_from:i0] = idle_angle
            s, ds, dds = b.progress(t[i0:i1])
            phi[i0:i1] = b.start_angle_rad + b.sign * s
            dphi[i0:i1] = b.sign * ds
            ddphi[i0:i1] = b.sign * dds
            idle_from, idle_angle = i1, b.end_angle_rad
        phi[idle_from:] = idle_angle
        return phi, dphi, ddphi

    def axis_path(self, t, axis):
        """Commanded position, velocity and acceleration of one axis.

        Parameters
        ----------
        t : ndarray, shape (n,)
            True times, increasing. [s]
        axis : int
            0 for X, 1 for Y.

        Returns
        -------
        tuple of 3 ndarray
            [m, m/s, m/s^2]
        """
        phi, dphi, ddphi = self.angle(t)
        r = self.radius_m
        if axis == 0:
            c, s = np.cos(phi), np.sin(phi)
            return self.centre_m[0] + r * c, -r * s * dphi, -r * (c * dphi**2 + s * ddphi)
        c, s = np.cos(phi), np.sin(phi)
        return self.centre_m[1] + r * s, r * c * dphi, r * (c * ddphi - s * dphi**2)

    def reversals(self, axis):
        """Times where one axis starts moving in the other direction.

        Parameters
        ----------
        axis : int
            0 for X (reverses where ``sin(phi) = 0``), 1 for Y (``cos(phi) = 0``).

        Returns
        -------
        times : ndarray
            True times of the reversals of the commanded axis. [s]
        directions : ndarray of int
            Direction (+1 or -1) of the motion after each reversal.
        initial : int
            Direction of the axis's first motion.
        """
        offset = 0.0 if axis == 0 else 0.5 * math.pi
        times, dirs = [], []
        previous = None
        for b in self.blocks:
            lo = min(b.start_angle_rad, b.end_angle_rad)
            hi = max(b.start_angle_rad, b.end_angle_rad)
            n_lo = math.floor((lo - offset) / math.pi) + 1
            n_hi = math.ceil((hi - offset) / math.pi) - 1
            crossings = offset + math.pi * np.arange(n_lo, n_hi + 1)
            if b.sign < 0:
                crossings = crossings[::-1]
            # A block that starts or ends on a reversal angle must not count
            # it as a crossing inside the block because of rounding.
            tol = 1e-9 * b.angle_rad
            travelled = np.abs(crossings - b.start_angle_rad)
            crossings = crossings[(travelled > tol) & (travelled < b.angle_rad - tol)]
            bounds = [b.start_angle_rad, *crossings, b.end_angle_rad]
            for k in range(len(bounds) - 1):
                mid = 0.5 * (bounds[k] + bounds[k + 1])
                rate = -math.sin(mid) if axis == 0 else math.cos(mid)
                direction = 1 if rate * b.sign > 0 else -1
                if previous is None:
                    initial = direction
                elif direction != previous:
                    s = abs(bounds[k] - b.start_angle_rad)
                    times.append(b.time_at_progress(s))
                    dirs.append(direction)
                previous = direction
        return np.asarray(times, dtype=float), np.asarray(dirs, dtype=int), initial

    def analysed_windows(self):
        """True time windows of the analysed whole cycles of each block. [s]"""
        return [b.analysed_window_s for b in self.blocks]


def _check_ramp(program, ramp_s, name_feed):
    """Refuse a ramp longer than a block, warn when it reaches into the analysed cycles."""
    at = f" at {program.feed_m_per_s * 6e4:g} mm/min" if name_feed else ""
    block_s = program.block_duration_s
    if ramp_s > block_s:
        raise ConfigError(
            f"[machine] ramp_s = {ramp_s!r} s is longer than the block duration "
            f"{block_s:.6g} s{at} (block angle / angular speed): the start and end feed "
            "ramps would overlap; shorten ramp_s or lower the feed"
        )
    ramp_angle = 0.5 * program.omega_rad_s * ramp_s
    if ramp_angle > program.overshoot_rad:
        warnings.warn(
            f"[machine] ramp_s = {ramp_s!r} s covers {math.degrees(ramp_angle):.4g} deg "
            f"of arc{at}, more than the overshoot of {math.degrees(program.overshoot_rad):.4g} "
            "deg: the feed ramps reach into the analysed cycles",
            ImuSquareWarning,
            stacklevel=3,
        )


def build_timeline(program, ramp_s, profile, lead_in_s, lead_out_s):
    """Place the program's blocks on the true time axis.

    Parameters
    ----------
    program : TestProgram
        The test program.
    ramp_s : float
        Duration of each feed ramp. [s]
    profile : str
        One of :data:`RAMP_PROFILES`.
    lead_in_s, lead_out_s : float
        Idle time before the first block and after the last. [s]

    Returns
    -------
    Timeline

    Raises
    ------
    ConfigError
        If ``ramp_s`` exceeds a block's nominal duration (the two ramps of a
        block would overlap), at any of the program's feeds.

    Warns
    -----
    ImuSquareWarning
        If a ramp covers more than the overshoot, so it reaches into the
        analysed whole cycles.
    """
    feeds = [program.at_feed(f) for f in range(program.n_feeds)]
    for feed in feeds:
        _check_ramp(feed, ramp_s, program.n_feeds > 1)
    blocks = []
    t = lead_in_s
    for plan in program.blocks():
        feed = feeds[plan.feed]
        b = BlockMotion(
            index=plan.index,
            direction=plan.direction,
            sign=plan.sign,
            start_angle_rad=plan.start_angle_rad,
            angle_rad=feed.block_angle_rad,
            overshoot_rad=program.overshoot_rad,
            omega_rad_s=feed.omega_rad_s,
            ramp_s=ramp_s,
            profile=profile,
            t_start_s=t,
        )
        blocks.append(b)
        t = b.t_end_s + program.dwell_s
    duration = blocks[-1].t_end_s + lead_out_s
    return Timeline(tuple(blocks), tuple(program.centre_m), program.radius_m, duration)
