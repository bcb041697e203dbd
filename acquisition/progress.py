"""Live progress of a recording for a person watching stderr.

On a terminal a one-line bar is redrawn in place; otherwise (a log file, CI)
a plain line is written every few seconds. Only the CLI creates one of these,
handing it the stream to write to.
"""

import math
import time

BAR_WIDTH = 24


def describe(status):
    """One line about a :class:`~acquisition.status.RecorderStatus`.

    Parameters
    ----------
    status : RecorderStatus
        Snapshot of the recorder.

    Returns
    -------
    str
    """
    expected = status.expected_s
    span = (
        f"{status.recorded_s:.1f}/{expected:.1f} s"
        if math.isfinite(expected)
        else f"{status.recorded_s:.1f} s"
    )
    rate = f"{status.rate_hz:.0f} Hz" if math.isfinite(status.rate_hz) else "- Hz"
    return (
        f"{status.state}: {status.samples_written} samples, {rate}, {span}, "
        f"gaps {status.gaps} (lost {status.lost}), CRC errors {status.crc_errors}, "
        f"reconnects {status.reconnects}"
    )


class ProgressPrinter:
    """Callable that shows a :class:`~acquisition.status.RecorderStatus`.

    Parameters
    ----------
    stream : text file
        Where to write (``sys.stderr``).
    bar : bool, optional
        Redraw a bar in place; by default when ``stream`` is a terminal.
    interval_s : float
        Time between plain lines. [s]
    """

    def __init__(self, stream, *, bar=None, interval_s=5.0):
        self.stream = stream
        self.bar = stream.isatty() if bar is None else bar
        self.interval_s = interval_s
        self._next = 0.0
        self._drawn = False

    def __call__(self, status):
        """Show ``status`` (a bar redraw, or a line when due)."""
        line = describe(status)
        if self.bar:
            fraction = 0.0
            if math.isfinite(status.expected_s) and status.expected_s > 0:
                fraction = min(1.0, status.recorded_s / status.expected_s)
            filled = round(fraction * BAR_WIDTH)
            bar = "#" * filled + "." * (BAR_WIDTH - filled)
            self.stream.write(f"\r[{bar}] {fraction:4.0%} {line}\033[K")
            self._drawn = True
        elif time.monotonic() >= self._next:
            self.stream.write(line + "\n")
            self._next = time.monotonic() + self.interval_s
        self.stream.flush()

    def filter(self, record):
        """Logging filter: wipe the bar before a log line is written under it.

        Add the printer to the package logger (``logger.addFilter(printer)``)
        so that log messages and the bar share the terminal cleanly.

        Returns
        -------
        bool
            Always True: the record is kept.
        """
        if self._drawn:
            self.stream.write("\r\033[K")
            self.stream.flush()
            self._drawn = False
        return True

    def close(self):
        """End the bar's line so later output starts on a fresh one."""
        if self._drawn:
            self.stream.write("\n")
            self.stream.flush()
            self._drawn = False
