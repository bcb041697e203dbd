"""Gravity coupling separated from the squareness by a joint fit over feeds.

A table that tilts as it travels (pitch and roll error motions) leaks ``g``
times the tilt into the sensor's x and y. With a tilt linear in position,
``K`` (rad/m), the sensor reads on a circle of radius ``r`` and angular speed
``omega``, for each axis in the position-angle domain (``docs/model.md``)::

    a(phi) = c - A_axis cos(phi - theta)      (x; y with sin)

and, writing each axis's fit as the phasor ``Z = A_axis exp(i theta)``,
exactly for the linear model the simulator states
(``M = I + J - (g r / A) K``)::

    Z = A p + gamma

with ``A = omega^2 r`` the inertial amplitude ``v^2/r``, ``p`` a phasor per
axis that holds the squareness, the sensor's rotation and gains, and
``gamma`` a phasor per axis that holds the gravity coupling, ``-g r`` times a
row of the tilt gradient seen through the sensor. The inertial term scales
with ``A`` and the gravity term does not depend on the feed, so the fits at
two or more feeds of the same circle separate them: a weighted straight-line
fit of ``Z`` on ``A`` per axis gives ``p`` (slope) and ``gamma`` (intercept).
Each feed's phase is then ``arg(A p + gamma)``, the ``atan(g k r / A)`` per
axis of :mod:`imu_square.simulate.truth`, exact and not only to first order.

Reported:

- ``squareness_rad = arg(p_y) - arg(p_x)``: ``theta_y - theta_x`` freed of
  gravity coupling (the paper's Eq. 4 measurand on a level table);
- ``gravity_coupling_rad_per_m``: ``kappa = (Im(gamma_y / p_y) - Im(gamma_x /
  p_x)) / (g r)``, the tilt gradient's symmetric shear in the sensor's axes,
  ``cos(2 eps) (k_xy + k_yx) + sin(2 eps) (k_yy - k_xx)``, which adds
  ``(g r / A) kappa`` to a one-feed ``theta_y - theta_x``;
- uncertainties by first-order propagation of each feed's type A
  uncertainty: to first order ``squareness = sum_i c_i D_i`` over the feeds'
  plain results ``D_i`` with ``c_i = w_i A_i (A_i - Abar) / sum_j w_j (A_j -
  Abar)^2`` (two feeds: ``c = (A1, -A2) / (A1 - A2)``), weights ``w_i = 1 /
  (A_i u_i)^2``, and ``kappa g r = sum_i e_i D_i`` with ``e_i = w_i A_i / W -
  Abar c_i``;
- the cost of the separation: that uncertainty over the uncertainty of the
  plain results' weighted mean (which gravity coupling biases).

The feeds' type A uncertainties are independent (different cycles), so the
variances add. ``A_i`` is ``omega_i^2 r`` with the measured ``omega_i``: only
the ratios of the ``A_i`` enter the squareness, and the sensor's gain
cancels in ``gamma / p``.
"""

import math
from dataclasses import dataclass

import numpy as np

from imu_square.errors import AnalysisError
from imu_square.pipeline.feeds import split_feeds
from imu_square.pipeline.squareness import analyze
from imu_square.program.spec import MIN_FEED_RATIO
from imu_square.units import MM, MM_PER_MIN, SQUARENESS_UNIT, URAD, G

# Two programs run the same circle when radius and centre agree to this. [m]
SAME_CIRCLE_M = 1e-6


@dataclass(frozen=True)
class FeedResult:
    """One feed's plain analysis, as the joint fit uses it.

    Attributes
    ----------
    source : str
        Where the feed's data came from (a path), for messages and JSON.
    program : TestProgram
        The feed's one-feed program.
    result : RunResult
        Its plain analysis (gravity coupling included).
    """

    source: str
    program: object
    result: object

    @property
    def feed_mm_per_min(self):
        """The programmed feed. [mm/min]"""
        return self.program.feed_m_per_s / MM_PER_MIN

    @property
    def amplitude_m_s2(self):
        """The inertial amplitude ``omega^2 r`` at the measured ``omega``. [m/s^2]"""
        return self.result.omega_rad_s**2 * self.program.radius_m


@dataclass(frozen=True)
class GravitySeparation:
    """Squareness and gravity coupling from a joint fit over feeds.

    Attributes
    ----------
    squareness_rad : float
        ``theta_y - theta_x`` freed of gravity coupling. [rad]
    u_squareness_rad : float
        Its standard uncertainty (type A, propagated from each feed's). [rad]
    u_squareness_dof : float
        Effective degrees of freedom (Welch-Satterthwaite).
    crb_rad : float
        The closed-form prediction: each feed's Cramér-Rao bound propagated
        the same way. [rad]
    gravity_coupling_rad_per_m : float
        ``kappa``, the gravity coupling that shows in ``theta_y - theta_x``. [rad/m]
    u_gravity_coupling_rad_per_m : float
        Its standard uncertainty. [rad/m]
    u_squareness_plain_rad : float
        Uncertainty of the weighted mean of the feeds' plain results: what
        ignoring gravity would have claimed. [rad]
    separation_cost : float
        ``u_squareness_rad / u_squareness_plain_rad``.
    feeds : tuple of FeedResult
        The feeds, in the order given.
    weights : tuple of float
        ``c_i``: the squareness is to first order ``sum c_i D_i``.
    gravity_phase_rad : tuple of float
        What gravity coupling added to each feed's plain result. [rad]
    residual_chi2 : float
        With three feeds or more, the sum of squared normalised residuals of
        the plain results from the fitted model (``n_feeds - 2`` degrees of
        freedom); NaN with two.
    """

    squareness_rad: float
    u_squareness_rad: float
    u_squareness_dof: float
    crb_rad: float
    gravity_coupling_rad_per_m: float
    u_gravity_coupling_rad_per_m: float
    u_squareness_plain_rad: float
    separation_cost: float
    feeds: tuple
    weights: tuple
    gravity_phase_rad: tuple
    residual_chi2: float

    def summary(self):
        """Human-readable lines about the separation.

        Returns
        -------
        str
        """
        unit = SQUARENESS_UNIT
        lines = [
            f"squareness {self.squareness_rad / URAD:.1f} ± {self.u_squareness_rad / URAD:.1f} "
            f"{unit} freed of gravity coupling (theta_y - theta_x, type A, k=1; noise floor "
            f"{self.crb_rad / URAD:.1f}; {len(self.feeds)} feeds)",
            f"  gravity coupling {self.gravity_coupling_rad_per_m / URAD:.4g} ± "
            f"{self.u_gravity_coupling_rad_per_m / URAD:.2g} µrad/m of tilt per metre of travel",
            f"  separation costs x{self.separation_cost:.2f} in uncertainty (plain weighted "
            f"mean ± {self.u_squareness_plain_rad / URAD:.1f} {unit})",
        ]
        for f, g in zip(self.feeds, self.gravity_phase_rad, strict=True):
            r = f.result
            lines.append(
                f"  {f.feed_mm_per_min:g} mm/min ({f.amplitude_m_s2:.3g} m/s²): plain "
                f"{r.squareness_rad / URAD:.1f} ± {r.u_squareness_rad / URAD:.1f} {unit}, "
                f"of which gravity {g / URAD:.1f}"
            )
        if math.isfinite(self.residual_chi2):
            lines.append(
                f"  model check: chi² {self.residual_chi2:.1f} on {len(self.feeds) - 2} "
                "degrees of freedom"
            )
        return "\n".join(lines)

    def to_json_dict(self):
        """The separation as JSON-ready scalars; angles in µrad.

        Returns
        -------
        dict
            ``squareness_urad`` is ``theta_y - theta_x`` freed of gravity
            coupling; ``feeds`` holds each feed's plain result (the keys of
            ``analyze --json``) with its feed, amplitude, weight and gravity phase.
        """
        feeds = []
        for f, c, g in zip(self.feeds, self.weights, self.gravity_phase_rad, strict=True):
            feeds.append(
                {
                    "recording": f.source,
                    "feed_mm_per_min": f.feed_mm_per_min,
                    "amplitude_m_s2": f.amplitude_m_s2,
                    "weight": c,
                    "gravity_phase_urad": g / URAD,
                    **f.result.to_json_dict(),
                }
            )
        return {
            "squareness_urad": self.squareness_rad / URAD,
            "u_squareness_urad": self.u_squareness_rad / URAD,
            "u_squareness_dof": self.u_squareness_dof,
            "crb_urad": self.crb_rad / URAD,
            "gravity_coupling_urad_per_m": self.gravity_coupling_rad_per_m / URAD,
            "u_gravity_coupling_urad_per_m": self.u_gravity_coupling_rad_per_m / URAD,
            "u_squareness_plain_urad": self.u_squareness_plain_rad / URAD,
            "separation_cost": self.separation_cost,
            "residual_chi2": None if math.isnan(self.residual_chi2) else self.residual_chi2,
            "feeds": feeds,
        }


def _check_feeds(planned):
    """Refuse fewer than two feeds, or feeds of different circles.

    ``planned`` is ``(source, one-feed program)`` of each feed: known before any
    analysis, so that a wrong input is refused before the work.
    """
    if len(planned) < 2:
        got = ", ".join(f"{p.feed_m_per_s / MM_PER_MIN:g}" for _, p in planned) or "none"
        raise AnalysisError(
            "separating gravity coupling needs the same circle at two feeds or more: a recording "
            f"of a program with feeds_mm_per_min, or one recording per feed; got {got} mm/min"
        )
    source0, first = planned[0]
    for source, p in planned[1:]:
        if (
            abs(p.radius_m - first.radius_m) > SAME_CIRCLE_M
            or math.dist(p.centre_m, first.centre_m) > SAME_CIRCLE_M
            or p.plane != first.plane
        ):
            raise AnalysisError(
                f"the feeds must run the same circle: {source0} has r = "
                f"{first.radius_m / MM:g} mm at centre {[c / MM for c in first.centre_m]} mm, "
                f"{source} r = {p.radius_m / MM:g} mm at {[c / MM for c in p.centre_m]} mm"
            )


def _phasors(feeds):
    """Per-axis phasors ``A_axis exp(i theta)`` of each feed, shape (n_feeds, 2)."""
    return np.array(
        [
            [
                f.result.amp_x_m_s2 * np.exp(1j * f.result.theta_x_rad),
                f.result.amp_y_m_s2 * np.exp(1j * f.result.theta_y_rad),
            ]
            for f in feeds
        ]
    )


def separate_gravity(feeds):
    """Fit the feeds' plain results jointly: squareness and gravity coupling.

    Parameters
    ----------
    feeds : sequence of FeedResult
        Plain results of the same circle at two feeds or more.

    Returns
    -------
    GravitySeparation

    Raises
    ------
    AnalysisError
        Fewer than two feeds; feeds of different circles; amplitudes too
        close to separate anything.
    """
    feeds = tuple(feeds)
    _check_feeds([(f.source, f.program) for f in feeds])
    amp = np.array([f.amplitude_m_s2 for f in feeds])
    if amp.max() < MIN_FEED_RATIO**2 * amp.min():
        raise AnalysisError(
            f"the feeds' v^2/r ({', '.join(f'{a:.4g}' for a in amp)} m/s^2) must differ by at "
            f"least {MIN_FEED_RATIO**2 - 1:.0%} to separate what does not scale with the feed"
        )
    u = np.array([f.result.u_squareness_rad for f in feeds])
    if not np.all(np.isfinite(u) & (u > 0)):
        raise AnalysisError(f"each feed needs a type A uncertainty, got {u / URAD} µrad")
    plain = np.array([f.result.squareness_rad for f in feeds])
    dof = np.array([f.result.u_squareness_dof for f in feeds], dtype=float)
    crb = np.array([f.result.crb_rad for f in feeds])
    w = 1.0 / (amp * u) ** 2
    big_w = w.sum()
    a_bar = float(np.sum(w * amp) / big_w)
    sxx = float(np.sum(w * (amp - a_bar) ** 2))

    z = _phasors(feeds)
    z_bar = np.sum(w[:, None] * z, axis=0) / big_w
    p = np.sum((w * (amp - a_bar))[:, None] * (z - z_bar), axis=0) / sxx
    gamma = z_bar - p * a_bar
    squareness = math.remainder(float(np.angle(p[1]) - np.angle(p[0])), 2 * math.pi)
    r = feeds[0].program.radius_m
    kappa = float(np.imag(gamma[1] / p[1]) - np.imag(gamma[0] / p[0])) / (G * r)
    model = amp[:, None] * p + gamma
    gravity = [
        math.remainder(float(np.angle(m[1]) - np.angle(m[0])) - squareness, 2 * math.pi)
        for m in model
    ]

    c = w * amp * (amp - a_bar) / sxx
    e = (w * amp / big_w - a_bar * c) / (G * r)
    u_sq = float(np.sqrt(np.sum((c * u) ** 2)))
    contrib = (c * u) ** 4 / np.where(dof > 0, dof, np.nan)
    nu = float(u_sq**4 / np.nansum(contrib)) if np.any(np.isfinite(contrib)) else math.nan
    u_plain = float(1.0 / np.sqrt(np.sum(1.0 / u**2)))
    chi2 = math.nan
    if len(feeds) > 2:
        fitted = squareness + np.array(gravity)
        chi2 = float(np.sum(((plain - fitted) / u) ** 2))
    return GravitySeparation(
        squareness_rad=squareness,
        u_squareness_rad=u_sq,
        u_squareness_dof=nu,
        crb_rad=float(np.sqrt(np.sum((c * crb) ** 2))),
        gravity_coupling_rad_per_m=kappa,
        u_gravity_coupling_rad_per_m=float(np.sqrt(np.sum((e * u) ** 2))),
        u_squareness_plain_rad=u_plain,
        separation_cost=u_sq / u_plain,
        feeds=feeds,
        weights=tuple(float(v) for v in c),
        gravity_phase_rad=tuple(gravity),
        residual_chi2=chi2,
    )


def analyze_feeds(sources, options=None, program=None):
    """Each feed's plain result from recordings of one circle at several feeds.

    Parameters
    ----------
    sources : sequence of tuple (str, Recording)
        ``(name, recording)``: one recording of a multi-feed program, or one
        recording per feed (loggers that write one file per feed), or a mix.
    options : AnalysisOptions, optional
        Analysis options for every feed.
    program : TestProgram, optional
        Overrides every recording's program.

    Returns
    -------
    list of FeedResult
        In the order of the sources, then of each program's feeds.

    Raises
    ------
    AnalysisError
        Fewer than two feeds or feeds of different circles (before any
        analysis); from the split or the analysis of a feed, with a message
        that names the source and the feed.
    """
    split = []
    for name, recording in sources:
        try:
            split.append((name, split_feeds(recording, program, options)))
        except AnalysisError as exc:
            raise AnalysisError(f"{name}: {exc}") from None
    _check_feeds([(name, part.program) for name, parts in split for part in parts])
    out = []
    for name, parts in split:
        for part in parts:
            try:
                result = analyze(part.recording, options, program=part.program)
            except AnalysisError as exc:
                where = f" at {part.feed_mm_per_min:g} mm/min" if len(parts) > 1 else ""
                raise AnalysisError(f"{name}{where}: {exc}") from None
            out.append(FeedResult(str(name), part.program, result))
    return out
