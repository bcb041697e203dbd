"""The speed the circles ran at: the program's, or the one the controller chose.

A controller may run an arc slower than programmed: LinuxCNC keeps the normal
acceleration of an arc within sqrt(3)/2 of its axes' acceleration limit, so a
25 mm circle programmed at 30,000 mm/min on 10 m/s^2 axes runs at 27,918
mm/min, 7.5 % longer a turn. The analysis maps time to position angle with the
period it measures (:mod:`imu_square.pipeline.segment`), so such a run is as
good as any; what must be told apart is a wrong sample clock, under which the
circles only *seem* to take longer.

The amplitude tells them apart. Circles that really ran at the measured angular
speed ``omega`` have the amplitude ``omega^2 r``; a sample clock that is off
stretches the time axis but leaves the amplitude at the program's ``v^2/r``.
So when the measured period departs from the program's by more than
:data:`~imu_square.pipeline.quality.PERIOD_LIMIT`:

- an amplitude within :data:`~imu_square.pipeline.quality.AMPLITUDE_FLAG` of
  ``omega^2 r`` means the circles ran at that speed: the run is analysed at the
  measured period, and a warning says so;
- otherwise the run is refused, as before: the feed override or the sensor's
  sample rate must be checked.

Within the period limit nothing changes: the amplitude is compared with the
program's ``v^2/r``.
"""

from dataclasses import dataclass

from imu_square.pipeline import quality as q


@dataclass(frozen=True)
class CircleSpeed:
    """The circles' speed as the analysis takes it.

    Attributes
    ----------
    period_disagreement : float
        Measured period over the program's, minus 1.
    amplitude_ratio : float
        Measured amplitude over that of the circle taken: ``v^2/r`` of the
        program, or ``omega^2 r`` of the measured speed.
    measured : bool
        Whether the circle is taken at the measured speed (the controller ran
        the arcs at another speed than programmed).
    feed_run_mm_per_min : float
        The feed the circles ran at, ``omega r``. [mm/min]
    """

    period_disagreement: float
    amplitude_ratio: float
    measured: bool
    feed_run_mm_per_min: float

    def warning(self, program):
        """The line that says the circles ran at another speed, or None."""
        if not self.measured:
            return None
        return (
            f"the circles ran at {self.feed_run_mm_per_min:.0f} mm/min, not the programmed "
            f"{program.feed_m_per_s * 6e4:.0f} (period {self.period_disagreement:+.1%}; the "
            f"amplitude, {self.amplitude_ratio:.3f} x omega^2 r, confirms the speed): the "
            f"control ran the arcs slower or faster than programmed (its acceleration limit or "
            f"the feed override); analysed at the measured period"
        )


def circle_speed(seg, amplitude_m_s2, program):
    """Take the program's circle or the measured one; refuse when neither fits.

    Parameters
    ----------
    seg : Segmentation
        The blocks found, with the measured angular speed.
    amplitude_m_s2 : float
        Fitted amplitude, mean of both axes. [m/s^2]
    program : TestProgram
        The program the machine ran.

    Returns
    -------
    CircleSpeed

    Raises
    ------
    AnalysisError
        The period departs from the program's beyond the limit and the
        amplitude does not confirm the measured speed (a sample clock error or
        a feed override that the amplitude contradicts); or the amplitude is
        far from the circle's.
    """
    omega = abs(seg.omega_rad_s)
    feed_run = omega * program.radius_m * 6e4
    disagreement = float(seg.period_disagreement)
    if abs(disagreement) > q.PERIOD_LIMIT:
        run_ratio = amplitude_m_s2 / (omega**2 * program.radius_m)
        if abs(run_ratio - 1) > q.AMPLITUDE_FLAG:
            q.check_period(disagreement, seg.period_s, program)
        return CircleSpeed(disagreement, float(run_ratio), True, feed_run)
    return CircleSpeed(disagreement, q.check_amplitude(amplitude_m_s2, program), False, feed_run)
