"""The machine's geometric error map in the XY plane (Chapman, Appendix I [1]_).

Commanded (axis) position ``(x, y)`` reaches ``(x + dx, y + dy)``. With
``X = x - x0`` and ``Y = y - y0`` measured from the middle of each axis's
travel (Chapman's ``x = 0``), ``k_x = 8 S_x / L_x^2`` and ``k_y = 8 S_y / L_y^2``:

    dx = s_x X - alpha(t) Y - [yaw_x] k_x X Y + (k_y / 2) Y^2
    dy = s_y Y + (k_x / 2) X^2 - [yaw_y] k_y X Y

``alpha(t) = alpha0 + rate * t`` is the squareness (positive when the angle
between +X and +Y exceeds 90 deg), ``s`` the scale errors, ``S`` the
straightness errors (bow at the ends of the travel, Eq. 1: ``dy = 4 S x^2/L^2``)
and the bracketed terms the associated yaw (Eq. 2-3). Without yaw the map is
Eq. 4. The Y axis terms follow by symmetry: a bow of the Y axis in X, whose
tangent turns clockwise by ``k_y Y``, which turns what it carries by the same
angle (``dy = -x k_y y``).

The map is a quadratic polynomial in ``(X, Y)``, so its derivatives along a
path are exact (:meth:`Geometry.apply`).

Local squareness. At ``(x, y)`` the local axis directions are the columns of
the Jacobian ``J`` of the map; the angle between them exceeds 90 deg by
``-(J_xy + J_yx) = -d(dx)/dy - d(dy)/dx``. That is what a ballbar circle
centred at ``(x, y)`` measures (its ``sin 2 phi`` term only sees the Jacobian at
the centre for a quadratic map) and what the inertial method measures. For
Chapman's machine 3 (X bow with yaw) it is uniform, as the paper finds; the
"-35 to +65 um/m" that the paper quotes for machine 3 is the angle between the
Y axis at X position ``x`` and the X axis's straight reference line, given by
:meth:`Geometry.axis_angle_y_to_x`.

References
----------
.. [1] Renishaw plc, "Calibration of machine squareness", white paper TE328
   (2013), Appendix I.
"""

from dataclasses import dataclass

import numpy as np

from imu_square.errors import ConfigError, check_option


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

    def machine_squareness_at(self, t):
        """Squareness alpha(t). [rad]"""
        return self.machine_squareness_rad + self.machine_squareness_rate_rad_s * np.asarray(
            t, dtype=float
        )

    def _coefficients(self):
        """Coefficients of dx and dy in (X, Y, X^2, XY, Y^2), squareness excluded."""
        kx, ky = self.k_x, self.k_y
        cx = (self.scale_x, 0.0, 0.0, -kx if self.yaw_x else 0.0, 0.5 * ky)
        cy = (0.0, self.scale_y, 0.5 * kx, -ky if self.yaw_y else 0.0, 0.0)
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
        (a1, a2, a3, a4, a5), (b1, b2, b3, b4, b5) = self._coefficients()
        alpha = self.machine_squareness_at(t)
        dx = a1 * X + (a2 - alpha) * Y + a3 * X * X + a4 * X * Y + a5 * Y * Y
        dy = b1 * X + b2 * Y + b3 * X * X + b4 * X * Y + b5 * Y * Y
        return dx, dy

    def apply(self, x, y, t):
        """Actual position, velocity and acceleration along an axis path.

        Exact chain rule through the quadratic map, including the squareness
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
        mono = (
            (X, X1, X2),
            (Y, Y1, Y2),
            (X * X, 2 * X * X1, 2 * (X1 * X1 + X * X2)),
            (X * Y, X1 * Y + X * Y1, X2 * Y + 2 * X1 * Y1 + X * Y2),
            (Y * Y, 2 * Y * Y1, 2 * (Y1 * Y1 + Y * Y2)),
        )
        alpha = self.machine_squareness_at(t)
        rate = self.machine_squareness_rate_rad_s
        out = []
        for base, coeffs in zip((x, y), self._coefficients(), strict=True):
            p = [base[0].copy(), base[1].copy(), base[2].copy()]
            for c, m in zip(coeffs, mono, strict=True):
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
        (a1, a2, a3, a4, a5), (b1, b2, b3, b4, b5) = self._coefficients()
        alpha = self.machine_squareness_at(t)
        return (
            a1 + 2 * a3 * X + a4 * Y,
            a2 - alpha + a4 * X + 2 * a5 * Y,
            b1 + 2 * b3 * X + b4 * Y,
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

        ``k_x X`` when the X straightness has its yaw (the X tangent turns
        counter-clockwise) and ``-k_y Y`` for the Y axis; zero otherwise.
        """
        x0, y0 = self.axis_centre_m
        yaw = np.zeros(np.broadcast(np.asarray(x), np.asarray(y)).shape)
        if self.yaw_x:
            yaw = yaw + self.k_x * (np.asarray(x, dtype=float) - x0)
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


def chapman_machine(n):
    """Machines 1-5 of Chapman's white paper: 800 mm axes, +15 um/m squareness.

    1: squareness only; 2: X straightness; 3: X straightness with yaw;
    4: X and Y straightness; 5: X and Y straightness with yaw. Straightness
    S = 10 um (derived from machine 3's -35 to +65 um/m, see module notes).

    Parameters
    ----------
    n : int
        Machine number, 1 to 5.

    Returns
    -------
    Geometry
        Axis centre at the machine origin.
    """
    check_option("chapman_machine n", n, (1, 2, 3, 4, 5), error=ConfigError)
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
