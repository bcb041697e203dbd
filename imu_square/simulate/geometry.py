"""The machine's geometric error map in the XY plane (Chapman, Appendix I [1]_).

Commanded (axis) position ``(x, y)`` reaches ``(x + dx, y + dy)``. With
``X = x - x0`` and ``Y = y - y0`` measured from the middle of each axis's
travel (Chapman's ``x = 0``), ``k_x = 8 S_x / L_x^2``, ``k_y = 8 S_y / L_y^2``
and ``q_x = 16 Q_x / L_x^4``:

    dx = s_x X - alpha(t) Y - [yaw_x] (k_x X + 4 q_x X^3) Y + (k_y / 2) Y^2
    dy = s_y Y + (k_x / 2) X^2 + q_x X^4 - [yaw_y] k_y X Y

``alpha(t) = alpha0 + rate * t`` is the squareness (positive when the angle
between +X and +Y exceeds 90 deg), ``s`` the scale errors, ``S`` the
straightness errors (bow at the ends of the travel, Eq. 1: ``dy = 4 S x^2/L^2``)
and the bracketed terms the associated yaw (Eq. 2-3). Without yaw the map is
Eq. 4. The Y axis terms follow by symmetry: a bow of the Y axis in X, whose
tangent turns clockwise by ``k_y Y``, which turns what it carries by the same
angle (``dy = -x k_y y``).

The X axis may also have a quartic part ``Q_x (2 X / L_x)^4`` in its form, for
Chapman's machine 7 ("a more complex form of straightness error, such as might
be shown by an axis supported at its airy points"); its associated yaw is
again the form's slope, ``4 q_x X^3``. The X form is then
``f(X) = S_x u^2 + Q_x u^4`` with ``u = 2 X / L_x``, and its straightness (peak
to valley) is no longer ``S_x``.

The map is a polynomial in ``(X, Y)``, so its derivatives along a path are
exact (:meth:`Geometry.apply`).

Local squareness. At ``(x, y)`` the local axis directions are the columns of
the Jacobian ``J`` of the map; the angle between them exceeds 90 deg by
``-(J_xy + J_yx) = -d(dx)/dy - d(dy)/dx``. For a quadratic map that is what a
ballbar circle centred at ``(x, y)`` measures (its ``sin 2 phi`` term only sees
the Jacobian at the centre) and what the inertial method measures. For
Chapman's machine 3 (X bow with yaw) it is uniform, as the paper finds; the
"-35 to +65 um/m" that the paper quotes for machine 3 is the angle between the
Y axis at X position ``x`` and the X axis's straight reference line, given by
:meth:`Geometry.axis_angle_y_to_x`.

On a circle of radius ``R`` the quartic part of the X form adds terms in
``f3 R^2``, with ``f3 = 24 q_x X`` the form's third derivative at the centre,
which the two instruments see differently because they read different
harmonics of the same path. The accelerometer's phases see the fundamental of
the path (``-f3 R^2 / 8`` without yaw) and, on a table turned by the
carriage's yaw ``f'(X)``, the second harmonic of that yaw (``+f3 R^2 / 4``
with yaw):
:meth:`Geometry.circle_squareness`. The ballbar's ``sin 2 phi`` term also
takes in the third harmonic of the path: ``-f3 R^2 / 12`` without yaw,
``+f3 R^2 / 6`` with it (:mod:`imu_square.reference.ballbar`).

References
----------
.. [1] Renishaw plc, "Calibration of machine squareness", white paper TE328
   (2013), Appendix I.
"""

from dataclasses import dataclass

import numpy as np

from imu_square.errors import ConfigError
from imu_square.validation import check_option


@dataclass(frozen=True)
class Geometry:
    """Geometric errors of the XY plane.

    Attributes
    ----------
    machine_squareness_rad : float
        Squareness alpha0 at t = 0. [rad]
    machine_squareness_rate_rad_s : float
        Linear drift of the squareness. [rad/s]
    scale_x, scale_y : float
        Scale errors s_x, s_y (``x (1 + s_x)``). [m/m]
    straightness_x_m : float
        Chapman's S of the X axis: bow in Y at the ends of the X travel. [m]
    straightness_y_m : float
        Chapman's S of the Y axis: bow in X at the ends of the Y travel. [m]
    straightness_x_quartic_m : float
        Q of the X axis: the quartic part ``Q (2 X / L_x)^4`` of its form in
        Y, i.e. its value at the ends of the X travel. [m]
    length_x_m, length_y_m : float
        Axis travels L_x, L_y. [m]
    axis_centre_m : tuple of float
        Machine coordinates of the middle of the X and Y travels (Chapman's
        ``x = 0, y = 0``). [m]
    yaw_x, yaw_y : bool
        Whether the straightness of that axis comes with its associated yaw.
    """

    machine_squareness_rad: float = 0.0
    machine_squareness_rate_rad_s: float = 0.0
    scale_x: float = 0.0
    scale_y: float = 0.0
    straightness_x_m: float = 0.0
    straightness_y_m: float = 0.0
    straightness_x_quartic_m: float = 0.0
    length_x_m: float = 0.8
    length_y_m: float = 0.8
    axis_centre_m: tuple = (0.0, 0.0)
    yaw_x: bool = False
    yaw_y: bool = False

    @property
    def k_x(self):
        """Curvature term 8 S_x / L_x^2 of the X axis. [1/m]"""
        return 8.0 * self.straightness_x_m / self.length_x_m**2

    @property
    def k_y(self):
        """Curvature term 8 S_y / L_y^2 of the Y axis. [1/m]"""
        return 8.0 * self.straightness_y_m / self.length_y_m**2

    @property
    def q_x(self):
        """Quartic term 16 Q_x / L_x^4 of the X axis's form. [1/m^3]"""
        return 16.0 * self.straightness_x_quartic_m / self.length_x_m**4

    def machine_squareness_at(self, t):
        """Squareness alpha(t). [rad]"""
        return self.machine_squareness_rad + self.machine_squareness_rate_rad_s * np.asarray(
            t, dtype=float
        )

    def _coefficients(self):
        """Coefficients of dx and dy in (X, Y, X^2, XY, Y^2, X^3 Y, X^4), squareness excluded."""
        kx, ky, q = self.k_x, self.k_y, self.q_x
        cx = (
            self.scale_x,
            0.0,
            0.0,
            -kx if self.yaw_x else 0.0,
            0.5 * ky,
            -4 * q if self.yaw_x else 0.0,
            0.0,
        )
        cy = (0.0, self.scale_y, 0.5 * kx, -ky if self.yaw_y else 0.0, 0.0, 0.0, q)
        return cx, cy

    def deviation(self, x, y, t=0.0):
        """Position error at commanded ``(x, y)``.

        Parameters
        ----------
        x, y : float or ndarray
            Commanded axis positions in machine coordinates. [m]
        t : float or ndarray
            Time, for the squareness drift. [s]

        Returns
        -------
        dx, dy : ndarray
            Position error; the machine reaches ``(x + dx, y + dy)``. [m]
        """
        x0, y0 = self.axis_centre_m
        X = np.asarray(x, dtype=float) - x0
        Y = np.asarray(y, dtype=float) - y0
        (a1, a2, a3, a4, a5, a6, _), (b1, b2, b3, b4, b5, _, b7) = self._coefficients()
        alpha = self.machine_squareness_at(t)
        X3 = X * X * X
        dx = a1 * X + (a2 - alpha) * Y + a3 * X * X + a4 * X * Y + a5 * Y * Y + a6 * X3 * Y
        dy = b1 * X + b2 * Y + b3 * X * X + b4 * X * Y + b5 * Y * Y + b7 * X3 * X
        return dx, dy

    def apply(self, x, y, t):
        """Actual position, velocity and acceleration along an axis path.

        Exact chain rule through the polynomial map, including the squareness
        drift (``alpha`` linear in ``t``).

        Parameters
        ----------
        x, y : tuple of 3 ndarray
            Axis position, velocity and acceleration, each shape (n,).
            [m, m/s, m/s^2]
        t : ndarray, shape (n,)
            Time, for the squareness drift. [s]

        Returns
        -------
        pos, vel, acc : ndarray, shape (n, 2)
            Actual tool position, velocity and acceleration in the plane.
            [m, m/s, m/s^2]
        """
        x0, y0 = self.axis_centre_m
        X, X1, X2 = x[0] - x0, x[1], x[2]
        Y, Y1, Y2 = y[0] - y0, y[1], y[2]
        # the monomials and their first and second time derivatives
        mono = [
            (X, X1, X2),
            (Y, Y1, Y2),
            (X * X, 2 * X * X1, 2 * (X1 * X1 + X * X2)),
            (X * Y, X1 * Y + X * Y1, X2 * Y + 2 * X1 * Y1 + X * Y2),
            (Y * Y, 2 * Y * Y1, 2 * (Y1 * Y1 + Y * Y2)),
        ]
        if self.q_x:  # the quartic form's X^3 Y and X^4, only when there is one
            X_2, X_3 = X * X, X * X * X
            mono.append(
                (
                    X_3 * Y,
                    3 * X_2 * X1 * Y + X_3 * Y1,
                    6 * X * X1 * X1 * Y + 3 * X_2 * (X2 * Y + 2 * X1 * Y1) + X_3 * Y2,
                )
            )
            mono.append((X_3 * X, 4 * X_3 * X1, 12 * X_2 * X1 * X1 + 4 * X_3 * X2))
        alpha = self.machine_squareness_at(t)
        rate = self.machine_squareness_rate_rad_s
        out = []
        for base, coeffs in zip((x, y), self._coefficients(), strict=True):
            p = [base[0].copy(), base[1].copy(), base[2].copy()]
            for c, m in zip(coeffs[: len(mono)], mono, strict=True):
                if c:
                    for k in range(3):
                        p[k] += c * m[k]
            out.append(p)
        # the squareness term -alpha(t) Y on x, with alpha' = rate, alpha'' = 0
        out[0][0] -= alpha * Y
        out[0][1] -= alpha * Y1 + rate * Y
        out[0][2] -= alpha * Y2 + 2 * rate * Y1
        return tuple(np.column_stack((out[0][k], out[1][k])) for k in range(3))

    def jacobian(self, x, y, t=0.0):
        """Derivatives of the error map at ``(x, y)``.

        Returns
        -------
        dxdx, dxdy, dydx, dydy : ndarray
            Partial derivatives of ``dx`` and ``dy`` by ``x`` and ``y``. [m/m]
        """
        x0, y0 = self.axis_centre_m
        X = np.asarray(x, dtype=float) - x0
        Y = np.asarray(y, dtype=float) - y0
        (a1, a2, a3, a4, a5, a6, _), (b1, b2, b3, b4, b5, _, b7) = self._coefficients()
        alpha = self.machine_squareness_at(t)
        X2 = X * X
        return (
            a1 + 2 * a3 * X + a4 * Y + 3 * a6 * X2 * Y,
            a2 - alpha + a4 * X + 2 * a5 * Y + a6 * X2 * X,
            b1 + 2 * b3 * X + b4 * Y + 4 * b7 * X2 * X,
            b2 + b4 * X + 2 * b5 * Y,
        )

    def local_machine_squareness(self, x, y, t=0.0):
        """Local squareness at ``(x, y)``: ``-(d(dx)/dy + d(dy)/dx)``.

        This is what a ballbar circle centred at ``(x, y)`` measures.

        Parameters
        ----------
        x, y : float or ndarray
            Machine coordinates. [m]
        t : float or ndarray
            Time, for the squareness drift. [s]

        Returns
        -------
        float or ndarray
            Local squareness. [rad]
        """
        _, dxdy, dydx, _ = self.jacobian(x, y, t)
        return -(dxdy + dydx)

    def circle_squareness(self, x, y, radius, t=0.0):
        """What ``theta_y - theta_x`` of a table-mounted accelerometer reads on a circle.

        The local squareness (:meth:`local_machine_squareness`) plus, for a quartic X
        form, ``-f3 R^2 / 8`` without its yaw (the fundamental of the path) or
        ``+f3 R^2 / 4`` with it (the second harmonic of the carriage's yaw
        turns the sensor), ``f3 = 24 q_x X`` at the centre; see the module
        notes. First order in the errors, the sensor's own terms excluded.
        Equal to the local squareness for a quadratic map.

        Parameters
        ----------
        x, y : float or ndarray
            Circle centre in machine coordinates. [m]
        radius : float
            Circle radius. [m]
        t : float or ndarray
            Time, for the squareness drift. [s]

        Returns
        -------
        float or ndarray
            [rad]
        """
        f3 = 24 * self.q_x * (np.asarray(x, dtype=float) - self.axis_centre_m[0])
        return self.local_machine_squareness(x, y, t) + f3 * radius**2 * (
            0.25 if self.yaw_x else -0.125
        )

    def axis_angle_y_to_x(self, x, t=0.0):
        """Angle between the Y axis at X position ``x`` and the X axis's reference line.

        The X reference line is the straight line through the ends of the X
        travel (the least-squares line of a symmetric bow), the Y direction is
        the local direction of Y motion at ``(x, y0)``. This is what an "L" or
        "T" test at that X position sees; Chapman quotes it for machine 3.

        Parameters
        ----------
        x : float or ndarray
            X position in machine coordinates. [m]
        t : float or ndarray
            Time, for the squareness drift. [s]

        Returns
        -------
        float or ndarray
            Angle beyond 90 deg. [rad]
        """
        _, dxdy, _, _ = self.jacobian(x, self.axis_centre_m[1], t)
        return -dxdy

    def carriage_yaw(self, x, y):
        """Yaw of the carriage from the axes' associated yaw. [rad]

        ``k_x X + 4 q_x X^3`` (the slope of the X form) when the X straightness
        has its yaw (the X tangent turns counter-clockwise) and ``-k_y Y`` for
        the Y axis; zero otherwise.
        """
        x0, y0 = self.axis_centre_m
        yaw = np.zeros(np.broadcast(np.asarray(x), np.asarray(y)).shape)
        if self.yaw_x:
            X = np.asarray(x, dtype=float) - x0
            # X * X * X, not X**3: a power of a negative number takes libm's slow path (100 times)
            yaw = yaw + self.k_x * X + 4 * self.q_x * (X * X * X)
        if self.yaw_y:
            yaw = yaw - self.k_y * (np.asarray(y, dtype=float) - y0)
        return yaw


CHAPMAN_SQUARENESS_RAD = 15e-6
CHAPMAN_LENGTH_M = 0.8
# Machine 3: the angle between the Y axis and the X axis goes from -35 to
# +65 um/m across the X travel, i.e. 15 -+ 4 S/L = 15 -+ 50 um/m => S = 10 um.
# The paper gives no other figure for machines 2-5; we use the same 10 um for
# every straightness error (machine 6 of the paper also has 10 um on X, 5 um on Y).
CHAPMAN_STRAIGHTNESS_M = 10e-6
# Machines 6 and 7: 750 mm x 250 mm, X straightness 10 um, Y straightness 5 um.
CHAPMAN_LONG_LENGTHS_M = (0.75, 0.25)
CHAPMAN_LONG_STRAIGHTNESS_M = (10e-6, 5e-6)
# Machine 7 with yaw: "T" and "L" read 95 and 39 um/m. T at 0 deg (bar along
# the top edge, stem through the middle of X) sees only the Y axis's yaw at the
# edge: 15 + 4 S_y / L_y = 15 + 80 = 95 um/m, whatever the X form. The L figure
# fixes the one parameter of the X form the paper leaves out (chapman_machine).
CHAPMAN_M7_L_RAD = 39e-6


def _machine_7_form(peak_to_valley, length, squareness, y_yaw_at_edge, l_reading):
    """``(S, Q)`` of an X form ``S u^2 + Q u^4`` for Chapman's machine 7.

    Two conditions: the form's straightness (peak to valley) is
    ``peak_to_valley``, and an L test at 0 deg (corner at ``x_min, y_min``)
    reads ``l_reading``: ``alpha + f'(-L/2) - y_yaw_at_edge``, ``f'(-L/2) =
    -(4 S + 8 Q) / L``. The solution is the "M" form (``Q < 0 < S``) whose
    peak-to-valley runs from the middle to the two crests; ``S + 2 Q = c``
    and ``S^2 / (2 (S - c)) = P`` give ``S = P + sqrt(P^2 - 2 P c)``.
    """
    c = -(length / 4) * (l_reading - squareness + y_yaw_at_edge)
    p = peak_to_valley
    s = p + (p * p - 2 * p * c) ** 0.5
    return s, (c - s) / 2


def chapman_machine(n, yaw=False):
    """Machines 1-7 of Chapman's white paper, +15 um/m squareness.

    1-5 have 800 mm axes: 1: squareness only; 2: X straightness; 3: X
    straightness with yaw; 4: X and Y straightness; 5: X and Y straightness
    with yaw. Straightness S = 10 um (derived from machine 3's -35 to
    +65 um/m, see module notes).

    6 and 7 are 750 mm x 250 mm with 10 um of X and 5 um of Y straightness
    and no yaw (Figs. 24-25); ``yaw=True`` adds the associated yaw of both
    axes, as the paper does to machine 7 in its text. Machine 6's forms are
    simple bows. Machine 7's X form is "more complex ... such as might be shown
    by an axis supported at its airy points", with no formula. We take the
    lowest-order symmetric form that has the two crests of a bar resting on
    two supports, ``f = S u^2 + Q u^4`` (``u = 2 X / L_x``, ``Q < 0``), keep
    its straightness (peak to valley) at machine 6's 10 um, and set its one
    remaining parameter so that the L test at 0 deg reads the paper's 39 um/m
    with yaw: ``S = 32.14 um``, ``Q = -25.82 um`` (crests at ``X = +-296 mm``,
    ends 6.3 um above the middle). The exact deflection of a bar on its Airy
    points cannot be what the paper used: its slope is zero at the ends, so
    with yaw every L would read 15 +- 80 um/m, never 39.

    Parameters
    ----------
    n : int
        Machine number, 1 to 7.
    yaw : bool
        Add the associated yaw of both axes; only for machines 6 and 7
        (machines 1-5 have it or not by their number).

    Returns
    -------
    Geometry
        Axis centre at the machine origin.
    """
    check_option("chapman_machine n", n, (1, 2, 3, 4, 5, 6, 7), error=ConfigError)
    if yaw and n < 6:
        raise ConfigError(f"chapman_machine yaw=True is for machines 6 and 7, got n={n!r}")
    if n >= 6:
        (lx, ly), (sx, sy) = CHAPMAN_LONG_LENGTHS_M, CHAPMAN_LONG_STRAIGHTNESS_M
        quartic = 0.0
        if n == 7:
            sx, quartic = _machine_7_form(
                sx, lx, CHAPMAN_SQUARENESS_RAD, 4 * sy / ly, CHAPMAN_M7_L_RAD
            )
        return Geometry(
            machine_squareness_rad=CHAPMAN_SQUARENESS_RAD,
            straightness_x_m=sx,
            straightness_y_m=sy,
            straightness_x_quartic_m=quartic,
            length_x_m=lx,
            length_y_m=ly,
            yaw_x=yaw,
            yaw_y=yaw,
        )
    s = CHAPMAN_STRAIGHTNESS_M
    return Geometry(
        machine_squareness_rad=CHAPMAN_SQUARENESS_RAD,
        straightness_x_m=s if n >= 2 else 0.0,
        straightness_y_m=s if n >= 4 else 0.0,
        length_x_m=CHAPMAN_LENGTH_M,
        length_y_m=CHAPMAN_LENGTH_M,
        yaw_x=n in (3, 5),
        yaw_y=n == 5,
    )
