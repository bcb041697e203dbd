"""Reference straight lines of a straightness trace (ISO 230-1, 3.4.2 and 3.6.7).

A squareness from two straightness traces is the difference of the slopes of
their reference lines. ISO 230-1 allows three lines [1]_ and Chapman (Fig. 1)
notes that their slopes, hence the squareness, can differ [2]_:

- ``"least_squares"``: the line minimising the sum of squared deviations
  (Chapman uses it throughout his paper, and so do the tests' defaults);
- ``"end_point"``: the line through the first and the last reading;
- ``"minimum_zone"``: the mean line of the two parallel lines that enclose
  the trace with the least separation, i.e. the line minimising the largest
  deviation (Chebyshev). Solved as a linear programme with
  :func:`scipy.optimize.linprog` (HiGHS): minimise ``t`` subject to
  ``|r_i - a - b s_i| <= t``. On distinct positions ``{1, s}`` is a Haar
  system, so the line is unique (Chebyshev's equioscillation theorem): three
  readings alternately touch the two enclosing lines.

Separations are measured along the reading (perpendicular to the arm), as the
standard does for straightness, not perpendicular to the fitted line; for the
slopes of a few hundred um/m the two differ by a relative 1e-8.

References
----------
.. [1] ISO 230-1:2012, Test code for machine tools - Part 1: Geometric
   accuracy of machines operating under no-load or quasi-static conditions,
   3.4.2 (reference straight lines) and 3.6.7 (squareness).
.. [2] M. A. V. Chapman, "Calibration of machine squareness", Renishaw white
   paper TE328 (2013), Fig. 1.
"""

import itertools
from dataclasses import dataclass

import numpy as np
from scipy.optimize import linprog

from imu_square.errors import ImuSquareError
from imu_square.validation import check_option

REFERENCE_LINES = ("least_squares", "end_point", "minimum_zone")


@dataclass(frozen=True)
class ReferenceLine:
    """A reference straight line ``r = intercept + slope * s`` of a trace.

    Attributes
    ----------
    method : str
        One of :data:`REFERENCE_LINES`.
    slope : float
        Inclination of the line. [m/m = rad]
    intercept : float
        Reading of the line at position 0. [m]
    zone_m : float
        Largest minus smallest deviation of the trace from the line: the
        straightness deviation about this line (the minimum-zone line gives
        the least). [m]
    """

    method: str
    slope: float
    intercept: float
    zone_m: float


def _checked(position, reading):
    s = np.asarray(position, dtype=float)
    r = np.asarray(reading, dtype=float)
    if s.ndim != 1 or s.shape != r.shape:
        raise ImuSquareError(
            f"position and reading must be 1-D arrays of one length, got shapes "
            f"{s.shape} and {r.shape}"
        )
    if s.size < 2 or not (np.all(np.isfinite(s)) and np.all(np.isfinite(r))):
        raise ImuSquareError(f"a reference line needs >= 2 finite readings, got {s.size}")
    if np.unique(s).size < 2:
        raise ImuSquareError("a reference line needs at least two distinct positions")
    return s, r


def _minimum_zone(s, r):
    # Scale to O(1): HiGHS works to absolute tolerances near 1e-7, and a
    # straightness trace in metres is 1e-6 to 1e-4.
    s0, s_scale = s.mean(), np.ptp(s)
    r0, r_scale = r.mean(), np.ptp(r)
    if r_scale == 0:  # a straight trace along the arm: zero zone, any LP tolerance aside
        return 0.0, float(r[0])
    u, v = (s - s0) / s_scale, (r - r0) / r_scale
    n = u.size
    ones = np.ones(n)
    # variables (a, b, t): v - a - b u <= t and a + b u - v <= t
    a_ub = np.block(
        [
            [-ones[:, None], -u[:, None], -ones[:, None]],
            [ones[:, None], u[:, None], -ones[:, None]],
        ]
    )
    b_ub = np.concatenate([-v, v])
    res = linprog(
        c=[0.0, 0.0, 1.0],
        A_ub=a_ub,
        b_ub=b_ub,
        bounds=[(None, None), (None, None), (0.0, None)],
        method="highs",
    )
    if res.status != 0:  # a bounded feasible LP: cannot happen short of a HiGHS failure
        raise ImuSquareError(f"minimum-zone line: linprog failed: {res.message}")
    a, b, _ = res.x
    # Polish to rounding: the optimal strip is parallel to an edge of the readings'
    # convex hull, and HiGHS places it only to its tolerance (1e-7 of a scaled trace,
    # too coarse when a steep trend dominates the scaling). Try every hull edge.
    for slope_edge in _hull_edge_slopes(u, v):
        d = v - slope_edge * u
        if np.ptp(d) < np.ptp(v - b * u):
            b, a = slope_edge, 0.5 * (d.max() + d.min())
    slope = b * r_scale / s_scale
    return slope, r0 + a * r_scale - slope * s0


def _hull_edge_slopes(u, v):
    """Slopes of the edges of the lower and upper convex hulls of points ``(u, v)``."""
    order = np.lexsort((v, u))
    pts = np.column_stack([u[order], v[order]])
    slopes = []
    for sign in (1.0, -1.0):  # lower hull, then upper hull (monotone chain)
        hull = []
        for p in pts:
            while len(hull) >= 2:
                (x1, y1), (x2, y2) = hull[-2], hull[-1]
                if sign * ((x2 - x1) * (p[1] - y1) - (y2 - y1) * (p[0] - x1)) <= 0:
                    hull.pop()
                else:
                    break
            hull.append(p)
        slopes += [
            (q[1] - p[1]) / (q[0] - p[0]) for p, q in itertools.pairwise(hull) if q[0] > p[0]
        ]
    return slopes


def reference_line(position, reading, method="least_squares"):
    """Fit a reference straight line to a straightness trace.

    Parameters
    ----------
    position : ndarray, shape (n,)
        Position along the arm, distinct values. [m]
    reading : ndarray, shape (n,)
        Straightness reading at each position. [m]
    method : {"least_squares", "end_point", "minimum_zone"}
        Which reference line (module docstring). ``"end_point"`` joins the
        readings at the smallest and the largest position.

    Returns
    -------
    ReferenceLine

    Raises
    ------
    ImuSquareError
        Unknown method, arrays of different shapes, fewer than two readings
        or two distinct positions, or non-finite values.
    """
    check_option("method", method, REFERENCE_LINES)
    s, r = _checked(position, reading)
    if method == "least_squares":
        design = np.column_stack([np.ones_like(s), s - s.mean()])
        (c0, slope), *_ = np.linalg.lstsq(design, r, rcond=None)
        intercept = c0 - slope * s.mean()
    elif method == "end_point":
        i, j = int(np.argmin(s)), int(np.argmax(s))
        slope = (r[j] - r[i]) / (s[j] - s[i])
        intercept = r[i] - slope * s[i]
    else:
        slope, intercept = _minimum_zone(s, r)
    dev = r - intercept - slope * s
    return ReferenceLine(
        method=method,
        slope=float(slope),
        intercept=float(intercept),
        zone_m=float(dev.max() - dev.min()),
    )
