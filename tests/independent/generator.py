"""An independent circle-test generator: machine and sensor physics from first principles.

This module writes a :class:`~imu_square.io.recording.Recording` of the
circle test of Szipka et al. [1]_ from the program's timeline and a
parametrisation of each machine and sensor effect chosen here, without the
project's own simulator. Its purpose is to test the project's analysis on
motion and effects that the analysis's author did not write.

Physical chain
--------------
Everything runs on a fine time grid ``h = dt_true / oversample`` in true time
``t`` (the sensor's samples are every ``oversample``-th grid point)::

    program -> commanded path p_c(t)            (feed ramps, dwells, idle)
            -> axis servo: delay, first-order lag   (per axis)
            -> axis reversals -> lost motion (play operator + contact filter),
                                 friction spikes (tracking-error transients)
            -> axis scale, cyclic error             (functions of the axis position)
            -> geometry: squareness, straightness (+ associated yaw)
            -> table acceleration a(t) (+ structural mode response q'')
            -> specific force f = s_k * a + g * tilt(p)
            -> sensor: rotation, non-orthogonality, gains, static tilt,
                       anti-alias (optional), clock, noise (white + 1/f),
                       ADC range and resolution, lost samples, events

Derivatives are exact: positions are carried as jets ``(value, d/dt,
d^2/dt^2)`` through every map (the chain and product rules are applied by
:class:`Jet`, not by circle formulas), and the linear filters (servo lag,
contact compliance, structural mode) are integrated exactly for inputs
linear between grid points (first-order hold), their derivatives read from
their state equations. No numerical differentiation is used; the tests check
the jets against an eighth-order finite difference.

Effects and their equations
---------------------------
Notation: ``x_c, y_c`` commanded axis positions, ``x_a, y_a`` servo outputs,
``q_x, q_y`` axis positions after lost motion and spikes, ``x_t, y_t`` the
table (sensor) position, ``sigma_i(t)`` the sign of axis ``i``'s velocity
(held through rests), ``t_r`` the reversal times of an axis.

Commanded path
    ``p_c = c + R (cos phi, sin phi)``, ``phi = phi_0 + sign * s(t) / R``;
    ``s(t)`` rises with a ramp of duration ``T_r``: ``ds/dt = v g(u)``,
    ``u = (t - t_0) / T_r``, with ``g(u) = u - sin(2 pi u) / (2 pi)``
    (``"cosine"``: jerk continuous), ``g = 2u^2 | 1 - 2(1-u)^2``
    (``"constant_jerk"``) or ``g = u`` (``"constant_accel"``), and falls
    symmetrically; each block lasts ``L / v + T_r`` for its arc ``L``.
Squareness (``alpha``)
    ``x_t = x - alpha * y`` (DESIGN.md's sign: positive when the angle between
    +X and +Y exceeds 90 degrees).
Servo (per axis)
    ``tau * dx_a/dt + x_a = x_c(t - d)``: a pure delay ``d`` and a first-order
    lag ``tau``; at the circle frequency ``H(omega) = exp(-j omega d) /
    (1 + j omega tau)``.
Lost motion (per axis, signed ``b``)
    ``q = x_a - (b / 2) * S(t)`` where ``S`` follows a play operator: after a
    reversal to direction ``sigma_a``, ``S = -sigma_a (1 - 2 min(1, d / |b|))``
    with ``d = sigma_a (x_a - x_a(t_r))`` the motor travel since the reversal.
    For ``b > 0`` the table stands still while the motor crosses the gap
    (true backlash: the table's extreme positions fall short by ``b / 2`` each
    side); for ``b < 0`` the table is thrown ahead by ``|b|`` (over-compensated
    backlash). The offset ``-(b/2) S`` is passed through the contact's
    compliance, ``o'' + 2 zeta w o' + w^2 o = w^2 * input`` (``w = 2 pi
    engagement_hz``), so that the acceleration stays finite.
Friction spikes (per axis, any number)
    A servo tracking-error transient at each axis reversal,
    ``e(t) = -sigma_a * h * shape(t - t_r)`` (``h > 0``: outward, the axis lags
    behind its new direction; ``h < 0``: inward). Shapes (``w`` the width):
    ``"after"``: ``(tau/w)^3 exp(3 (1 - tau/w))`` for ``tau >= 0`` (peak ``h``
    at ``tau = w``; position, velocity and acceleration continuous at the
    reversal: the friction force builds up over the pre-sliding regime
    instead of stepping, which an ideal sampler could not take without
    aliasing);
    ``"centred"``: ``exp(-tau^2 / (2 w^2))``;
    ``"led"``: ``after(tau) - k exp(-(tau + t_lead)^2 / (2 w^2))``, the friction
    spike led by a compensation pulse of relative size ``k`` fired ``t_lead``
    early, pushing the other way.
    Each shape returns to zero position and velocity: the net impulse
    ``int e'' dt`` is zero (the servo restores the motion); its position-time
    area ``int e dt`` is ``2 e^3 h w / 27`` (after), ``h w sqrt(2 pi)`` (centred).
Scale and cyclic error (per axis)
    ``x -> (1 + s) x + A sin(2 pi x / P + phase)``.
Straightness (per axis, Chapman's appendix I [2]_)
    X axis, in Y: ``dy = S2 xi^2 + S4 xi^4``, ``xi = 2 (x - x_mid) / L`` (a plain
    bend and a quartic, e.g. an axis on its Airy points); with associated
    yaw, ``dx = -(y - y_mid) d(dy)/dx`` (the yaw of the bent axis turns the axis
    it carries). Y axis, in X: ``dx = T2 eta^2 + T4 eta^4``; with yaw,
    ``dy = -(x - x_mid) d(dx)/dy``.
Structural mode (per axis)
    ``q'' + 2 zeta w_n q' + w_n^2 q = -(kappa * a_i + mu * tanh(v_i / v_s))``:
    the table's flexure, base-excited by the drive's acceleration
    (participation ``kappa``: excites at every block start and stop through
    the ramp's jerk) and by a smoothed Coulomb friction ``mu`` that flips at
    reversals (``v_s`` its velocity scale); the sensor reads ``a_i + q''``.
Gravity coupling
    A table tilt changing with position leaks ``g * K @ (x_t, y_t)`` into the
    X and Y channels (``K`` in rad/m: ``K[0][0]`` pitch of X with X, ``K[0][1]``
    roll of Y with Y, ``K[1][0]`` roll of X with X, ``K[1][1]`` pitch of Y
    with Y); the sensor's own static tilt adds ``g * (tilt_x, tilt_y)``.
Sensor
    ``s_x = (1 + g_x) n_x . f + g tilt_x``, ``s_y = (1 + g_y) n_y . f + g tilt_y``
    with ``n_x = (cos e, sin e)``, ``n_y = (cos(e + pi/2 + beta), sin(e + pi/2
    + beta))``: ``e = eps_c`` is the rotation of the sensor's x axis about +Z
    from the machine's +X, ``beta`` the sensor's non-orthogonality with the
    same sign convention as the machine's (positive when its +x, +y angle
    exceeds 90 degrees). Then white noise of one-sided density ``d`` (variance
    ``d^2 fs / 2`` per sample) plus a 1/f part with PSD ``d^2 f_c / f``,
    clipping at the range, rounding to the resolution, a clock running fast
    by ``clock_error`` (sample ``k`` at true time ``k dt / (1 + clock_error)``),
    and lost samples.

Expected ``theta_y - theta_x``
------------------------------
With ``P_x, P_y`` the fundamental (circle-frequency) phasors of the X and Y
readings along the position angle ``phi`` (reading ``= Re(P e^{j phi})``, in
units of ``-omega^2 R`` so that a perfect machine and sensor give ``P_x = 1``,
``P_y = -j``), the phases are ``theta_x = -arg P_x``, ``theta_y = -arg(j P_y)``
and

    theta_y - theta_x = arg(P_x / (j P_y)),

averaged over CCW and CW (each as a function of ``phi``, i.e. CW flipped).
For squareness and sensor alone this is exact:

    theta_y - theta_x = atan2(sin(e + beta), cos(e + beta) + alpha sin(e + beta))
                        - atan(tan(e) - alpha)
                      = alpha + beta - alpha (e^2 + (e + beta)^2) + O(3)
                      ~ beta + alpha cos(2 e),

so a sensor rotation weakens the machine's term by ``2 alpha e^2`` (0.27 % at
``e`` = 2.1 degrees, the paper's) but not the sensor's. Servo delays and lags
enter as ``H(+omega)`` for CCW and ``H(-omega) = conj H(+omega)`` for CW and
cancel in the mean exactly, except through their amplitude mismatch: a gain
ratio ``G = |H_y| / |H_x|`` (or a scale mismatch ``s_y - s_x``) seen through
the rotation shifts the mean by ``~ -2 e (G - 1)``. Gravity coupling enters as
``P -> P - (g / omega^2) K P`` and does not cancel: ``+(g/omega^2)(K_xy +
K_yx)``. :func:`expected_phasors` evaluates all linear effects (plus the
fundamental of lost motion, spikes, straightness and cyclic error at first
order) in closed form; :func:`project_fundamental` measures the same on the
noise-free readings. The truth holds both.

How this parametrisation differs from a naive one
-------------------------------------------------
A naive generator writes ``a_x = -R w^2 cos(w t)`` with a phase offset per
effect. Here each effect acts where it acts physically (servo on the command,
lost motion and friction on the axis after its servo, geometry on the axis
positions, gravity on the table position, the structural mode on the table's
acceleration, the sensor on the specific force), derivatives are exact, every
block starts and stops through a feed ramp (so the start-up transient, the
ramp's jerk and the reversals through a dwell exist), reversals are found on
the actual axis velocity (so they move with the servo's delay), friction is a
tracking error with zero net impulse rather than an acceleration spike, and
lost motion is a play operator rather than a direction-dependent offset.

References
----------
.. [1] K. Szipka, A. Archenti, G. W. Vogl, M. A. Donmez, "Identification of
   machine tool squareness errors via inertial measurements", CIRP Annals 68
   (2019).
.. [2] J. Chapman, "Calibration of machine squareness", Renishaw, appendix I.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field, fields, is_dataclass, replace

import numpy as np
from scipy import linalg, signal

from imu_square.io.recording import Event, Recording, SensorInfo

G_STANDARD = 9.80665  # [m/s^2]
UG = 1e-6 * G_STANDARD  # one micro-g [m/s^2]
_V_EPS = 1e-9  # below this an axis is at rest [m/s]
SPIKE_SHAPES = ("after", "centred", "led")
RAMP_SHAPES = ("cosine", "constant_jerk", "constant_accel")


# --------------------------------------------------------------------------- parameters


@dataclass
class Servo:
    """One axis's position loop.

    Attributes
    ----------
    delay_s : float
        Pure delay of the axis behind its command. [s]
    tau_s : float
        Time constant of a first-order lag after the delay. [s]
    """

    delay_s: float = 0.0
    tau_s: float = 0.0


@dataclass
class LostMotion:
    """Lost motion of one axis at its reversals.

    Attributes
    ----------
    lost_motion_m : float
        Signed lost motion ``b``: positive for backlash (the table falls short
        by ``b / 2`` at each end), negative for over-compensated backlash (it
        is thrown ahead by ``|b|``). [m]
    engagement_hz : float
        Natural frequency of the contact compliance that smooths the play
        operator. [Hz]
    engagement_zeta : float
        Its damping ratio.
    """

    lost_motion_m: float = 0.0
    engagement_hz: float = 150.0
    engagement_zeta: float = 1.0


@dataclass
class Spike:
    """A friction (reversal) spike of one axis, at each of its reversals.

    Attributes
    ----------
    axis : str
        ``"x"`` or ``"y"``.
    shape : str
        ``"after"``, ``"centred"`` or ``"led"`` (see the module docstring).
    height_m : float
        Peak tracking error; positive outward (the axis lags behind its new
        direction), negative inward. [m]
    width_s : float
        Time scale ``w`` of the shape. [s]
    lead_s : float or None
        ``"led"`` only: how early the compensation pulse fires (default
        ``2 * width_s``). [s]
    comp_ratio : float
        ``"led"`` only: compensation pulse size relative to ``height_m``.
    """

    axis: str = "x"
    shape: str = "after"
    height_m: float = 0.0
    width_s: float = 0.01
    lead_s: float | None = None
    comp_ratio: float = 0.5


@dataclass
class Mode:
    """A structural mode of the table along one axis.

    Attributes
    ----------
    freq_hz : float
        Natural frequency. [Hz]
    zeta : float
        Damping ratio.
    participation : float
        ``kappa``: share of the drive's acceleration that excites the mode.
    friction_m_s2 : float
        ``mu``: friction force per moving mass, ``-mu tanh(v / v_s)`` on the
        mode (opposing the axis's velocity), that flips at each reversal and
        excites the mode. [m/s^2]
    friction_velocity_m_s : float
        ``v_s``: velocity over which the friction force turns over. [m/s]
    """

    freq_hz: float = 40.0
    zeta: float = 0.05
    participation: float = 0.0
    friction_m_s2: float = 0.0
    friction_velocity_m_s: float = 1e-3


@dataclass
class Straightness:
    """Straightness of one axis (Chapman, appendix I), in the other axis's direction.

    Attributes
    ----------
    quadratic_m : float
        ``S2``: deviation at the ends of the travel of a plain bend. [m]
    quartic_m : float
        ``S4``: coefficient of ``xi^4`` (``xi = +-1`` at the ends). [m]
    length_m : float
        Axis travel ``L``. [m]
    mid_m : float
        Machine coordinate of the middle of the travel. [m]
    yaw_coupled : bool
        Whether the bend turns the axis this one carries (associated yaw).
    """

    quadratic_m: float = 0.0
    quartic_m: float = 0.0
    length_m: float = 0.5
    mid_m: float = 0.0
    yaw_coupled: bool = False


@dataclass
class Cyclic:
    """Cyclic (ball-screw lead) error of one axis.

    Attributes
    ----------
    amplitude_m : float
        ``A``. [m]
    pitch_m : float
        ``P``, the period in axis position. [m]
    phase_rad : float
        Phase at the machine zero. [rad]
    """

    amplitude_m: float = 0.0
    pitch_m: float = 0.01
    phase_rad: float = 0.0


@dataclass
class Effects:
    """The machine's errors. Everything zero is a perfect machine.

    Attributes
    ----------
    squareness_rad : float
        ``alpha``: commanded (x, y) reaches (x - alpha y, y). [rad]
    servo_x, servo_y : Servo
    lost_motion_x, lost_motion_y : LostMotion
    spikes : list of Spike
    mode_x, mode_y : Mode or None
    straightness_x : Straightness
        The X axis's straightness in Y.
    straightness_y : Straightness
        The Y axis's straightness in X.
    scale_x, scale_y : float
        Axis scale errors. [m/m]
    cyclic_x, cyclic_y : Cyclic
    tilt_gradient_rad_m : tuple of tuple of float
        ``K``, 2 x 2: gravity's share in (X, Y) per metre of table travel in
        (X, Y). [rad/m]
    kinematics : str
        ``"tool"``: the sensor moves with the programmed coordinates;
        ``"table"``: it sits on a table that moves opposite to them (a
        machine whose spindle stands still).
    """

    squareness_rad: float = 0.0
    servo_x: Servo = field(default_factory=Servo)
    servo_y: Servo = field(default_factory=Servo)
    lost_motion_x: LostMotion = field(default_factory=LostMotion)
    lost_motion_y: LostMotion = field(default_factory=LostMotion)
    spikes: list = field(default_factory=list)
    mode_x: Mode | None = None
    mode_y: Mode | None = None
    straightness_x: Straightness = field(default_factory=Straightness)
    straightness_y: Straightness = field(default_factory=Straightness)
    scale_x: float = 0.0
    scale_y: float = 0.0
    cyclic_x: Cyclic = field(default_factory=Cyclic)
    cyclic_y: Cyclic = field(default_factory=Cyclic)
    tilt_gradient_rad_m: tuple = ((0.0, 0.0), (0.0, 0.0))
    kinematics: str = "tool"

    def __post_init__(self):
        for f in fields(self):
            kind = _NESTED.get(f.name)
            value = getattr(self, f.name)
            if kind is not None and isinstance(value, dict):
                setattr(self, f.name, kind(**value))
        self.spikes = [s if isinstance(s, Spike) else Spike(**s) for s in self.spikes]


_NESTED = {
    "servo_x": Servo,
    "servo_y": Servo,
    "lost_motion_x": LostMotion,
    "lost_motion_y": LostMotion,
    "mode_x": Mode,
    "mode_y": Mode,
    "straightness_x": Straightness,
    "straightness_y": Straightness,
    "cyclic_x": Cyclic,
    "cyclic_y": Cyclic,
}


@dataclass
class Sensor:
    """The accelerometer and its recording chain.

    Attributes
    ----------
    rate_hz : float
        Nominal output data rate; ``1e9 / rate_hz`` must be whole nanoseconds. [Hz]
    eps_c_rad : float
        Rotation of the sensor's x axis about +Z from the machine's +X. [rad]
    nonorthogonality_rad : float
        ``beta``: the sensor's +x to +y angle minus 90 degrees. [rad]
    gain_x, gain_y, gain_z : float
        Relative gain errors.
    tilt_x_rad, tilt_y_rad : float
        Static tilt: gravity's share in the x and y channels. [rad]
    noise_density_m_s2_rthz : float
        White-noise density per axis (one-sided). [m/s^2/sqrt(Hz)]
    flicker_corner_hz : float
        Where the 1/f part equals the white part (0: none). [Hz]
    resolution_m_s2 : float
        One ADC step (0: none). [m/s^2]
    range_m_s2 : float
        Full scale; readings clip at +-range (inf: none). [m/s^2]
    clock_error : float
        Relative rate error of the sensor's clock (positive: fast). [1]
    gaps_s : list of (float, float)
        Spans of lost samples, in seconds from the first sample (sensor clock).
    loss_fraction : float
        Random loss: expected fraction of samples lost.
    mean_gap_samples : float
        Mean length of a random gap (geometric). [samples]
    bandwidth_hz : float or None
        Causal 2-pole Butterworth anti-alias filter, or None for ideal sampling. [Hz]
    event_delay_s : float
        Latency of the block markers on the sensor clock. [s]
    clock_origin_ns : int
        Sensor clock at the first sample. [ns]
    state_noise_density : bool
        Whether the recording's :class:`SensorInfo` states the white density.
    """

    rate_hz: float = 1000.0
    eps_c_rad: float = 0.0
    nonorthogonality_rad: float = 0.0
    gain_x: float = 0.0
    gain_y: float = 0.0
    gain_z: float = 0.0
    tilt_x_rad: float = 0.0
    tilt_y_rad: float = 0.0
    noise_density_m_s2_rthz: float = 7.0 * UG
    flicker_corner_hz: float = 0.0
    resolution_m_s2: float = 3.9 * UG
    range_m_s2: float = 2.048 * G_STANDARD
    clock_error: float = 0.0
    gaps_s: list = field(default_factory=list)
    loss_fraction: float = 0.0
    mean_gap_samples: float = 5.0
    bandwidth_hz: float | None = None
    event_delay_s: float = 0.0
    clock_origin_ns: int = 0
    state_noise_density: bool = True


@dataclass
class Motion:
    """How the controller runs the program.

    Attributes
    ----------
    ramp_s : float
        Duration ``T_r`` of the feed ramp at each block's start and end. [s]
    ramp_shape : str
        ``"cosine"``, ``"constant_jerk"`` or ``"constant_accel"``.
    lead_in_s, lead_out_s : float
        Idle (at rest) before the first block and after the last. [s]
    oversample : int
        Fine-grid points per sample.
    """

    ramp_s: float = 0.2
    ramp_shape: str = "cosine"
    lead_in_s: float = 2.0
    lead_out_s: float = 2.0
    oversample: int = 4


def _coerce(cls, value):
    """A dataclass from itself, None (defaults) or a (nested) dict."""
    if value is None:
        return cls()
    if isinstance(value, cls):
        return value
    if not isinstance(value, dict):
        raise TypeError(f"{cls.__name__}: expected a dict or {cls.__name__}, got {value!r}")
    names = {f.name for f in fields(cls)}
    unknown = sorted(set(value) - names)
    if unknown:
        raise TypeError(f"{cls.__name__}: unknown field {unknown[0]!r}; allowed: {sorted(names)}")
    return cls(**value)


def _plain(obj):
    """JSON-ready copy of a parameter dataclass."""
    if is_dataclass(obj):
        return {k: _plain(v) for k, v in asdict(obj).items()}
    if isinstance(obj, dict):
        return {k: _plain(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_plain(v) for v in obj]
    if isinstance(obj, np.generic):
        return obj.item()
    return obj


# --------------------------------------------------------------------------- jets


class Jet:
    """A quantity with its first and second time derivatives, exact under + - * cos sin.

    Parameters
    ----------
    v, d, dd : float or ndarray
        Value, first and second derivative.
    """

    __slots__ = ("d", "dd", "v")

    def __init__(self, v, d=0.0, dd=0.0):
        self.v, self.d, self.dd = v, d, dd

    def __add__(self, other):
        if isinstance(other, Jet):
            return Jet(self.v + other.v, self.d + other.d, self.dd + other.dd)
        return Jet(self.v + other, self.d, self.dd)

    __radd__ = __add__

    def __neg__(self):
        return Jet(-self.v, -self.d, -self.dd)

    def __sub__(self, other):
        return self + (-other)

    def __rsub__(self, other):
        return (-self) + other

    def __mul__(self, other):
        if isinstance(other, Jet):
            return Jet(
                self.v * other.v,
                self.d * other.v + self.v * other.d,
                self.dd * other.v + 2.0 * self.d * other.d + self.v * other.dd,
            )
        return Jet(self.v * other, self.d * other, self.dd * other)

    __rmul__ = __mul__

    def cos(self):
        """cos of the jet."""
        c, s = np.cos(self.v), np.sin(self.v)
        return Jet(c, -s * self.d, -c * self.d**2 - s * self.dd)

    def sin(self):
        """sin of the jet."""
        c, s = np.cos(self.v), np.sin(self.v)
        return Jet(s, c * self.d, -s * self.d**2 + c * self.dd)

    def powi(self, n):
        """Integer power ``n >= 1`` of the jet."""
        if n == 1:
            return Jet(self.v, self.d, self.dd)
        pn1 = self.v ** (n - 1)
        pn2 = self.v ** (n - 2)
        return Jet(
            self.v**n,
            n * pn1 * self.d,
            n * (n - 1) * pn2 * self.d**2 + n * pn1 * self.dd,
        )


def fd_second_derivative(y, h):
    """Eighth-order central second difference (for checking the jets only).

    Parameters
    ----------
    y : ndarray, shape (n,)
        Samples on a uniform grid.
    h : float
        Grid step. [s]

    Returns
    -------
    ndarray, shape (n,)
        ``d^2 y / dt^2``; the first and last 4 points are NaN.
    """
    c = np.array([-1 / 560, 8 / 315, -1 / 5, 8 / 5, -205 / 72, 8 / 5, -1 / 5, 8 / 315, -1 / 560])
    out = np.full(y.shape, np.nan)
    out[4:-4] = np.convolve(y, c[::-1], mode="valid") / h**2
    return out


# --------------------------------------------------------------------------- motion


def _ramp_functions(shape):
    """``g(u)``, ``g'(u)`` and ``G(u) = int_0^u g`` of a unit speed ramp on [0, 1]."""
    if shape == "cosine":
        two_pi = 2.0 * math.pi

        def g(u):
            return u - np.sin(two_pi * u) / two_pi

        def dg(u):
            return 1.0 - np.cos(two_pi * u)

        def big_g(u):
            return u**2 / 2.0 - (1.0 - np.cos(two_pi * u)) / two_pi**2

    elif shape == "constant_jerk":

        def g(u):
            return np.where(u < 0.5, 2.0 * u**2, 1.0 - 2.0 * (1.0 - u) ** 2)

        def dg(u):
            return np.where(u < 0.5, 4.0 * u, 4.0 * (1.0 - u))

        def big_g(u):
            return np.where(u < 0.5, 2.0 * u**3 / 3.0, u - 0.5 + 2.0 * (1.0 - u) ** 3 / 3.0)

    elif shape == "constant_accel":

        def g(u):
            return u

        def dg(u):
            return np.ones_like(u)

        def big_g(u):
            return u**2 / 2.0

    else:
        raise ValueError(f"ramp_shape must be one of {RAMP_SHAPES!r}, got {shape!r}")
    return g, dg, big_g


@dataclass(frozen=True)
class BlockTiming:
    """One block as this generator runs it (true time).

    Attributes
    ----------
    index : int
    direction : str
    sign : int
        +1 CCW (phi increases), -1 CW.
    feed : int
    speed_m_s : float
    phi_start_rad, phi_end_rad : float
    analysed_start_rad : float
    cycles : int
    t_start_s, t_end_s : float
        Start and end of motion, true time from the first sample. [s]
    t_analysed_s : tuple of float
        Start and end of the analysed whole cycles. [s]
    """

    index: int
    direction: str
    sign: int
    feed: int
    speed_m_s: float
    phi_start_rad: float
    phi_end_rad: float
    analysed_start_rad: float
    cycles: int
    t_start_s: float
    t_end_s: float
    t_analysed_s: tuple


class CommandedPath:
    """The program's tool path in true time, with feed ramps, dwells and idle.

    Parameters
    ----------
    program : TestProgram
    motion : Motion

    Attributes
    ----------
    blocks : list of BlockTiming
    duration_s : float
        From the first sample (rest) to the end of the lead-out. [s]
    """

    def __init__(self, program, motion):
        self.program = program
        self.motion = motion
        self.radius = float(program.radius_m)
        self.centre = (float(program.centre_m[0]), float(program.centre_m[1]))
        self._g, self._dg, self._G = _ramp_functions(motion.ramp_shape)
        tr = float(motion.ramp_s)
        if tr <= 0:
            raise ValueError(f"motion.ramp_s must be positive, got {tr!r}")
        blocks = []
        t = float(motion.lead_in_s)
        for plan in program.blocks():
            v = float(program.feeds[plan.feed])
            cycles = int(program.feed_cycles[plan.feed])
            angle = 2 * math.pi * cycles + 2 * float(program.overshoot_rad)
            arc = angle * self.radius
            if arc < v * tr:
                raise ValueError(f"block {plan.index}: the feed ramps ({tr} s) overlap")
            duration = arc / v + tr
            ramp_arc = v * tr / 2.0
            over_arc = float(program.overshoot_rad) * self.radius
            if ramp_arc > over_arc + 1e-12:
                # The analysed cycles would include the ramp; allowed, but said in the truth.
                pass
            # Time at which the path reaches arc length s in the cruise: t0 + tr/2 + s/v.
            a0 = t + tr / 2.0 + over_arc / v
            a1 = a0 + 2 * math.pi * cycles * self.radius / v
            blocks.append(
                BlockTiming(
                    index=plan.index,
                    direction=plan.direction,
                    sign=plan.sign,
                    feed=plan.feed,
                    speed_m_s=v,
                    phi_start_rad=float(plan.start_angle_rad),
                    phi_end_rad=float(plan.start_angle_rad) + plan.sign * angle,
                    analysed_start_rad=float(plan.analysed_start_rad),
                    cycles=cycles,
                    t_start_s=t,
                    t_end_s=t + duration,
                    t_analysed_s=(a0, a1),
                )
            )
            t += duration + float(program.dwell_s)
        self.blocks = blocks
        self.duration_s = blocks[-1].t_end_s + float(motion.lead_out_s)
        self.ramp_inside_overshoot = v * tr / 2.0 <= float(program.overshoot_rad) * self.radius

    def phi(self, t):
        """Commanded position angle as a :class:`Jet` at true times ``t``. [rad]"""
        t = np.asarray(t, dtype=float)
        v = np.full(t.shape, self.blocks[0].phi_start_rad)
        d = np.zeros(t.shape)
        dd = np.zeros(t.shape)
        tr = float(self.motion.ramp_s)
        r = self.radius
        for b in self.blocks:
            after = t >= b.t_end_s
            v[after] = b.phi_end_rad
            inside = (t >= b.t_start_s) & (t < b.t_end_s)
            if not inside.any():
                continue
            tt = t[inside] - b.t_start_s
            span = b.t_end_s - b.t_start_s
            arc = (b.phi_end_rad - b.phi_start_rad) * b.sign * r
            sp = b.speed_m_s
            s = sp * (tt - tr / 2.0)
            sd = np.full(tt.shape, sp)
            sdd = np.zeros(tt.shape)
            up = tt < tr
            u = tt[up] / tr
            s[up] = sp * tr * self._G(u)
            sd[up] = sp * self._g(u)
            sdd[up] = sp / tr * self._dg(u)
            down = tt > span - tr
            w = (span - tt[down]) / tr
            s[down] = arc - sp * tr * self._G(w)
            sd[down] = sp * self._g(w)
            sdd[down] = -sp / tr * self._dg(w)
            v[inside] = b.phi_start_rad + b.sign * s / r
            d[inside] = b.sign * sd / r
            dd[inside] = b.sign * sdd / r
        return Jet(v, d, dd)

    def position(self, t):
        """Commanded (x, y) as :class:`Jet` s at true times ``t``. [m]"""
        phi = self.phi(t)
        return self.centre[0] + self.radius * phi.cos(), self.centre[1] + self.radius * phi.sin()


# --------------------------------------------------------------------------- filters


def first_order_lag(w, tau, h):
    """Exact (first-order hold) response of ``tau e' + e = w``, from rest.

    Parameters
    ----------
    w : ndarray, shape (n,)
        Input on the grid, linear between points.
    tau : float
        Time constant. [s]
    h : float
        Grid step. [s]

    Returns
    -------
    ndarray, shape (n,)
    """
    a = math.exp(-h / tau)
    c = 1.0 - tau / h * (1.0 - a)
    return signal.lfilter([c, 1.0 - a - c], [1.0, -a], w)


def foh_second_order(omega, zeta, gain, u, h):
    """Exact (first-order hold) state of ``y'' + 2 zeta omega y' + omega^2 y = gain * u``.

    Parameters
    ----------
    omega : float
        Natural frequency. [rad/s]
    zeta : float
        Damping ratio.
    gain : float
        Input gain.
    u : ndarray, shape (n,)
        Input, zero at the start (the system starts at rest), linear between points.
    h : float
        Grid step. [s]

    Returns
    -------
    y, yd, ydd : ndarray, shape (n,)
        The state and its second derivative from the state equation.
    """
    a_mat = np.array([[0.0, 1.0], [-(omega**2), -2.0 * zeta * omega]])
    b_vec = np.array([[0.0], [gain]])
    m = np.zeros((4, 4))
    m[:2, :2] = a_mat * h
    m[:2, 2:3] = b_vec * h
    m[2, 3] = 1.0
    e = linalg.expm(m)
    phi, g1, g2 = e[:2, :2], e[:2, 2:3], e[:2, 3:4]
    # x_{n+1} = phi x_n + (g1 - g2) u_n + g2 u_{n+1}; xi_n = x_n - g2 u_n is a plain state.
    b_xi = phi @ g2 + g1 - g2
    num, den = signal.ss2tf(phi, b_xi, np.eye(2), g2)
    y = signal.lfilter(num[0], den, u)
    yd = signal.lfilter(num[1], den, u)
    ydd = gain * u - 2.0 * zeta * omega * yd - omega**2 * y
    return y, yd, ydd


# --------------------------------------------------------------------------- machine


def _spike_shape(shape, tau, w, lead, ratio):
    """Unit spike ``(e, e', e'')`` at times ``tau`` from the reversal."""
    e = np.zeros_like(tau)
    ed = np.zeros_like(tau)
    edd = np.zeros_like(tau)
    if shape in ("after", "led"):
        pos = tau >= 0
        u = tau[pos] / w
        ex = np.exp(3.0 - 3.0 * u)
        e[pos] += u**3 * ex
        ed[pos] += (3.0 * u**2 - 3.0 * u**3) * ex / w
        edd[pos] += (6.0 * u - 18.0 * u**2 + 9.0 * u**3) * ex / w**2
    if shape == "centred":
        u = tau / w
        ex = np.exp(-(u**2) / 2.0)
        e += ex
        ed += -u * ex / w
        edd += (u**2 - 1.0) * ex / w**2
    if shape == "led":
        u = (tau + lead) / w
        ex = np.exp(-(u**2) / 2.0)
        e -= ratio * ex
        ed -= ratio * (-u * ex / w)
        edd -= ratio * ((u**2 - 1.0) * ex / w**2)
    return e, ed, edd


def spike_fourier(shape, w, lead, ratio, nu):
    """Fourier transform ``int shape(t) exp(-j nu t) dt`` of a unit spike. [s]"""
    gauss = w * math.sqrt(2 * math.pi) * math.exp(-((nu * w) ** 2) / 2.0)
    after = math.e**3 * w * 6.0 / (3.0 + 1j * nu * w) ** 4
    if shape == "after":
        return after
    if shape == "centred":
        return gauss
    return after - ratio * gauss * np.exp(1j * nu * lead)


def find_reversals(vel, t, block_starts, delay):
    """Reversals of one axis from its velocity on the grid.

    Parameters
    ----------
    vel : ndarray, shape (n,)
        Axis velocity. [m/s]
    t : ndarray, shape (n,)
        Grid times. [s]
    block_starts : ndarray
        True start times of the blocks. [s]
    delay : float
        The axis's servo delay. [s]

    Returns
    -------
    times : ndarray
        Reversal times: the zero crossing, or the restart after a rest. [s]
    new_sign : ndarray of int
        Direction after each reversal.
    first_sign : int
        Direction of the first motion (0 if the axis never moves).
    sigma : ndarray of int, shape (n,)
        Direction held through rests (``first_sign`` before the first motion).
    """
    s = np.sign(vel) * (np.abs(vel) > _V_EPS)
    moving = np.flatnonzero(s)
    if moving.size == 0:
        return np.array([]), np.array([], dtype=int), 0, np.zeros(t.shape, dtype=int)
    ss = s[moving]
    change = np.flatnonzero(ss[1:] != ss[:-1]) + 1
    times, signs = [], []
    for k in change:
        i0, i1 = moving[k - 1], moving[k]
        if i1 == i0 + 1:
            tr = t[i0] + (t[i1] - t[i0]) * vel[i0] / (vel[i0] - vel[i1])
        else:
            starts = block_starts + delay
            cand = starts[(starts >= t[i0]) & (starts <= t[i1])]
            tr = cand[-1] if cand.size else t[i1 - 1]
        times.append(tr)
        signs.append(int(ss[k]))
    held = np.zeros(t.shape, dtype=int)
    held[moving] = ss
    # hold the last non-zero value through rests
    idx = np.where(held != 0, np.arange(t.size), 0)
    np.maximum.accumulate(idx, out=idx)
    sigma = held[idx]
    sigma[: moving[0]] = int(ss[0])
    return np.array(times), np.array(signs, dtype=int), int(ss[0]), sigma


@dataclass
class MachineState:
    """The machine on the fine grid.

    Attributes
    ----------
    t : ndarray, shape (n,)
        True time. [s]
    commanded : tuple of Jet
    axis : tuple of Jet
        Servo outputs.
    joint : tuple of Jet
        Axis positions after lost motion and spikes.
    table : tuple of Jet
        Table position (geometry applied).
    accel : ndarray, shape (n, 2)
        Table acceleration including the structural modes (machine frame). [m/s^2]
    specific_force : ndarray, shape (n, 2)
        What a perfectly aligned sensor on the table reads in X, Y. [m/s^2]
    reversals : dict
        Per axis: ``times``, ``new_sign``.
    contributions : dict of str to ndarray, shape (n, 2)
        Acceleration of each effect alone, where it is additive. [m/s^2]
    """

    t: np.ndarray
    commanded: tuple
    axis: tuple
    joint: tuple
    table: tuple
    accel: np.ndarray
    specific_force: np.ndarray
    reversals: dict
    contributions: dict


def simulate_machine(path, effects, t):
    """Run the commanded path through the machine's effects on the grid ``t``.

    Parameters
    ----------
    path : CommandedPath
    effects : Effects
    t : ndarray, shape (n,)
        Uniform true-time grid. [s]

    Returns
    -------
    MachineState
    """
    h = float(t[1] - t[0])
    block_starts = np.array([b.t_start_s for b in path.blocks])
    commanded = path.position(t)
    axes, joints, revs, sigmas, contrib = [], [], {}, {}, {}
    for i, name in enumerate("xy"):
        servo = getattr(effects, f"servo_{name}")
        cmd_d = path.position(t - servo.delay_s)[i] if servo.delay_s else commanded[i]
        if servo.tau_s > 0:
            # The lag is linear, so it commutes with d/dt: position, velocity and
            # acceleration are each the lag of the command's (exact) own, the
            # position through its small deviation ``x_a - x_c`` (which obeys
            # ``tau e' + e = -tau x_c'``) to keep its digits.
            tau = servo.tau_s
            e = first_order_lag(-tau * cmd_d.d, tau, h)
            ax = Jet(
                cmd_d.v + e,
                first_order_lag(cmd_d.d, tau, h),
                first_order_lag(cmd_d.dd, tau, h),
            )
        else:
            ax = Jet(cmd_d.v, cmd_d.d, cmd_d.dd)
        axes.append(ax)
        times, new_sign, first, sigma = find_reversals(ax.d, t, block_starts, servo.delay_s)
        revs[name] = {"times": times, "new_sign": new_sign, "first_sign": first}
        sigmas[name] = sigma
        joint = Jet(ax.v, ax.d, ax.dd)
        # lost motion
        lm = getattr(effects, f"lost_motion_{name}")
        if lm.lost_motion_m != 0 and times.size:
            b = lm.lost_motion_m
            state = np.full(t.shape, float(first))
            rev_pos = np.interp(times, t, ax.v)
            for k, (tr, sa) in enumerate(zip(times, new_sign, strict=True)):
                end = times[k + 1] if k + 1 < times.size else np.inf
                m = (t >= tr) & (t < end)
                travel = sa * (ax.v[m] - rev_pos[k])
                state[m] = -sa * (1.0 - 2.0 * np.clip(travel / abs(b), 0.0, 1.0))
            raw = -(b / 2.0) * state
            om = 2 * math.pi * lm.engagement_hz
            o0 = raw[0]
            y, yd, ydd = foh_second_order(om, lm.engagement_zeta, om**2, raw - o0, h)
            joint = joint + Jet(y + o0, yd, ydd)
            contrib[f"lost_motion_{name}"] = ydd
        # spikes
        spk = Jet(np.zeros(t.shape), np.zeros(t.shape), np.zeros(t.shape))
        for sp in effects.spikes:
            if sp.axis != name or sp.height_m == 0:
                continue
            if sp.shape not in SPIKE_SHAPES:
                raise ValueError(f"spike shape must be one of {SPIKE_SHAPES!r}, got {sp.shape!r}")
            lead = 2.0 * sp.width_s if sp.lead_s is None else sp.lead_s
            reach = 12.0 * sp.width_s + lead
            for tr, sa in zip(times, new_sign, strict=True):
                lo, hi = np.searchsorted(t, [tr - reach, tr + reach])
                e, ed, edd = _spike_shape(sp.shape, t[lo:hi] - tr, sp.width_s, lead, sp.comp_ratio)
                k = -sa * sp.height_m
                spk.v[lo:hi] += k * e
                spk.d[lo:hi] += k * ed
                spk.dd[lo:hi] += k * edd
        if np.any(spk.dd):
            joint = joint + spk
            contrib[f"spikes_{name}"] = spk.dd.copy()
        # scale and cyclic error, functions of the axis position
        scale = getattr(effects, f"scale_{name}")
        cyc = getattr(effects, f"cyclic_{name}")
        mapped = joint * (1.0 + scale)
        if cyc.amplitude_m:
            mapped = (
                mapped
                + cyc.amplitude_m * (joint * (2 * math.pi / cyc.pitch_m) + cyc.phase_rad).sin()
            )
        joints.append(mapped)
    qx, qy = joints
    # geometry
    sx, sy = effects.straightness_x, effects.straightness_y
    xi = (qx - sx.mid_m) * (2.0 / sx.length_m)
    eta = (qy - sy.mid_m) * (2.0 / sy.length_m)
    dy_x = sx.quadratic_m * xi.powi(2) + sx.quartic_m * xi.powi(4)
    dx_y = sy.quadratic_m * eta.powi(2) + sy.quartic_m * eta.powi(4)
    xt = qx - effects.squareness_rad * qy + dx_y
    yt = qy + dy_x
    if sx.yaw_coupled:
        slope = (2.0 / sx.length_m) * (2.0 * sx.quadratic_m * xi + 4.0 * sx.quartic_m * xi.powi(3))
        xt = xt - (qy - sy.mid_m) * slope
    if sy.yaw_coupled:
        slope = (2.0 / sy.length_m) * (
            2.0 * sy.quadratic_m * eta + 4.0 * sy.quartic_m * eta.powi(3)
        )
        yt = yt - (qx - sx.mid_m) * slope
    accel = np.stack([xt.dd, yt.dd], axis=1)
    # structural modes, base-excited by the table's acceleration and the friction flips
    for i, name in enumerate("xy"):
        mode = getattr(effects, f"mode_{name}")
        if mode is None:
            continue
        om = 2 * math.pi * mode.freq_hz
        fric = np.tanh(axes[i].d / mode.friction_velocity_m_s)
        exc = mode.participation * accel[:, i] + mode.friction_m_s2 * fric
        exc0 = exc[0]
        # q = q_static + response to the change of the excitation; q'' from the state.
        _, _, qdd = foh_second_order(om, mode.zeta, -1.0, exc - exc0, h)
        contrib[f"mode_{name}"] = np.column_stack(
            [qdd if i == 0 else 0 * qdd, qdd if i == 1 else 0 * qdd]
        )
        accel[:, i] += qdd
    sign = 1.0 if effects.kinematics == "tool" else -1.0
    if effects.kinematics not in ("tool", "table"):
        raise ValueError(f"kinematics must be 'tool' or 'table', got {effects.kinematics!r}")
    accel *= sign
    k = np.asarray(effects.tilt_gradient_rad_m, dtype=float)
    pos = np.stack([xt.v, yt.v], axis=1)
    grav = G_STANDARD * pos @ k.T
    return MachineState(
        t=t,
        commanded=commanded,
        axis=tuple(axes),
        joint=(qx, qy),
        table=(xt, yt),
        accel=accel,
        specific_force=accel + grav,
        reversals=revs,
        contributions=contrib,
    )


# --------------------------------------------------------------------------- sensor


def sensor_axes(sensor):
    """Unit sensing directions ``n_x, n_y`` in the machine's XY plane."""
    e, b = sensor.eps_c_rad, sensor.nonorthogonality_rad
    nx = np.array([math.cos(e), math.sin(e)])
    ny = np.array([math.cos(e + math.pi / 2 + b), math.sin(e + math.pi / 2 + b)])
    return nx, ny


def sensor_noise(sensor, n, rng):
    """White plus 1/f noise for ``n`` samples of each of the three axes.

    Parameters
    ----------
    sensor : Sensor
    n : int
    rng : numpy.random.Generator

    Returns
    -------
    ndarray, shape (n, 3)
        One-sided PSD ``d^2 (1 + f_c / f)``. [m/s^2]
    """
    d = sensor.noise_density_m_s2_rthz
    fs = sensor.rate_hz
    white = rng.standard_normal((n, 3)) * d * math.sqrt(fs / 2.0)
    if sensor.flicker_corner_hz <= 0:
        return white
    nfft = 1 << math.ceil(math.log2(max(n, 2)))
    f = np.fft.rfftfreq(nfft, 1.0 / fs)
    spec = np.fft.rfft(rng.standard_normal((nfft, 3)), axis=0)
    shape = np.zeros(f.shape)
    shape[1:] = np.sqrt(sensor.flicker_corner_hz / f[1:])
    flick = np.fft.irfft(spec * shape[:, None], n=nfft, axis=0)[:n]
    return white + flick * d * math.sqrt(fs / 2.0)


def _lost_mask(sensor, n, rng):
    """Boolean mask of the samples kept."""
    keep = np.ones(n, dtype=bool)
    dt = 1.0 / sensor.rate_hz
    for a, b in sensor.gaps_s:
        i0, i1 = math.ceil(a / dt - 1e-9), math.floor(b / dt + 1e-9)
        keep[max(i0, 1) : min(i1 + 1, n - 1)] = False
    if sensor.loss_fraction > 0:
        mean = max(float(sensor.mean_gap_samples), 1.0)
        p_start = sensor.loss_fraction / mean
        starts = np.flatnonzero(rng.random(n) < p_start)
        lengths = rng.geometric(1.0 / mean, size=starts.size)
        for s, ln in zip(starts, lengths, strict=True):
            keep[max(s, 1) : min(s + ln, n - 1)] = False
    return keep


# --------------------------------------------------------------------------- truth


def fundamental_geometry(effects, centre, radius, n=256):
    """Fundamental phasors (per unit radius) of the nonlinear geometric errors on the circle.

    Evaluates straightness, associated yaw and cyclic error on the nominal
    circle and returns their first Fourier coefficients ``F_x, F_y`` with
    ``error = R Re(F exp(j phi))``.
    """
    phi = 2 * math.pi * np.arange(n) / n
    x = centre[0] + radius * np.cos(phi)
    y = centre[1] + radius * np.sin(phi)
    sx, sy = effects.straightness_x, effects.straightness_y
    xi = 2 * (x - sx.mid_m) / sx.length_m
    eta = 2 * (y - sy.mid_m) / sy.length_m
    dx = sy.quadratic_m * eta**2 + sy.quartic_m * eta**4
    dy = sx.quadratic_m * xi**2 + sx.quartic_m * xi**4
    if sx.yaw_coupled:
        dx = dx - (y - sy.mid_m) * (2 / sx.length_m) * (
            2 * sx.quadratic_m * xi + 4 * sx.quartic_m * xi**3
        )
    if sy.yaw_coupled:
        dy = dy - (x - sx.mid_m) * (2 / sy.length_m) * (
            2 * sy.quadratic_m * eta + 4 * sy.quartic_m * eta**3
        )
    for cyc, coord, out in ((effects.cyclic_x, x, "x"), (effects.cyclic_y, y, "y")):
        if cyc.amplitude_m:
            err = cyc.amplitude_m * np.sin(2 * math.pi * coord / cyc.pitch_m + cyc.phase_rad)
            if out == "x":
                dx = dx + err
            else:
                dy = dy + err
    fx = 2 * np.mean(dx * np.exp(-1j * phi)) / radius
    fy = 2 * np.mean(dy * np.exp(-1j * phi)) / radius
    return complex(fx), complex(fy)


def expected_phasors(effects, sensor, omega, sign, radius, centre):
    """Closed-form fundamental phasors of the X and Y readings for one direction.

    Parameters
    ----------
    effects : Effects
    sensor : Sensor
    omega : float
        Circle angular speed ``v / R``. [rad/s]
    sign : int
        +1 CCW, -1 CW.
    radius : float
        [m]
    centre : tuple of float
        [m]

    Returns
    -------
    px, py : complex
        Readings ``= -omega^2 R Re(P exp(j phi))`` at first order in the
        non-linear effects (lost motion, spikes, straightness, cyclic error,
        friction-excited modes) and exactly in the linear ones.
    """
    nu = sign * omega
    cmd = {"x": 1.0 + 0j, "y": -1j}
    joint = {}
    for name in "xy":
        servo = getattr(effects, f"servo_{name}")
        hs = np.exp(-1j * nu * servo.delay_s) / (1 + 1j * nu * servo.tau_s)
        ax = hs * cmd[name]
        unit_v = 1j * sign * ax / abs(ax)  # the velocity's direction phasor
        lm = getattr(effects, f"lost_motion_{name}")
        j = ax - (2 * lm.lost_motion_m / (math.pi * radius)) * unit_v
        for sp in effects.spikes:
            if sp.axis == name and sp.height_m:
                lead = 2.0 * sp.width_s if sp.lead_s is None else sp.lead_s
                four = spike_fourier(sp.shape, sp.width_s, lead, sp.comp_ratio, nu)
                j = j + (2 * omega / math.pi) * sp.height_m * (ax / abs(ax)) * four / radius
        joint[name] = (1 + getattr(effects, f"scale_{name}")) * j
    fx, fy = fundamental_geometry(effects, centre, radius)
    tx = joint["x"] - effects.squareness_rad * joint["y"] + fx
    ty = joint["y"] + fy
    table = [tx, ty]
    out = []
    for i, name in enumerate("xy"):
        mode = getattr(effects, f"mode_{name}")
        p = table[i]
        if mode is not None:
            wn = 2 * math.pi * mode.freq_hz
            den = wn**2 - omega**2 + 2j * mode.zeta * wn * nu
            p = p * (1 + mode.participation * omega**2 / den)
            ax = cmd[name]
            servo = getattr(effects, f"servo_{name}")
            ax = ax * np.exp(-1j * nu * servo.delay_s) / (1 + 1j * nu * servo.tau_s)
            unit_v = 1j * sign * ax / abs(ax)
            p = p - mode.friction_m_s2 * (4 / math.pi) * unit_v / (den * radius)
        out.append(p)
    if effects.kinematics == "table":
        out = [-p for p in out]
    k = np.asarray(effects.tilt_gradient_rad_m, dtype=float)
    tab = np.array([table[0], table[1]])
    grav = -(G_STANDARD / omega**2) * (k @ tab)
    pm = np.array(out) + grav
    nx, ny = sensor_axes(sensor)
    px, py = complex(nx @ pm), complex(ny @ pm)
    if sensor.bandwidth_hz:
        bb, ab = signal.butter(2, 2 * math.pi * sensor.bandwidth_hz, analog=True)
        resp = signal.freqs(bb, ab, worN=[abs(nu)])[1][0]
        resp = resp if nu > 0 else np.conj(resp)
        px, py = px * resp, py * resp
    return px, py


def phases(px, py):
    """``theta_x, theta_y, theta_y - theta_x`` of fundamental phasors (module docstring). [rad]"""
    tx = -np.angle(px)
    ty = -np.angle(1j * py)
    return float(tx), float(ty), float(np.angle(px / (1j * py)))


def project_fundamental(t, readings, path, feed=None):
    """Fundamental phasors of noise-free readings over each block's analysed cycles.

    Parameters
    ----------
    t : ndarray, shape (n,)
        True times. [s]
    readings : ndarray, shape (n, 2)
        X and Y readings. [m/s^2]
    path : CommandedPath
    feed : int or None
        Only the blocks of this feed.

    Returns
    -------
    dict
        ``ccw`` and ``cw``: ``(px, py)`` averaged over the blocks, in units of
        ``-omega^2 R`` as :func:`expected_phasors`.
    """
    phi = path.phi(t).v
    acc = {"ccw": [], "cw": []}
    for b in path.blocks:
        if feed is not None and b.feed != feed:
            continue
        a0, a1 = b.t_analysed_s
        sl = (t >= a0) & (t < a1)
        ph = phi[sl]
        # least squares on a constant and the first three harmonics: exact for a
        # sinusoid whatever the window's rounding to the grid
        cols = [np.ones_like(ph)]
        for k in (1, 2, 3):
            cols += [np.cos(k * ph), np.sin(k * ph)]
        basis = np.column_stack(cols)
        coef = np.linalg.lstsq(basis, readings[sl], rcond=None)[0]
        p = coef[1] - 1j * coef[2]
        omega = b.speed_m_s / path.radius
        acc[b.direction].append(p / (-(omega**2) * path.radius))
    return {k: tuple(np.mean(v, axis=0)) for k, v in acc.items() if v}


def _direction_summary(pair):
    (pxc, pyc), (pxw, pyw) = pair
    txc, tyc, dc = phases(pxc, pyc)
    txw, tyw, dw = phases(pxw, pyw)
    return {
        "theta_diff_rad": 0.5 * (dc + dw),
        "theta_diff_ccw_rad": dc,
        "theta_diff_cw_rad": dw,
        "servo_mismatch_rad": 0.5 * (dc - dw),
        "theta_x_ccw_rad": txc,
        "theta_y_ccw_rad": tyc,
        "theta_x_cw_rad": txw,
        "theta_y_cw_rad": tyw,
        "theta_x_rad": 0.5 * (txc + txw),
        "theta_y_rad": 0.5 * (tyc + tyw),
        "amp_ratio_y_x": float(0.5 * (abs(pyc) / abs(pxc) + abs(pyw) / abs(pxw))),
    }


# --------------------------------------------------------------------------- generate


def generate(program, effects=None, sensor=None, seed=0, motion=None):
    """Simulate one circle test and its ground truth.

    Parameters
    ----------
    program : TestProgram
        The program the machine runs (its blocks, feeds, dwell, overshoot).
    effects : Effects or dict, optional
        Machine errors; a perfect machine if None.
    sensor : Sensor or dict, optional
        Sensor and recording chain; a default ADXL355-like sensor if None.
    seed : int
        Seed of the noise and of the random sample loss.
    motion : Motion or dict, optional
        Feed ramps, idle and grid.

    Returns
    -------
    recording : Recording
        Samples on the sensor clock, with block and gap events.
    truth : dict
        Every parameter, the timeline, and what the analysis should report:
        ``squareness_expected_rad`` (``theta_y - theta_x`` of the noise-free
        fundamental, closed form, CCW and flipped CW averaged; for a
        multi-feed program the first feed's, with ``per_feed``),
        ``squareness_projected_rad`` (the same measured on the noise-free
        readings), ``measurand_rad`` (Eq. 4: ``alpha_eff + beta``, where
        ``alpha_eff`` adds the straightness's local squareness on this
        circle), ``squareness_without_transients_rad`` (the closed form
        with lost motion, spikes and friction-rung modes taken out: what an
        analysis that rejects the reversals aims at), ``eps_c_rad`` (sensor
        x axis), ``eps_c_mean_rad`` (mean
        misalignment of the sensor's axes from the machine's:
        ``eps_c + (beta - alpha) / 2``), and per-effect detail.
    """
    effects = _coerce(Effects, effects)
    sensor = _coerce(Sensor, sensor)
    motion = _coerce(Motion, motion)
    rng = np.random.default_rng(seed)
    dt_ns = 1e9 / sensor.rate_hz
    if abs(dt_ns - round(dt_ns)) > 1e-6:
        raise ValueError(f"sensor.rate_hz must give whole nanoseconds, got {sensor.rate_hz!r}")
    dt_ns = round(dt_ns)
    path = CommandedPath(program, motion)
    dt_true = dt_ns * 1e-9 / (1.0 + sensor.clock_error)
    m = int(motion.oversample)
    n_samples = math.floor(path.duration_s / dt_true) + 1
    n_fine = (n_samples - 1) * m + 1
    t = np.arange(n_fine) * (dt_true / m)
    state = simulate_machine(path, effects, t)
    nx, ny = sensor_axes(sensor)
    f = state.specific_force
    clean = np.column_stack([f @ nx, f @ ny])
    if sensor.bandwidth_hz:
        sos = signal.butter(2, sensor.bandwidth_hz, fs=m / dt_true, output="sos")
        clean = signal.sosfilt(sos, clean, axis=0)
    # truth: fundamental of the noise-free readings, before gains (common per channel)
    per_feed = []
    for feed, speed in enumerate(program.feeds):
        omega = speed / program.radius_m
        exp = [
            expected_phasors(effects, sensor, omega, s, program.radius_m, program.centre_m)
            for s in (1, -1)
        ]
        proj = project_fundamental(t, clean, path, feed)
        entry = {"feed_m_per_s": speed, "omega_rad_s": omega}
        entry["expected"] = _direction_summary(exp)
        if "ccw" in proj and "cw" in proj:
            entry["projected"] = _direction_summary((proj["ccw"], proj["cw"]))
        per_feed.append(entry)
    gains = np.array([1 + sensor.gain_x, 1 + sensor.gain_y])
    tilt = G_STANDARD * np.array([sensor.tilt_x_rad, sensor.tilt_y_rad])
    xy = clean[::m] * gains + tilt
    z = np.full(n_samples, G_STANDARD * (1 + sensor.gain_z))
    accel = np.column_stack([xy, z])
    noise = sensor_noise(sensor, n_samples, rng)
    accel = accel + noise
    if math.isfinite(sensor.range_m_s2):
        accel = np.clip(accel, -sensor.range_m_s2, sensor.range_m_s2)
    if sensor.resolution_m_s2 > 0:
        accel = np.round(accel / sensor.resolution_m_s2) * sensor.resolution_m_s2
    keep = _lost_mask(sensor, n_samples, rng)
    seq = np.arange(n_samples, dtype=np.int64)
    time_ns = sensor.clock_origin_ns + seq * dt_ns
    scale = 1e9 * (1.0 + sensor.clock_error)

    def clock(tt):
        return round(sensor.clock_origin_ns + tt * scale + sensor.event_delay_s * 1e9)

    events = []
    for b in path.blocks:
        events.append(Event(clock(b.t_start_s), "block_start", b.direction, b.index))
        events.append(Event(clock(b.t_end_s), "block_end", b.direction, b.index))
    kept = np.flatnonzero(keep)
    jumps = np.diff(kept)
    gap_list = []
    for i in np.flatnonzero(jumps > 1):
        lost = int(jumps[i] - 1)
        after = int(kept[i + 1])
        gap_list.append((after, lost))
        events.append(
            Event(
                int(time_ns[after]), "gap", detail=f"lost={lost},lost_s={lost * dt_ns * 1e-9:.6f}"
            )
        )
    rec = Recording(
        accel=accel[kept].astype(np.float32),
        time_ns=time_ns[kept],
        seq=seq[kept],
        dt_ns=dt_ns,
        program=program,
        sensor=SensorInfo(
            model="indgen",
            serial=f"seed-{seed}",
            noise_density_m_s2_rthz=(
                sensor.noise_density_m_s2_rthz if sensor.state_noise_density else float("nan")
            ),
            range_m_s2=sensor.range_m_s2 if math.isfinite(sensor.range_m_s2) else float("nan"),
            resolution_m_s2=sensor.resolution_m_s2 or float("nan"),
        ),
        machine_id="indgen",
        events=events,
        metadata={"generator": "tests/independent/generator.py", "seed": str(seed)},
    )
    truth = _truth(program, effects, sensor, motion, path, state, per_feed, seed)
    truth["samples"] = {
        "n_generated": n_samples,
        "n_kept": int(kept.size),
        "lost": int(n_samples - kept.size),
        "gaps": gap_list,
        "dt_ns": dt_ns,
        "dt_true_s": dt_true,
        "clipped": int(np.sum(np.abs(accel) >= sensor.range_m_s2)),
    }
    return rec, truth


def _truth(program, effects, sensor, motion, path, state, per_feed, seed):
    alpha, beta, eps = effects.squareness_rad, sensor.nonorthogonality_rad, sensor.eps_c_rad
    fx, fy = fundamental_geometry(effects, program.centre_m, program.radius_m)
    local = float(fx.imag - fy.real)
    first = per_feed[0]
    exact_geom = math.atan2(
        math.sin(eps + beta), math.cos(eps + beta) + alpha * math.sin(eps + beta)
    ) - math.atan(math.tan(eps) - alpha)
    truth = {
        "seed": seed,
        "program": program.as_dict(),
        "effects": _plain(effects),
        "sensor": _plain(sensor),
        "motion": _plain(motion),
        "squareness_rad": alpha,
        "sensor_nonorthogonality_rad": beta,
        "straightness_local_squareness_rad": local,
        "measurand_rad": alpha + local + beta,
        "squareness_geometric_exact_rad": exact_geom,
        "squareness_expected_rad": first["expected"]["theta_diff_rad"],
        "squareness_projected_rad": first.get("projected", {}).get("theta_diff_rad", math.nan),
        "squareness_without_transients_rad": _without_transients(program, effects, sensor),
        "servo_mismatch_expected_rad": first["expected"]["servo_mismatch_rad"],
        "servo_lag_difference_rad": _servo_lag_difference(
            effects, program.feeds[0] / program.radius_m
        ),
        "eps_c_rad": eps,
        "eps_c_mean_rad": eps + (beta - alpha) / 2.0,
        "per_feed": per_feed,
        "amplitude_m_s2": [v**2 / program.radius_m for v in program.feeds],
        "ramp_inside_overshoot": bool(path.ramp_inside_overshoot),
        "blocks": [
            {
                "index": b.index,
                "direction": b.direction,
                "feed": b.feed,
                "t_start_s": b.t_start_s,
                "t_end_s": b.t_end_s,
                "t_analysed_s": list(b.t_analysed_s),
                "phi_start_rad": b.phi_start_rad,
                "phi_end_rad": b.phi_end_rad,
            }
            for b in path.blocks
        ],
        "reversals": {
            k: {"times_s": v["times"].tolist(), "new_sign": v["new_sign"].tolist()}
            for k, v in state.reversals.items()
        },
        "effects_present": sorted(_present(effects)),
        "per_effect": _per_effect(program, effects, sensor),
    }
    return truth


def _without_transients(program, effects, sensor):
    """Closed-form ``theta_y - theta_x`` with the reversal transients taken out. [rad]

    Lost motion, friction spikes and friction-rung modes live at the axis
    reversals; an analysis that rejects the reversals (a robust fit) aims at
    this value rather than at the least-squares fundamental
    (``squareness_expected_rad``). The two differ by the transients' share of
    the fundamental, mostly an amplitude change seen through the sensor
    rotation (``-2 eps_c dA/A``).
    """
    quiet = replace(
        effects,
        spikes=[],
        lost_motion_x=LostMotion(),
        lost_motion_y=LostMotion(),
        mode_x=effects.mode_x and replace(effects.mode_x, friction_m_s2=0.0),
        mode_y=effects.mode_y and replace(effects.mode_y, friction_m_s2=0.0),
    )
    omega = program.feeds[0] / program.radius_m
    pair = [
        expected_phasors(quiet, sensor, omega, s, program.radius_m, program.centre_m)
        for s in (1, -1)
    ]
    return _direction_summary(pair)["theta_diff_rad"]


def _servo_lag_difference(effects, omega):
    """``arg H_x - arg H_y`` at the circle frequency: ``omega (d_y - d_x) + atan(omega tau_y)
    - atan(omega tau_x)``, the servos' own phase mismatch. [rad]

    ``servo_mismatch_expected_rad`` (half the CCW minus CW difference of
    ``theta_y - theta_x``) equals it times ``cos(2 eps_c)`` to first order, plus
    whatever else flips with the direction (lost motion, the spikes' asymmetry,
    the modes' damping).
    """
    sx, sy = effects.servo_x, effects.servo_y
    return (
        omega * (sy.delay_s - sx.delay_s)
        + math.atan(omega * sy.tau_s)
        - math.atan(omega * sx.tau_s)
    )


def _isolated(effects):
    """``(name, Effects with only that effect)`` for every effect switched on."""
    base = {"kinematics": effects.kinematics}
    out = []
    if effects.squareness_rad:
        out.append(("squareness", {"squareness_rad": effects.squareness_rad}))
    for n in "xy":
        for key in ("servo", "lost_motion", "mode", "straightness", "cyclic"):
            value = getattr(effects, f"{key}_{n}")
            if value is not None and value != type(value)():
                out.append((f"{key}_{n}", {f"{key}_{n}": value}))
        if getattr(effects, f"scale_{n}"):
            out.append((f"scale_{n}", {f"scale_{n}": getattr(effects, f"scale_{n}")}))
    for k, sp in enumerate(effects.spikes):
        if sp.height_m:
            out.append((f"spike_{k}_{sp.axis}_{sp.shape}", {"spikes": [sp]}))
    if np.any(np.asarray(effects.tilt_gradient_rad_m)):
        out.append(("gravity", {"tilt_gradient_rad_m": effects.tilt_gradient_rad_m}))
    return [(name, Effects(**base, **kw)) for name, kw in out]


def _per_effect(program, effects, sensor):
    """Each effect alone: its parameters and its closed-form shift of the phases.

    The shifts are at the program's first feed, against the same sensor on a
    perfect machine: ``theta_diff_shift_rad`` (CCW and flipped CW averaged),
    ``servo_mismatch_shift_rad`` (half CCW minus CW) and ``theta_x_shift_rad``
    (the time-reference phase, CCW).
    """
    omega = program.feeds[0] / program.radius_m
    args = (omega, program.radius_m, program.centre_m)

    def summary(eff):
        pair = [expected_phasors(eff, sensor, args[0], s, args[1], args[2]) for s in (1, -1)]
        return _direction_summary(pair)

    ref = summary(Effects(kinematics=effects.kinematics))
    out = {}
    for name, eff in _isolated(effects):
        got = summary(eff)
        entry = {
            "theta_diff_shift_rad": got["theta_diff_rad"] - ref["theta_diff_rad"],
            "servo_mismatch_shift_rad": got["servo_mismatch_rad"] - ref["servo_mismatch_rad"],
            "theta_x_shift_rad": got["theta_x_ccw_rad"] - ref["theta_x_ccw_rad"],
            "amp_ratio_y_x": got["amp_ratio_y_x"],
        }
        if name.startswith("spike_"):
            sp = eff.spikes[0]
            lead = 2.0 * sp.width_s if sp.lead_s is None else sp.lead_s
            entry["area_m_s"] = (
                sp.height_m * spike_fourier(sp.shape, sp.width_s, lead, sp.comp_ratio, 0.0).real
            )
        if name.startswith("lost_motion_"):
            lm = getattr(eff, name)
            entry["travel_change_m"] = -lm.lost_motion_m
        if name.startswith("mode_"):
            md = getattr(eff, name)
            entry["damped_freq_hz"] = md.freq_hz * math.sqrt(max(1 - md.zeta**2, 0.0))
        if name == "gravity":
            k = np.asarray(effects.tilt_gradient_rad_m, dtype=float)
            entry["first_order_shift_rad"] = G_STANDARD / omega**2 * (k[0, 1] + k[1, 0])
        out[name] = _plain(entry)
    return out


def _present(effects):
    """Names of the effects that are switched on."""
    out = set()
    if effects.squareness_rad:
        out.add("squareness")
    for n in "xy":
        s = getattr(effects, f"servo_{n}")
        if s.delay_s or s.tau_s:
            out.add("servo")
        if getattr(effects, f"lost_motion_{n}").lost_motion_m:
            out.add("lost_motion")
        if getattr(effects, f"mode_{n}") is not None:
            out.add("vibration")
        if getattr(effects, f"scale_{n}"):
            out.add("scale")
        if getattr(effects, f"cyclic_{n}").amplitude_m:
            out.add("cyclic")
        st = getattr(effects, f"straightness_{n}")
        if st.quadratic_m or st.quartic_m:
            out.add("straightness")
    for sp in effects.spikes:
        if sp.height_m:
            out.add(f"spike_{sp.shape}")
    if np.any(np.asarray(effects.tilt_gradient_rad_m)):
        out.add("gravity")
    return out
