"""Laser diagonal tests (ISO 230-6, B5.54): diagonal lengths, E, B and squareness.

The machine moves all its axes together along a face or body diagonal while a
laser interferometer, aligned with the diagonal, reads the displacement at
equispaced targets [1]_ [2]_. With the error map ``d`` (commanded ``p``
reaches ``p + d(p)``), the positioning error at target ``P_i`` of a diagonal
from ``P_0`` with unit direction ``u`` is

    X_i = u . (P_i + d(P_i) - P_0 - d(P_0)) - |P_i - P_0|,

zero at the first target, where the laser is zeroed.

Squareness from the XY face diagonals (Renishaw/Chapman):

    S = D0 (D1 - D2) / (2 X Y),   D0 = sqrt(X^2 + Y^2),

with ``D1`` the diagonal from ``(x_max, y_min)`` to ``(x_min, y_max)`` and
``D2`` the one from ``(x_min, y_min)`` to ``(x_max, y_max)``, the measured
(actual) lengths. A positive squareness (angle between +X and +Y over 90 deg,
``dx = -alpha y``) stretches D1 and compresses D2, so ``S = alpha``. From body
diagonals, D1 and D2 are the means of the pairs that overlap when projected on
the face and ``D0 = sqrt(X^2 + Y^2 + Z^2)``.

References
----------
.. [1] ISO 230-6:2002, Test code for machine tools - Part 6: Determination of
   positioning accuracy on body and face diagonals.
.. [2] Renishaw plc, "Laser diagonal measurements for machine tool performance
   assessment", white paper H-5650-2053-01-A (2016).
.. [3] M. A. V. Chapman, "Calibration of machine squareness", Renishaw white
   paper TE328 (2013), Method 5.
"""

from dataclasses import dataclass

import numpy as np

from imu_square.errors import ImuSquareError
from imu_square.validation import check_option

_AXES = "XYZ"


def face_diagonals(x_range, y_range):
    """The two XY face diagonals, as (start, end) pairs.

    Parameters
    ----------
    x_range, y_range : tuple of float
        ``(min, max)`` of the travel used on each axis. [m]

    Returns
    -------
    list of tuple of ndarray
        ``[(start, end) of D1, (start, end) of D2]``: D1 from ``(x_max,
        y_min)`` to ``(x_min, y_max)``, D2 from ``(x_min, y_min)`` to
        ``(x_max, y_max)``. [m]
    """
    (x0, x1), (y0, y1) = x_range, y_range
    return [
        (np.array([x1, y0]), np.array([x0, y1])),
        (np.array([x0, y0]), np.array([x1, y1])),
    ]


def body_diagonals(x_range, y_range, z_range):
    """The four body diagonals of a box, each starting at a ``z_min`` corner.

    Parameters
    ----------
    x_range, y_range, z_range : tuple of float
        ``(min, max)`` of the travel used on each axis. [m]

    Returns
    -------
    list of tuple of ndarray
        (start, end) pairs; the first two project onto the XY face's D1, the
        last two onto D2 (see :func:`face_diagonals`). [m]
    """
    (x0, x1), (y0, y1), (z0, z1) = x_range, y_range, z_range
    return [
        (np.array([x1, y0, z0]), np.array([x0, y1, z1])),
        (np.array([x0, y1, z0]), np.array([x1, y0, z1])),
        (np.array([x0, y0, z0]), np.array([x1, y1, z1])),
        (np.array([x1, y1, z0]), np.array([x0, y0, z1])),
    ]


def _actual(deviation, points):
    points = np.atleast_2d(np.asarray(points, dtype=float))
    d = deviation(*points.T)
    return points + np.column_stack([np.asarray(c, dtype=float) for c in d])


def diagonal_lengths(deviation, diagonals):
    """Actual lengths of diagonals on a machine with errors.

    Parameters
    ----------
    deviation : callable
        ``deviation(x, y[, z]) -> (dx, dy[, dz])``: the position error at a
        commanded point, arrays in and out, as many coordinates as the
        diagonals' points. [m]
    diagonals : list of (start, end)
        Commanded end points. [m]

    Returns
    -------
    ndarray, shape (n_diagonals,)
        Distance between the actual end points. [m]
    """
    out = []
    for start, end in diagonals:
        a = _actual(deviation, [start, end])
        out.append(np.linalg.norm(a[1] - a[0]))
    return np.array(out)


def squareness_from_diagonals(d1, d2, travels):
    """Squareness ``S = D0 (D1 - D2) / (2 X Y)`` (Renishaw/Chapman).

    Parameters
    ----------
    d1, d2 : float
        Measured lengths of D1 (stretched by a positive squareness) and D2;
        for body diagonals, the means of the overlapping pairs. [m]
    travels : tuple of float
        ``(X, Y)`` for a face, ``(X, Y, Z)`` for body diagonals: the
        programmed travel along each axis; the first two are the plane's. [m]

    Returns
    -------
    float
        Squareness, positive when the angle between +X and +Y exceeds 90 deg.
        [rad]
    """
    d0 = float(np.linalg.norm(travels))
    return d0 * (d1 - d2) / (2 * travels[0] * travels[1])


def diagonal_squareness(deviation, x_range, y_range):
    """Squareness from the two XY face diagonal lengths.

    Parameters
    ----------
    deviation : callable
        ``deviation(x, y) -> (dx, dy)``, arrays in and out. [m]
    x_range, y_range : tuple of float
        ``(min, max)`` of the travel used on each axis. [m]

    Returns
    -------
    float
        Squareness, Chapman's sign. [rad]
    """
    d1, d2 = diagonal_lengths(deviation, face_diagonals(x_range, y_range))
    return squareness_from_diagonals(d1, d2, (x_range[1] - x_range[0], y_range[1] - y_range[0]))


@dataclass(frozen=True)
class DiagonalResult:
    """ISO 230-6 analysis of one diagonal.

    Attributes
    ----------
    start, end : ndarray
        Commanded end points. [m]
    target_m : ndarray, shape (n,)
        Target positions along the diagonal from its start. [m]
    forward_error_m, reverse_error_m : ndarray, shape (n,)
        Mean positioning errors approaching each target forward and in
        reverse. [m]
    e_m : float
        Bi-directional systematic positioning error
        ``E = max(X_up, X_down) - min(X_up, X_down)``. [m]
    b_m : float
        Reversal error ``B = max |X_up,i - X_down,i|``. [m]
    length_m : float
        Actual length between the end points. [m]
    """

    start: np.ndarray
    end: np.ndarray
    target_m: np.ndarray
    forward_error_m: np.ndarray
    reverse_error_m: np.ndarray
    e_m: float
    b_m: float
    length_m: float


@dataclass(frozen=True)
class DiagonalTest:
    """ISO 230-6 result of a set of diagonals.

    Attributes
    ----------
    diagonals : list of DiagonalResult
        One per diagonal, in the order given.
    e_d_m : float
        Diagonal systematic deviation of positioning ``E_d = max E_k``. [m]
    b_d_m : float
        Diagonal reversal value ``B_d = max B_k``. [m]
    """

    diagonals: list
    e_d_m: float
    b_d_m: float


def diagonal_test(deviation, diagonals, n_targets=11, reversal_m=0.0):
    """Simulate the ISO 230-6 diagonal displacement test.

    Parameters
    ----------
    deviation : callable
        ``deviation(x, y[, z]) -> (dx, dy[, dz])``, arrays in and out. [m]
    diagonals : list of (start, end)
        Commanded end points, e.g. from :func:`face_diagonals` or
        :func:`body_diagonals`. [m]
    n_targets : int
        Equispaced targets along each diagonal, both ends included.
    reversal_m : float
        Reversal value along the diagonal: the forward mean error (targets
        approached from ``start`` towards ``end``) is raised by half of it and
        the reverse one lowered by half, so for a positive value the machine
        passes each target by ``reversal_m / 2`` in its direction of travel
        and stops ``reversal_m`` further along the reverse direction than
        going forward. A negative value models lost motion (the machine stops
        short of each target in both directions); ``E`` and ``B`` depend
        only on its size. [m]

    Returns
    -------
    DiagonalTest

    Raises
    ------
    ImuSquareError
        If ``n_targets < 2`` or a diagonal has zero length.
    """
    if not (isinstance(n_targets, int | np.integer) and n_targets >= 2):
        raise ImuSquareError(f"n_targets must be an integer >= 2, got {n_targets!r}")
    results = []
    for start, end in diagonals:
        start = np.asarray(start, dtype=float)
        end = np.asarray(end, dtype=float)
        length = float(np.linalg.norm(end - start))
        if length == 0:
            raise ImuSquareError(f"a diagonal must have two distinct ends, got {start!r}, {end!r}")
        u = (end - start) / length
        frac = np.linspace(0.0, 1.0, n_targets)
        targets = start + frac[:, None] * (end - start)
        actual = _actual(deviation, targets)
        error = (actual - actual[0]) @ u - frac * length
        forward = error + 0.5 * reversal_m
        reverse = error - 0.5 * reversal_m
        both = np.concatenate([forward, reverse])
        results.append(
            DiagonalResult(
                start=start,
                end=end,
                target_m=frac * length,
                forward_error_m=forward,
                reverse_error_m=reverse,
                e_m=float(both.max() - both.min()),
                b_m=float(np.max(np.abs(forward - reverse))),
                length_m=float(np.linalg.norm(actual[-1] - actual[0])),
            )
        )
    return DiagonalTest(
        diagonals=results,
        e_d_m=max(r.e_m for r in results),
        b_d_m=max(r.b_m for r in results),
    )


def body_diagonal_squareness(deviation, x_range, y_range, z_range, plane="XY"):
    """Squareness of one plane from the four body diagonal lengths.

    Parameters
    ----------
    deviation : callable
        ``deviation(x, y, z) -> (dx, dy, dz)``, arrays in and out. [m]
    x_range, y_range, z_range : tuple of float
        ``(min, max)`` of the travel used on each axis. [m]
    plane : {"XY", "YZ", "ZX"}
        The plane; its first axis plays X and its second Y in
        :func:`squareness_from_diagonals`.

    Returns
    -------
    float
        Squareness, positive when the angle between the plane's first and
        second positive axes exceeds 90 deg. [rad]
    """
    check_option("plane", plane, ("XY", "YZ", "ZX"))
    order = [_AXES.index(a) for a in plane] + [_AXES.index(a) for a in _AXES if a not in plane]
    ranges = [(x_range, y_range, z_range)[i] for i in order]
    inverse = np.argsort(order)

    def permuted(*coords):
        machine = [coords[i] for i in inverse]
        d = deviation(*machine)
        return tuple(d[i] for i in order)

    lengths = diagonal_lengths(permuted, body_diagonals(*ranges))
    travels = tuple(r[1] - r[0] for r in ranges)
    return squareness_from_diagonals(lengths[:2].mean(), lengths[2:].mean(), travels)
