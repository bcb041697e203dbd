"""What an axis drive adds at its reversals: backlash, friction spikes, vibration.

Each effect is a function of the time since each reversal of the axis, with
exact first and second derivatives, added to the axis position. ``d`` is the
direction of motion after the reversal (+1 or -1), ``t'`` the time since it.

- backlash ``b``: the axis lags the command by ``b/2`` against its direction of
  motion, taken up smoothly: offset ``-(b/2) D(t)``, where ``D`` steps from the
  old to the new direction along ``(1 + tanh(t'/tau_b)) / 2``. The take-up
  is centred on the reversal shifted by ``o_b tau_b`` (``o_b = 0``: half of
  it happens before the commanded reversal, an acausal smooth stand-in; ``o_b``
  of 2 or more: the take-up starts at the reversal, as a play operator's
  does); ``b`` is signed (negative: over-compensated, the table is thrown
  ahead); the reversal times in the truth are the commanded ones;
- reversal spike: following-error bump ``-d h u^2 exp(-u)``, ``u = t'/tau_s - o``,
  whose acceleration starts at the peak ``2 h / tau_s^2`` and has zero area;
  ``h`` is signed (negative: inward, an over-set friction compensation) and the
  onset ``o`` (in ``tau_s``) places it after the reversal (0), centred on it
  (-2: the position peak on the reversal) or leading it (below -2). This
  skewed bump is friction building up after the reversal. Its symmetric
  form is a stick zone around the reversal: through a reversal at
  acceleration ``a_r`` the commanded velocity is ``d a_r t'``; a table that
  keeps only ``1 - k sech^2(t'/tau_s)`` of it lags by an error whose
  velocity, ``-k d a_r t' sech^2``, is odd in time, so the error is the even
  bump ``-d A tau_s^2 g(s)``, ``g = ln 2 + ln cosh s - s tanh s >= 0``, back
  to zero on both sides, with ``A = -k a_r`` (a full stick, ``k = 1``, stops
  the table at the reversal: inward). Its acceleration is largest at the
  centre, ``|A|``; ``s = u - 2`` puts its peak where the skewed bump's is;
- structural vibration: ``-d D exp(-sigma t') (1 - cos(omega_d t'))``, which
  starts with zero position and velocity and acceleration ``D omega_d^2``.
  The same mode is also rung at the corners of each block's feed ramps,
  where the acceleration steps (:func:`add_start_stop_vibration`).
"""

import numpy as np

# Beyond these multiples of their time constants the effects are below 1e-15
# of their size and are dropped (backlash becomes an exact step).
_TANH_WINDOW = 20.0
_SPIKE_WINDOW = 45.0
_SYMMETRIC_WINDOW = 20.0  # either side of the centre: (1 + 2 s) exp(-2 s) < 1e-15
_VIBRATION_DECAY = 35.0


# The ramps' ringing is sized this long after the corner, where a recording shows it (past
# the ramp's own transient): sized at the corner, its size would trade against its damping.
RAMP_RING_SIZED_AT_S = 0.03


def _window(t, start, stop):
    return slice(*np.searchsorted(t, (start, stop), side="left"))


def add_backlash(p, t, times, directions, initial, lost_m, take_up_s, onset=0.0):
    """Add backlash to an axis path in place.

    Parameters
    ----------
    p : list of 3 ndarray
        Axis position, velocity, acceleration, modified in place. [m, m/s, m/s^2]
    t : ndarray, shape (n,)
        True times, increasing. [s]
    times, directions : ndarray
        Reversal times [s] and the direction after each.
    initial : int
        Direction before the first reversal.
    lost_m : float
        Lost motion b. [m]
    take_up_s : float
        Time constant tau_b of the take-up. [s]
    onset : float
        Centre of the take-up after the reversal, in units of ``take_up_s``.
    """
    if lost_m == 0:
        return
    times = np.asarray(times) + onset * take_up_s
    previous = np.concatenate(([initial], directions[:-1])) if len(directions) else []
    # D(t): the direction steps after each take-up window, smooth inside it
    steps = np.zeros(len(t) + 1)
    windows = []
    for tk, dk, dprev in zip(times, directions, previous, strict=True):
        sl = _window(t, tk - _TANH_WINDOW * take_up_s, tk + _TANH_WINDOW * take_up_s)
        steps[sl.stop] += dk - dprev
        windows.append((sl, tk, dk - dprev))
    state = initial + np.cumsum(steps[:-1])
    for sl, tk, jump in windows:
        th = np.tanh((t[sl] - tk) / take_up_s)
        sech2 = 1.0 - th * th
        state[sl] += jump * 0.5 * (1.0 + th)
        p[1][sl] += -0.5 * lost_m * jump * sech2 / (2.0 * take_up_s)
        p[2][sl] += -0.5 * lost_m * jump * (-th * sech2 / take_up_s**2)
    p[0] += -0.5 * lost_m * state


def add_spikes(p, t, times, directions, peak_m_s2, tau_s, onset=0.0, symmetric=False):
    """Add friction following-error bumps at each reversal, in place.

    Parameters
    ----------
    p : list of 3 ndarray
        Axis position, velocity, acceleration, modified in place.
    t : ndarray, shape (n,)
        True times, increasing. [s]
    times, directions : ndarray
        Reversal times [s] and the direction after each.
    peak_m_s2 : float
        Largest acceleration of the bump: ``2 h / tau_s^2`` at the skewed
        bump's start, ``|A|`` at the symmetric bump's centre; positive
        outward (the position bump against the new direction). [m/s^2]
    tau_s : float
        Time constant of the bump. [s]
    onset : float
        Start of the skewed bump after the reversal, in units of ``tau_s``
        (negative: before); the position peak of either form is at
        ``(onset + 2) tau_s``.
    symmetric : bool
        The stick zone's even bump instead of the friction build-up's skewed one.
    """
    if peak_m_s2 == 0:
        return
    if symmetric:
        _add_symmetric_spikes(p, t, times, directions, peak_m_s2, tau_s, onset + 2.0)
        return
    h = 0.5 * peak_m_s2 * tau_s**2
    for tk, dk in zip(times, directions, strict=True):
        tk = tk + onset * tau_s
        sl = _window(t, tk, tk + _SPIKE_WINDOW * tau_s)
        u = (t[sl] - tk) / tau_s
        e = -dk * h * np.exp(-u)
        p[0][sl] += e * u * u
        p[1][sl] += e * (2.0 * u - u * u) / tau_s
        p[2][sl] += e * (2.0 - 4.0 * u + u * u) / tau_s**2


def _add_symmetric_spikes(p, t, times, directions, peak_m_s2, tau_s, centre):
    for tk, dk in zip(times, directions, strict=True):
        tk = tk + centre * tau_s
        sl = _window(t, tk - _SYMMETRIC_WINDOW * tau_s, tk + _SYMMETRIC_WINDOW * tau_s)
        s = (t[sl] - tk) / tau_s
        # in q = exp(-2|s|), exact in the tails: g = 2|s| q / (1 + q) + log1p(q)
        q = np.exp(-2.0 * np.abs(s))
        sech2 = 4.0 * q / (1.0 + q) ** 2
        th = np.tanh(s)
        a = -dk * peak_m_s2
        p[0][sl] += a * tau_s**2 * (2.0 * np.abs(s) * q / (1.0 + q) + np.log1p(q))
        p[1][sl] += a * tau_s * (-s * sech2)
        p[2][sl] += a * (-sech2 * (1.0 - 2.0 * s * th))


def add_vibration(p, t, times, directions, accel_m_s2, frequency_hz, damping, sized_at_s=0.0):
    """Add a damped oscillation of the axis excited at each reversal, in place.

    Parameters
    ----------
    p : list of 3 ndarray
        Axis position, velocity, acceleration, modified in place.
    t : ndarray, shape (n,)
        True times, increasing. [s]
    times, directions : ndarray
        Reversal times [s] and the direction after each.
    accel_m_s2 : float
        Acceleration amplitude ``D omega_d^2``, ``sized_at_s`` after the excitation. [m/s^2]
    frequency_hz : float
        Natural frequency. [Hz]
    damping : float
        Damping ratio, in (0, 1).
    sized_at_s : float
        When the amplitude is taken (0: the initial acceleration). [s]
    """
    if accel_m_s2 == 0:
        return
    wn = 2.0 * np.pi * frequency_hz
    sigma = damping * wn
    wd = wn * np.sqrt(1.0 - damping**2)
    amp = accel_m_s2 / wd**2
    for tk, dk in zip(times, directions, strict=True):
        sl = _window(t, tk, tk + _VIBRATION_DECAY / sigma)
        tau = t[sl] - tk
        e = -dk * amp * np.exp(-sigma * (tau - sized_at_s))
        c, s = np.cos(wd * tau), np.sin(wd * tau)
        p[0][sl] += e * (1.0 - c)
        p[1][sl] += e * (-sigma + sigma * c + wd * s)
        p[2][sl] += e * (sigma**2 + (wd**2 - sigma**2) * c - 2.0 * sigma * wd * s)


def add_start_stop_vibration(
    p, t, times, components, accel_m_s2, frequency_hz, damping, quadrature_m_s2=0.0
):
    """Add the structural mode rung at the corners of the feed ramps, in place.

    The feed ramps step the acceleration along the direction of motion at
    their corners (up at the start of motion and at the end of the stop ramp,
    down at the end of the start ramp and at the start of the stop ramp); the
    mode answers each step with the reversal's oscillation
    (:func:`add_vibration`) along the step. A ramp of constant jerk rings it
    a quarter period later: the quadrature, from the position
    ``(Q' / omega_d^2) exp(-sigma t') (omega_d t' - sin omega_d t')``, which
    starts with zero position, velocity and acceleration and the jerk
    ``Q' omega_d``; its acceleration is ``Q' exp(-sigma t') sin(omega_d t')``
    to within a part that does not oscillate, of order ``2 zeta Q'`` (the
    price of a position that comes back to rest). Together the two ring at
    any phase: a controller's ramp, of its own shape and length, rings the
    mode at its own. Both are sized :data:`RAMP_RING_SIZED_AT_S` after the
    corner: ``Q' = Q exp(sigma RAMP_RING_SIZED_AT_S)``, and so for the
    in-phase part.

    Parameters
    ----------
    p : list of 3 ndarray
        Axis position, velocity, acceleration, modified in place.
    t : ndarray, shape (n,)
        True times, increasing. [s]
    times : ndarray, shape (n_events,)
        The ramps' corners, as the axis runs them. [s]
    components : ndarray, shape (n_events,)
        This axis's component of the unit direction of the step at each.
    accel_m_s2 : float
        Amplitude of the in-phase (cosine) oscillation along the direction of
        motion, :data:`RAMP_RING_SIZED_AT_S` after the corner. [m/s^2]
    frequency_hz : float
        Natural frequency. [Hz]
    damping : float
        Damping ratio, in (0, 1).
    quadrature_m_s2 : float
        ``Q``: amplitude of the quadrature (sine) oscillation along the step,
        as long after the corner. [m/s^2]
    """
    at = RAMP_RING_SIZED_AT_S
    add_vibration(p, t, times, -np.asarray(components), accel_m_s2, frequency_hz, damping, at)
    if quadrature_m_s2 == 0:
        return
    wn = 2.0 * np.pi * frequency_hz
    sigma = damping * wn
    wd = wn * np.sqrt(1.0 - damping**2)
    amp = quadrature_m_s2 / wd**2
    for tk, ck in zip(times, components, strict=True):
        sl = _window(t, tk, tk + _VIBRATION_DECAY / sigma)
        tau = t[sl] - tk
        e = ck * amp * np.exp(-sigma * (tau - at))
        g = wd * tau - np.sin(wd * tau)
        dg = wd * (1.0 - np.cos(wd * tau))
        ddg = wd**2 * np.sin(wd * tau)
        p[0][sl] += e * g
        p[1][sl] += e * (dg - sigma * g)
        p[2][sl] += e * (ddg - 2.0 * sigma * dg + sigma**2 * g)
