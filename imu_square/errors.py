"""The project's one error tree and one warning class.

Every user mistake raises a subclass of :class:`ImuSquareError` whose message
names the file or parameter, what was allowed and what was received. The CLI
prints such an error as one line on stderr and exits non-zero.
"""

from contextlib import contextmanager


class ImuSquareError(Exception):
    """Base class of every error a user can cause."""


class ProgramError(ImuSquareError):
    """The test program (TOML) is malformed or physically implausible."""


class RecordingError(ImuSquareError):
    """A recording file is missing, corrupt, truncated or in the wrong units."""


class ConfigError(ImuSquareError):
    """A machine or sensor description (TOML) is malformed."""


class MonitorConfigError(ConfigError):
    """The monitor file (TOML) is malformed: a field names something impossible."""


class MonitorError(ImuSquareError):
    """The monitor cannot write one of its own files (metrics, alert outbox)."""


class AnalysisError(ImuSquareError):
    """The data cannot give a trustworthy squareness (too few cycles, no motion, ...)."""


class AcquisitionError(ImuSquareError):
    """The serial link or the device misbehaved in a way the recorder cannot absorb."""


class ControllerError(ImuSquareError):
    """A CNC controller (LinuxCNC) is missing, cannot run the program, or ran something else."""


class HistoryError(ImuSquareError):
    """The monitor's history cannot be opened, read or written as asked."""


class OutputError(ImuSquareError):
    """An output file cannot be written where asked (no such folder, a directory, no room)."""


class OutputWriteError(OutputError):
    """Writing an output file failed part-way (disk full, I/O error).

    What was flushed before the failure stays in the file; the CLI exits with
    its own code (4) so a script can tell this from a user's mistake.
    """


class ImuSquareWarning(UserWarning):
    """A recoverable oddity: the result is still produced, but say so."""


@contextmanager
def step(name, error=ImuSquareError):
    """Run one step of a command: an unexpected numerical failure in it is one line naming it.

    A library's ``OverflowError``, ``ZeroDivisionError``, ``ValueError`` or
    ``LinAlgError`` out of a computation (an extreme input no check foresaw)
    must not end a nightly job in a traceback; the traceback stays in the
    debug log (``-v``).

    Parameters
    ----------
    name : str
        The step, e.g. ``"designing the alarm charts"``.
    error : type
        The :class:`ImuSquareError` subclass to raise.
    """
    try:
        yield
    except (ArithmeticError, ValueError) as exc:
        from imu_square.log import logger

        logger.debug("%s failed", name, exc_info=True)
        text = str(exc).strip().splitlines()[0] if str(exc).strip() else ""
        raise error(f"{name} failed: {type(exc).__name__}: {text}") from exc
