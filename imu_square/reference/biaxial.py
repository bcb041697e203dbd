"""Bi-axial straightness squareness tests in "L", "T" and "+" shapes (ISO 230-1).

A square (mechanical, or a laser straightness reflector with an optical
square) sets two perpendicular reference arms on the table. Each machine axis
in turn moves along one arm while an indicator reads its straightness, the
deviation perpendicular to the arm, in the instrument's own frame [1]_.

Instrument frame. Arm ``k`` has unit direction ``a_k`` and normal ``n_k =
R(+90 deg) a_k``; at commanded point ``p`` the reading is ``n_k . (p + d(p) -
o_k)`` against the arm position ``s = a_k . (p - o_k)``, with ``o_k`` the arm's
origin. The slope ``m_k`` of the reading's reference line (least squares by
default, as in Chapman's paper; end-point or minimum-zone on request, see
:mod:`imu_square.reference.reference_line`) is the angle by which the machine's motion
along that arm is turned counter-clockwise from the arm; a line's turn does
not depend on which way along it ``a_k`` points. Hence, with ``m_X`` and
``m_Y`` the slopes of the arms along X and Y,

    squareness = m_Y - m_X

(the angle between +X and +Y motion is ``90 deg + m_Y - m_X``; Chapman's sign:
positive over 90 deg). A rotation ``eps`` of the whole instrument subtracts
``eps`` from both slopes and cancels.

Shapes and orientations on the tested rectangle ``[x_min, x_max] x [y_min,
y_max]`` (orientation: the instrument turned clockwise, seen from above, by
that angle from its 0 deg set-up):

====== ============================ =====================================
shape  0 / 90 / 180 / 270 deg       arms
====== ============================ =====================================
L      corner at lower-left /        both arms along the two edges that
       upper-left / upper-right /    meet at the corner
       lower-right
T      bar along the top / right /   the bar along that edge, the stem
       bottom / left edge            through the middle of the other axis
\\+     any                           both arms through the middle
====== ============================ =====================================

Chapman [1]_: with yaw-induced distortion, L and T results vary with
orientation while "+" agrees with ballbar and diagonal; averaging L or T
results from opposite corners or sides agrees with them too.

With associated yaw on both axes (``dx = -y (alpha + f'(x)) + g(y)``, ``dy =
f(x) - x g'(y)`` for symmetric forms ``f``, ``g``) the result is ``alpha +
f'(x_Y) + g'(y_X)``: the two axes' yaw where the arms run, at ``x_Y`` (the Y
arm's X position) and ``y_X`` (the X arm's Y position). That is how machine 7
with yaw reads 95 um/m in T at 0 deg (``g'`` at the top edge, 80 um/m) while
"+" (both arms through the middle, where ``f' = g' = 0``) reads 15.

The three reference lines give the same slope for a symmetric form; they
differ when the form is not, e.g. ``dy = c x^3`` over ``[-h, h]``: least
squares ``0.6 c h^2``, minimum zone ``0.75 c h^2`` (``x^3 - 3x/4`` is a
Chebyshev polynomial: it equioscillates), end point ``c h^2``.

References
----------
.. [1] M. A. V. Chapman, "Calibration of machine squareness", Renishaw white
   paper TE328 (2013), Methods 1-3 and machine simulations.
"""

from dataclasses import dataclass

import numpy as np

from imu_square.errors import ImuSquareError
from imu_square.reference.reference_line import REFERENCE_LINES
from imu_square.reference.reference_line import reference_line as reference_line_fit
from imu_square.validation import check_option

SHAPES = ("L", "T", "+")
ORIENTATIONS_DEG = (0, 90, 180, 270)


@dataclass(frozen=True)
class BiaxialResult:
    """A bi-axial straightness squareness test.

    Attributes
    ----------
    machine_squareness_rad : float
        ``m_Y - m_X``, Chapman's sign. [rad]
    shape : str
        ``"L"``, ``"T"`` or ``"+"``.
    orientation_deg : int
        Instrument orientation.
    x_line_y_m : float
        Y position of the arm along which X moves. [m]
    y_line_x_m : float
        X position of the arm along which Y moves. [m]
    slope_x_rad, slope_y_rad : float
        Slopes ``m_X``, ``m_Y`` of the reference lines of the two straightness
        traces in the instrument frame. [rad]
    reference_line : str
        The reference line used for both traces (one of ``REFERENCE_LINES``).
    straightness_x_m, straightness_y_m : float
        Straightness deviation of each trace about its reference line
        (largest minus smallest deviation). [m]
    position_x_m, reading_x_m, position_y_m, reading_y_m : ndarray
        The two traces: arm position and straightness reading. [m]
    """

    machine_squareness_rad: float
    shape: str
    orientation_deg: int
    x_line_y_m: float
    y_line_x_m: float
    slope_x_rad: float
    slope_y_rad: float
    reference_line: str
    straightness_x_m: float
    straightness_y_m: float
    position_x_m: np.ndarray
    reading_x_m: np.ndarray
    position_y_m: np.ndarray
    reading_y_m: np.ndarray


def _layout(shape, orientation, x_range, y_range):
    """Arm lines and directions: ((y of X arm, +-1 along X), (x of Y arm, +-1 along Y))."""
    (x0, x1), (y0, y1) = x_range, y_range
    xm, ym = 0.5 * (x0 + x1), 0.5 * (y0 + y1)
    if shape == "+":
        return (ym, 1), (xm, 1)
    if shape == "L":
        # corner and the arms' directions away from it
        corner = {
            0: (x0, y0, 1, 1),
            90: (x0, y1, 1, -1),
            180: (x1, y1, -1, -1),
            270: (x1, y0, -1, 1),
        }
        cx, cy, sx, sy = corner[orientation]
        return (cy, sx), (cx, sy)
    bar = {0: ("X", y1, 1), 90: ("Y", x1, -1), 180: ("X", y0, -1), 270: ("Y", x0, 1)}
    axis, at, sense = bar[orientation]
    if axis == "X":
        return (at, sense), (xm, -sense)
    return (ym, sense), (at, sense)


def _rot90(v):
    return np.array([-v[1], v[0]])


def biaxial_squareness(
    deviation,
    shape,
    orientation_deg=0,
    x_range=(-0.4, 0.4),
    y_range=(-0.4, 0.4),
    n=81,
    instrument_rotation_rad=0.0,
    reference_line="least_squares",
):
    """Simulate an L, T or + bi-axial straightness test and compute squareness.

    Parameters
    ----------
    deviation : callable
        ``deviation(x, y) -> (dx, dy)``: position error at commanded
        ``(x, y)``, arrays in and out. [m]
    shape : {"L", "T", "+"}
        Test configuration.
    orientation_deg : {0, 90, 180, 270}
        Instrument turned clockwise by this angle (see the module table).
    x_range, y_range : tuple of float
        ``(min, max)`` of the travel tested on each axis. [m]
    n : int
        Readings per arm, equispaced, ends included.
    instrument_rotation_rad : float
        Misalignment of the whole instrument on the table (counter-clockwise);
        it cancels from the result. [rad]
    reference_line : {"least_squares", "end_point", "minimum_zone"}
        Reference line fitted to both traces (ISO 230-1 allows each; use the
        same for both, as Chapman advises).

    Returns
    -------
    BiaxialResult

    Raises
    ------
    ImuSquareError
        Unknown shape, orientation or reference line, or fewer than 3
        readings per arm.
    """
    check_option("shape", shape, SHAPES)
    check_option("orientation_deg", orientation_deg, ORIENTATIONS_DEG)
    if not (isinstance(n, int | np.integer) and n >= 3):
        raise ImuSquareError(f"readings per arm n must be an integer >= 3, got {n!r}")
    check_option("reference_line", reference_line, REFERENCE_LINES)
    (x_line, sx), (y_line, sy) = _layout(shape, orientation_deg, x_range, y_range)
    c, s_ = np.cos(instrument_rotation_rad), np.sin(instrument_rotation_rad)
    rot = np.array([[c, -s_], [s_, c]])

    traces = []
    for axis, line, sense, rng in (("X", x_line, sx, x_range), ("Y", y_line, sy, y_range)):
        along = np.linspace(rng[0], rng[1], n)
        if axis == "X":
            pts = np.column_stack([along, np.full(n, line)])
            a = np.array([float(sense), 0.0])
        else:
            pts = np.column_stack([np.full(n, line), along])
            a = np.array([0.0, float(sense)])
        a = rot @ a
        normal = _rot90(a)
        origin = pts[0] if sense > 0 else pts[-1]
        dx, dy = deviation(pts[:, 0], pts[:, 1])
        actual = pts + np.column_stack([dx, dy])
        position = (pts - origin) @ a
        reading = (actual - origin) @ normal
        traces.append((position, reading, reference_line_fit(position, reading, reference_line)))
    (px, rx, lx), (py, ry, ly) = traces
    mx, my = lx.slope, ly.slope
    return BiaxialResult(
        machine_squareness_rad=my - mx,
        shape=shape,
        orientation_deg=orientation_deg,
        x_line_y_m=float(x_line),
        y_line_x_m=float(y_line),
        slope_x_rad=mx,
        slope_y_rad=my,
        reference_line=reference_line,
        straightness_x_m=lx.zone_m,
        straightness_y_m=ly.zone_m,
        position_x_m=px,
        reading_x_m=rx,
        position_y_m=py,
        reading_y_m=ry,
    )
