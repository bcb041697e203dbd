"""Where the simulated test's commanded motion comes from: our trajectory or LinuxCNC's.

``--motion trajectory`` (the default) is our own trajectory
(:mod:`imu_square.simulate.trajectory`); ``--motion linuxcnc`` runs the program
through LinuxCNC's trajectory planner (:mod:`imu_square.linuxcnc`), or takes
that run's motion from the cache.
"""

from imu_square.validation import check_option

MOTION_SOURCES = ("trajectory", "linuxcnc")


def commanded_motion(program, source, progress=None):
    """The motion ``simulate_run`` takes for a program from a source.

    Parameters
    ----------
    program : TestProgram
        The test program.
    source : str
        One of :data:`MOTION_SOURCES`.
    progress : callable, optional
        Called with a line of text while LinuxCNC runs or the cache answers.

    Returns
    -------
    SampledMotion or None
        None for our own trajectory, which ``simulate_run`` builds itself.

    Raises
    ------
    ImuSquareError
        An unknown source; :class:`~imu_square.errors.ControllerError` when
        LinuxCNC is missing or fails.
    """
    check_option("--motion", source, MOTION_SOURCES)
    if source == "trajectory":
        return None
    from imu_square.linuxcnc import linuxcnc_motion  # starts a controller: only when asked

    return linuxcnc_motion(program, progress=progress)
