"""A program's motion on LinuxCNC: from the cache, or from a run."""

import hashlib

from imu_square.linuxcnc.cache import load_samples, motion_key, store_samples
from imu_square.linuxcnc.configuration import default_configuration
from imu_square.linuxcnc.runner import linuxcnc_version, run_on_linuxcnc
from imu_square.linuxcnc.samples import block_spans
from imu_square.program.ncgen import START_DWELL_S, generate_nc
from imu_square.simulate.sampled_motion import SampledMotion

# The user M-code of the block markers in the program run on LinuxCNC.
MARKER_MCODE = 101


def linuxcnc_motion(program, configuration=None, *, use_cache=True, progress=None):
    """The motion LinuxCNC's trajectory planner commands for a program.

    The program runs as ``imu-square program --dialect linuxcnc --marker-mcode
    101`` writes it, on the project's simulated machining centre by default.

    Parameters
    ----------
    program : TestProgram
        The test program.
    configuration : Configuration, optional
        The LinuxCNC configuration (:func:`default_configuration` if None).
    use_cache : bool
        Take the motion from the cache when it holds it, and keep a new run's
        there (:mod:`imu_square.linuxcnc.cache`).
    progress : callable, optional
        Called with a line of text about the run or the cache.

    Returns
    -------
    SampledMotion
        Its ``source`` names LinuxCNC's version, the configuration and the NC
        program's SHA-256.

    Raises
    ------
    ControllerError
        LinuxCNC is not installed (one line says how to install it), cannot
        run the program, or ran something else.
    """
    say = progress or (lambda text: None)
    configuration = configuration or default_configuration()
    nc = generate_nc(program, "linuxcnc", marker_mcode=MARKER_MCODE)
    key = motion_key(nc, configuration.digest(), linuxcnc_version())
    samples = load_samples(key) if use_cache else None
    if samples is None:
        duration = program.duration_s + max(program.dwell_s, START_DWELL_S)
        samples = run_on_linuxcnc(nc, configuration, MARKER_MCODE, duration, say)
        samples.source["nc_sha256"] = hashlib.sha256(nc.encode()).hexdigest()
        if use_cache:
            say(f"kept LinuxCNC's motion in {store_samples(key, samples)}")
    else:
        say(f"LinuxCNC's motion of this program from the cache ({key[:12]})")
    return SampledMotion(samples, program, block_spans(samples.markers, program.n_blocks))
