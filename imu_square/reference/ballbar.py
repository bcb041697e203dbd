"""Ballbar circular test (ISO 230-4) on a geometric error map, and its squareness.

A telescoping ballbar joins a pivot on the table, set by the machine at the
commanded centre ``c``, to the tool, which runs a circle of radius ``R``
around it. With the error map ``d`` (commanded ``p`` reaches ``p + d(p)``) the
bar reads

    L(phi) = | p(phi) + d(p(phi)) - c - d(c) |,   p = c + R (cos phi, sin phi).

To first order the radial deviation ``dr = L - R`` is ``u . (d(p) - d(c))``
with ``u = (cos phi, sin phi)``. A pure squareness ``alpha`` (``dx = -alpha
y``, Chapman's convention) gives ``dr = -alpha R sin(phi) cos(phi) = -(alpha R
/ 2) sin(2 phi)``: the bar shortens on the 45 deg diagonal and lengthens on
the 135 deg one. A scale mismatch gives a ``cos(2 phi)`` term, a centre
offset ``cos(phi)`` and ``sin(phi)`` terms and a radius change a constant.
The squareness is read from the least-squares ``sin(2 phi)`` coefficient
``b2`` as ``alpha = -2 b2 / R``, as Renishaw's ballbar software does after
removing the centre offset [1]_ [2]_.

Backlash (lost motion ``b`` per axis: the axis lags the command by ``b / 2``
in its direction of motion) adds ``s (b_x / 2) cos(phi) sign(sin phi) - s (b_y
/ 2) sin(phi) sign(cos phi)`` to ``dr`` (``s = +1`` CCW, ``-1`` CW), whose
``sin(2 phi)`` part biases each direction's squareness by ``-s 8 (b_x - b_y) /
(3 pi R)``. The bias flips with the direction, so the mean of the CCW and CW
runs, which is what the test reports, is free of it.

Partial arcs. Renishaw's software estimates squareness from arcs down to
220 deg [2]_, so that a ballbar can test a machine whose axes differ in length:
a 220 deg arc symmetric about +Y spans ``2 R`` by ``R (1 + sin 20 deg)``, an
aspect ratio of 1.49, "approaching 1.5 : 1". The same five-term least-squares
fit is made over the arc's samples. Over a full circle the trace's higher
harmonics are orthogonal to the five terms; over an arc they are not. A bow's
quadratic terms give the trace third harmonics: an X bow's (``sin phi cos^2
phi``) are even about the arc's axis +Y, orthogonal to ``sin 2 phi``, while a
Y bow's (``cos phi sin^2 phi``) are odd like it and shift the arc's result.

Non-quadratic maps. The ``sin(2 phi)`` coefficient also takes in the third
harmonic of the path: with ``dx`` and ``dy`` expanded in harmonics of ``phi``,
``b2 = (b1 + c1) / 2 + (b3 - c3) / 2``, where ``b_k`` is the ``sin(k phi)``
coefficient of ``dx`` and ``c_k`` the ``cos(k phi)`` coefficient of ``dy``. An
accelerometer's phases see only ``b1 + c1``. For an X form with a quartic
part (Chapman's machine 7, :mod:`imu_square.simulate.geometry`; ``f3`` its
third derivative at the centre) the ballbar therefore reads ``f3 R^2 / 6``
(with yaw) or ``-f3 R^2 / 12`` (without) away from the local squareness; a
symmetric set of circles averages it out.

References
----------
.. [1] ISO 230-4:2005, Test code for machine tools - Part 4: Circular tests
   for numerically controlled machine tools.
.. [2] M. A. V. Chapman, "Calibration of machine squareness", Renishaw white
   paper TE328 (2013), Method 4.
"""

from dataclasses import dataclass

import numpy as np

from imu_square.errors import ImuSquareError


@dataclass(frozen=True)
class BallbarResult:
    """A simulated ballbar test and its least-squares analysis.

    Attributes
    ----------
    machine_squareness_rad : float
        Mean of the CCW and CW squareness, Chapman's sign. [rad]
    machine_squareness_ccw_rad, machine_squareness_cw_rad : float
        Squareness from each direction alone. [rad]
    arc_deg : float
        Angle of the arc run: 360 for a full circle. [deg]
    centre_offset_m : tuple of float
        Fitted offset of the circle centre (x, y), mean of both directions. [m]
    radius_change_m : float
        Fitted change of the mean radius. [m]
    scale_mismatch : float
        ``s_x - s_y`` from the ``cos(2 phi)`` term. [m/m]
    phi_rad : ndarray, shape (n,)
        Position angles of the samples. [rad]
    deviation_ccw_m, deviation_cw_m : ndarray, shape (n,)
        Radial deviation ``L - R`` of each run, at ``phi_rad``. [m]
    residual_rms_m : float
        RMS of what the five-term model leaves, both runs. [m]
    """

    machine_squareness_rad: float
    machine_squareness_ccw_rad: float
    machine_squareness_cw_rad: float
    arc_deg: float
    centre_offset_m: tuple
    radius_change_m: float
    scale_mismatch: float
    phi_rad: np.ndarray
    deviation_ccw_m: np.ndarray
    deviation_cw_m: np.ndarray
    residual_rms_m: float


def _trace(deviation, centre, radius, phi, direction, backlash):
    cx, cy = centre
    x = cx + radius * np.cos(phi)
    y = cy + radius * np.sin(phi)
    # axis velocity signs along the run: d/dphi of (cos, sin) times direction
    vx = np.sign(-direction * np.sin(phi))
    vy = np.sign(direction * np.cos(phi))
    xa = x - 0.5 * backlash[0] * vx
    ya = y - 0.5 * backlash[1] * vy
    dx, dy = deviation(xa, ya)
    dcx, dcy = deviation(np.asarray(cx, dtype=float), np.asarray(cy, dtype=float))
    return np.hypot(xa + dx - cx - dcx, ya + dy - cy - dcy) - radius


def _design(phi):
    return np.column_stack(
        [np.ones_like(phi), np.cos(phi), np.sin(phi), np.cos(2 * phi), np.sin(2 * phi)]
    )


def ballbar_squareness(
    deviation, centre, radius, n=3600, backlash=(0.0, 0.0), arc_deg=360.0, arc_start_deg=None
):
    """Simulate a ballbar circle or arc (CCW and CW) and fit squareness.

    Parameters
    ----------
    deviation : callable
        ``deviation(x, y) -> (dx, dy)``: the machine's position error at
        commanded ``(x, y)``, arrays in and out. [m]
    centre : tuple of float
        Commanded circle centre, where the table pivot is set. [m]
    radius : float
        Ballbar length. [m]
    n : int
        Samples over the circle or arc, equispaced in angle (an arc's two
        ends included).
    backlash : tuple of float
        Lost motion of the X and Y axes. [m]
    arc_deg : float
        Angle of the arc, 220 to 360 (Renishaw's software analyses arcs down
        to 220 deg). [deg]
    arc_start_deg : float, optional
        Position angle where the arc starts; by default 0 for a full circle
        and ``90 - arc_deg / 2`` for an arc (symmetric about +Y: -20 to 200
        deg for 220 deg). [deg]

    Returns
    -------
    BallbarResult

    Raises
    ------
    ImuSquareError
        If ``radius`` is not positive, ``n`` is below 16 or ``arc_deg`` is
        outside [220, 360].
    """
    if not radius > 0:
        raise ImuSquareError(f"ballbar radius must be > 0 m, got {radius!r}")
    if not (isinstance(n, int | np.integer) and n >= 16):
        raise ImuSquareError(f"ballbar samples n must be an integer >= 16, got {n!r}")
    if not 220.0 <= arc_deg <= 360.0:
        raise ImuSquareError(f"ballbar arc_deg must be in [220, 360], got {arc_deg!r}")
    if arc_deg == 360.0:
        start = 0.0 if arc_start_deg is None else arc_start_deg
        phi = np.radians(start) + 2 * np.pi * np.arange(n) / n
    else:
        start = 90.0 - arc_deg / 2 if arc_start_deg is None else arc_start_deg
        phi = np.radians(start + arc_deg * np.arange(n) / (n - 1))
    design = _design(phi)
    traces, coefs = [], []
    for direction in (1, -1):
        dr = _trace(deviation, centre, radius, phi, direction, backlash)
        coef, *_ = np.linalg.lstsq(design, dr, rcond=None)
        traces.append(dr)
        coefs.append(coef)
    ccw, cw = (-2 * c[4] / radius for c in coefs)
    mean = 0.5 * (coefs[0] + coefs[1])
    resid = np.concatenate([t - design @ c for t, c in zip(traces, coefs, strict=True)])
    return BallbarResult(
        machine_squareness_rad=float(0.5 * (ccw + cw)),
        machine_squareness_ccw_rad=float(ccw),
        machine_squareness_cw_rad=float(cw),
        arc_deg=float(arc_deg),
        centre_offset_m=(float(mean[1]), float(mean[2])),
        radius_change_m=float(mean[0]),
        scale_mismatch=float(2 * mean[3] / radius),
        phi_rad=phi,
        deviation_ccw_m=traces[0],
        deviation_cw_m=traces[1],
        residual_rms_m=float(np.sqrt(np.mean(resid**2))),
    )
