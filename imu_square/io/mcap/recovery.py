"""Rescue a cut or damaged MCAP recording: what is complete in it, written as a whole file."""

from imu_square.io.mcap.reader import scan_mcap
from imu_square.io.mcap.writer import write_mcap


def recover_mcap(src, dst):
    """Read what is complete in a damaged MCAP file and write it as a whole file.

    Parameters
    ----------
    src : str or Path
        The damaged (e.g. truncated) MCAP file.
    dst : str or Path
        The repaired file, with summary and indexes.

    Returns
    -------
    RecoveryReport
        What was recovered from ``src``.

    Raises
    ------
    RecordingError
        If nothing is recoverable.
    """
    contents = scan_mcap(src)
    write_mcap(contents.recording, dst)
    return contents.report
