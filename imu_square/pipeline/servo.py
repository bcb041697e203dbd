"""What the servos leave in ``theta_y - theta_x`` at one feed: a bound.

Servo lags flip sign with the direction and cancel in the mean of CCW and
flipped CW (``docs/model.md``). Their *amplitude* does not: a servo that
behaves as a first-order loop ``1 / (1 + s tau)`` shrinks its axis's circle
by ``1 / sqrt(1 + (omega tau)^2)``, and axes of different ``tau`` trace an
ellipse. Seen through sensor axes turned by ``eps_c`` the ellipse adds

    b = (A_x - A_y) / A sin(2 eps_c) = m (omega tau_mean) sin(2 eps_c)

to ``theta_y - theta_x`` (to leading order, with ``m = omega (tau_y -
tau_x)`` the servo mismatch, ``tau_mean = (tau_x + tau_y) / 2``), the same in
both directions. It grows as ``omega^2``; a sensor's gain mismatch, seen in the
same fitted amplitudes, does not, so two feeds separate them. At one feed
``m`` and ``eps_c`` are measured but ``tau_mean`` is not: the anchor at the
middle of the motion absorbs every common delay. The measured amplitude bounds
it, since ``A = (1 + g) v^2 / r (1 - omega^2 (tau_x^2 + tau_y^2) / 4)`` with
``g`` the sensor's mean gain error: for ``|g| <= gain_tolerance``,

    omega tau_mean <= sqrt(2 (1 - A / (omega^2 r) + gain_tolerance)),

and ``b`` lies between 0 and ``m sin(2 eps_c)`` times that. Pure lags
(feed-forward servos) give ``b = 0``; a first-order servo is the case that
shrinks the circle most for its phase lag, so the bound holds for either.
"""

import math


def servo_amplitude_bound(servo_mismatch_rad, eps_c_rad, amplitude_ratio, gain_tolerance):
    """Signed bound of the servos' amplitude share of ``theta_y - theta_x``.

    Parameters
    ----------
    servo_mismatch_rad : float
        Measured servo mismatch ``m``. [rad]
    eps_c_rad : float
        Measured sensor rotation. [rad]
    amplitude_ratio : float
        Fitted amplitude over ``omega^2 r`` with the measured ``omega`` and
        the programmed radius.
    gain_tolerance : float
        Largest relative error of the sensor's mean x/y gain.

    Returns
    -------
    float
        ``b_max``: the share lies between 0 and ``b_max`` (module docstring). [rad]
    """
    shrink = max(0.0, 1.0 - amplitude_ratio) + gain_tolerance
    omega_tau = math.sqrt(2.0 * shrink)
    return servo_mismatch_rad * omega_tau * math.sin(2.0 * eps_c_rad)
