"""Checks that stop a wrong number: amplitude, period, clipping, cycles.

A measurement that cannot be trusted raises :class:`AnalysisError` with a
message a machinist can act on; an oddity that leaves the result usable
becomes a quality flag on the result, which the CLI prints.
"""

import numpy as np

from imu_square.errors import AnalysisError

# The measured amplitude must lie within this factor of v^2/r, else refuse.
AMPLITUDE_LIMIT = 1.5
# Flag when the amplitude departs from v^2/r by more than this fraction.
AMPLITUDE_FLAG = 0.05
# Refuse when the period departs from the program's by more than this fraction.
PERIOD_LIMIT = 0.05


def format_accel(value):
    """Two significant digits, trailing zeros kept: 0.4 -> '0.40'. [m/s^2]"""
    return f"{value:#.2g}" if abs(value) < 100 else f"{value:.0f}"


def check_amplitude(measured_m_s2, program):
    """Refuse an amplitude far from ``v^2/r``.

    Parameters
    ----------
    measured_m_s2 : float
        Fitted amplitude, mean of both axes. [m/s^2]
    program : TestProgram
        The program the machine ran.

    Returns
    -------
    float
        Ratio of the measured amplitude to ``v^2/r``.

    Raises
    ------
    AnalysisError
        If the ratio is outside ``[1/AMPLITUDE_LIMIT, AMPLITUDE_LIMIT]``.
    """
    implied = program.centripetal_m_s2
    ratio = measured_m_s2 / implied
    if not 1 / AMPLITUDE_LIMIT <= ratio <= AMPLITUDE_LIMIT:
        raise AnalysisError(
            f"measured {format_accel(measured_m_s2)} m/s² but the program implies "
            f"{format_accel(implied)} m/s²: check the feed, the radius or the units"
        )
    return float(ratio)


def check_period(disagreement, measured_s, program):
    """Refuse a circle period far from the program's.

    Parameters
    ----------
    disagreement : float
        Measured period over the program's, minus 1.
    measured_s : float
        Measured period. [s]
    program : TestProgram
        The program the machine ran.

    Raises
    ------
    AnalysisError
        If ``|disagreement| > PERIOD_LIMIT``.
    """
    if abs(disagreement) > PERIOD_LIMIT:
        raise AnalysisError(
            f"the circles take {measured_s:.3f} s but the program implies "
            f"{program.period_s:.3f} s ({disagreement:+.1%}): check the feed override "
            f"or the sensor's sample rate"
        )


def clipped_times(t_s, accel, range_m_s2):
    """Times of samples at or beyond the sensor's full scale.

    Parameters
    ----------
    t_s : ndarray, shape (n_samples,)
        Sample times. [s]
    accel : ndarray, shape (n_samples, 3)
        Raw acceleration. [m/s^2]
    range_m_s2 : float
        Full-scale range; NaN when unknown (then nothing is flagged). [m/s^2]

    Returns
    -------
    ndarray
        Times of clipped samples. [s]
    """
    if not np.isfinite(range_m_s2):
        return np.empty(0)
    hit = np.any(np.abs(accel) >= 0.999 * range_m_s2, axis=1)
    return t_s[hit]


def check_cycles(n_ccw, n_cw, program, min_cycles, dropped):
    """Refuse too few usable cycles in either direction.

    Parameters
    ----------
    n_ccw, n_cw : int
        Usable cycles per direction.
    program : TestProgram
        The program.
    min_cycles : int
        Least usable cycles per direction.
    dropped : sequence of dict
        The dropped cycles with their reasons.

    Raises
    ------
    AnalysisError
    """
    if min(n_ccw, n_cw) < min_cycles:
        reasons = sorted({d["reason"] for d in dropped})
        why = f"; dropped: {', '.join(reasons)}" if reasons else ""
        raise AnalysisError(
            f"too few usable cycles: {n_ccw} CCW and {n_cw} CW of "
            f"{program.cycles_per_direction * program.runs} each, min_cycles={min_cycles}{why}"
        )
