"""What ``record`` and ``nightly`` share: a recorder run under the stop signals, with progress.

SIGINT (Ctrl-C) and SIGTERM (a scheduler, ``kill``) ask the recorder to stop;
it then finishes the file, so it stays valid. The handlers, the progress
printer and its logging filter are put back as they were afterwards.
"""

import signal
import sys
from contextlib import contextmanager

from imu_square.cli import EXIT_INCOMPLETE, EXIT_OK

STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)


@contextmanager
def stop_signals(stop):
    """Call ``stop()`` on SIGINT or SIGTERM inside the block; restore the handlers after.

    Parameters
    ----------
    stop : callable
        Called with no argument from the signal handler: it must only ask
        (set an event), never block.
    """
    previous = {s: signal.signal(s, lambda *_: stop()) for s in STOP_SIGNALS}
    try:
        yield
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)


def run_recorder(recorder, *, quiet=False):
    """Run ``recorder`` to its end with progress on stderr; the stop signals end it cleanly.

    Parameters
    ----------
    recorder : Recorder
        A recorder not yet run; its progress callback is replaced.
    quiet : bool
        No progress.

    Returns
    -------
    RecorderStatus
    """
    from acquisition.progress import ProgressPrinter
    from imu_square.log import logger

    printer = ProgressPrinter(sys.stderr)
    recorder.progress = None if quiet else printer
    logger.addFilter(printer)
    try:
        with stop_signals(recorder.stop):
            return recorder.run()
    finally:
        logger.removeFilter(printer)
        printer.close()


def report(path, status):
    """Say on stderr how the recording went; return the exit code it calls for.

    Parameters
    ----------
    path : str or Path
        The recording.
    status : RecorderStatus
        The recorder's final status.

    Returns
    -------
    int
        0 for a complete run, :data:`~imu_square.cli.EXIT_INCOMPLETE` otherwise.
    """
    from acquisition.progress import describe

    print(f"{path}: {describe(status)}; stopped: {status.stop_reason}", file=sys.stderr)
    if status.complete:
        return EXIT_OK
    print(
        f"{path}: incomplete recording (the file is valid): {'; '.join(status.problems)}",
        file=sys.stderr,
    )
    return EXIT_INCOMPLETE
