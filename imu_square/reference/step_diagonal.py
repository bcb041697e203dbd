"""Step-diagonal ("vector") test on a face, and what a misaligned mirror does to it.

In a step-diagonal test the machine moves one axis at a time between the
targets of a diagonal, and a laser aligned with the diagonal reads after each
single-axis step [1]_. A plane mirror on the spindle returns the beam while
the spindle zig-zags across it. If the mirror's normal ``m`` is not along the
beam ``u``, the reading is the distance along the beam to the mirror plane,
so a move ``dp`` of the mirror changes it by

    dL = (m . dp) / (m . u).

For the face diagonal at angle ``theta`` from the first axis and the mirror
turned by ``phi`` in the face (towards the first axis), ``m . u = cos phi``
and a step ``s`` of the first axis reads ``s (cos theta + sin theta tan phi)``:
an error of ``s sin(theta) tan(phi)`` per step, a relative error of
``tan(phi) tan(theta)`` on the first axis's reading. A step of the second axis
reads ``-s cos(theta) tan(phi)`` too little. Renishaw's example [1]_: a 1:1 face
(``theta = 45 deg``), ``phi = 0.2 mm/m`` (40 arcsec), 50 mm steps: +7 um per X
step, accumulating to +140 um per metre of X travel, and -7 um per Z step,
-140 um per metre of Z travel. Moving back (the opposite sequence, from the
other end) the error per metre of travel is the same: it is
indistinguishable from an over-travel of one axis and an under-travel of the
other, so slope removal, which takes the mirror's error out, takes the axes'
linear errors with it. A move along the diagonal itself (``dp`` parallel to
``u``) reads ``|dp|`` whatever the mirror, so the targets on the diagonal, the
diagonal lengths and the squareness from them are unaffected.

References
----------
.. [1] Renishaw plc, "Laser diagonal measurements for machine tool performance
   assessment", white paper H-5650-2053-01-A (2016), "Step diagonal method",
   Figs. 18-20.
"""

from dataclasses import dataclass

import numpy as np

from imu_square.errors import ImuSquareError


@dataclass(frozen=True)
class StepDiagonalResult:
    """A simulated step-diagonal run along one face diagonal.

    Attributes
    ----------
    commanded_m : ndarray, shape (2 n_steps + 1, 2)
        Commanded position before the first step and after each single-axis
        step, in the order run. [m]
    moved_axis : ndarray of int, shape (2 n_steps,)
        Which axis (0 or 1) moved in each step.
    reading_m : ndarray, shape (2 n_steps + 1,)
        Laser reading, zeroed at the start. [m]
    error_m : ndarray, shape (2 n_steps + 1,)
        Reading minus the commanded displacement projected on the beam. [m]
    step_error_m : ndarray, shape (2 n_steps,)
        Error added by each step. [m]
    error_per_travel : tuple of float
        For each axis, the sum of its steps' errors divided by its commanded
        travel (signed): the apparent linear error of that axis a naive
        analysis reports. [m/m]
    diagonal_error_m : ndarray, shape (n_steps + 1,)
        Error at the targets on the diagonal (after both axes have moved). [m]
    """

    commanded_m: np.ndarray
    moved_axis: np.ndarray
    reading_m: np.ndarray
    error_m: np.ndarray
    step_error_m: np.ndarray
    error_per_travel: tuple
    diagonal_error_m: np.ndarray


def step_diagonal_test(deviation, start, end, n_steps, mirror_tilt_rad=0.0, reverse=False):
    """Simulate a step-diagonal run on a face with a plane mirror.

    Parameters
    ----------
    deviation : callable
        ``deviation(a, b) -> (da, db)``: the machine's position error in the
        face at commanded ``(a, b)``, arrays in and out. [m]
    start, end : tuple of float
        Commanded end points of the diagonal in the face's two axes; the
        laser sits beyond ``start`` and its beam runs from ``start`` to
        ``end``. [m]
    n_steps : int
        Targets along the diagonal after the first; going forward each is
        reached by a step of axis 0 then a step of axis 1.
    mirror_tilt_rad : float
        Rotation of the mirror's normal from the beam, in the face, positive
        towards the face's first axis (axis 0). [rad]
    reverse : bool
        Run back from ``end`` to ``start`` with the opposite axis sequence
        (axis 1 first), through the same points, beam and mirror.

    Returns
    -------
    StepDiagonalResult

    Raises
    ------
    ImuSquareError
        If ``n_steps < 1`` or the diagonal does not move both axes.
    """
    if not (isinstance(n_steps, int | np.integer) and n_steps >= 1):
        raise ImuSquareError(f"n_steps must be an integer >= 1, got {n_steps!r}")
    start = np.asarray(start, dtype=float)
    end = np.asarray(end, dtype=float)
    span = end - start
    if np.any(span == 0):
        raise ImuSquareError(
            f"a step diagonal must move both axes, got start {start!r} and end {end!r}"
        )
    u = span / np.linalg.norm(span)
    c, s = np.cos(mirror_tilt_rad), np.sin(mirror_tilt_rad)
    # turn u towards axis 0 by phi: clockwise in the (axis 0, axis 1) plane
    normal = np.array([c * u[0] + s * u[1], -s * u[0] + c * u[1]])

    step = span / n_steps
    points = [start.copy()]
    moved = []
    for _ in range(n_steps):
        for axis in (0, 1):
            p = points[-1].copy()
            p[axis] += step[axis]
            points.append(p)
            moved.append(axis)
    commanded = np.array(points)
    moved = np.array(moved)
    travel = span
    if reverse:
        commanded, moved, travel = commanded[::-1], moved[::-1], -span
    d = deviation(commanded[:, 0], commanded[:, 1])
    actual = commanded + np.column_stack([np.asarray(v, dtype=float) for v in d])
    reading = (actual - actual[0]) @ normal / (normal @ u)
    error = reading - (commanded - commanded[0]) @ u
    step_error = np.diff(error)
    per_travel = tuple(float(step_error[moved == k].sum() / travel[k]) for k in (0, 1))
    return StepDiagonalResult(
        commanded_m=commanded,
        moved_axis=moved,
        reading_m=reading,
        error_m=error,
        step_error_m=step_error,
        error_per_travel=per_travel,
        diagonal_error_m=error[::2],
    )
