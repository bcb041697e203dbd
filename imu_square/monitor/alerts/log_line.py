"""The log sink: one line per alert through the package logger.

The line is ``alert: machine 'mill-3' alarm: changed by +14 ± 3 µm/m: check
the machine``, at INFO for ``ok`` and ``no_baseline``, WARNING for
``warning``, ``invalid`` and ``stale_baseline``, ERROR for ``alarm``. Control
characters in the machine id or the verdict become spaces, so a crafted value
cannot forge a second log line.
"""

import logging
from dataclasses import dataclass

from imu_square.log import logger
from imu_square.monitor.alerts.alert import STATES, one_line

_LEVELS = {
    "ok": logging.INFO,
    "no_baseline": logging.INFO,
    "warning": logging.WARNING,
    "invalid": logging.WARNING,
    "stale_baseline": logging.WARNING,
    "alarm": logging.ERROR,
}


@dataclass(frozen=True)
class LogSink:
    """Log one line per alert.

    Attributes
    ----------
    name : str
        Always ``"log"``.
    states : tuple of str
        States that are logged; all of them by default, since a log line per
        night costs nothing and the journal then shows every night.
    """

    name: str = "log"
    states: tuple = STATES
    timeout_s = None  # a log call does not wait on anything
    kind = "log"

    def deliver(self, alert, timeout_s=None):
        """Log ``alert``.

        Parameters
        ----------
        alert : Alert
            The alert.
        timeout_s : float, optional
            Unused: logging does not wait. [s]
        """
        logger.log(
            _LEVELS[alert.state],
            "alert: machine %r %s: %s",
            one_line(alert.machine_id),
            alert.state,
            one_line(alert.verdict),
        )

    def describe(self):
        """What the sink does, for messages (never a secret)."""
        return "the log"


def log_from_table(table):
    """The ``[alerts.log]`` table.

    Parameters
    ----------
    table : imu_square.validation.TomlTable
        The checked table.

    Returns
    -------
    LogSink
    """
    return LogSink(states=table.choices("states", STATES, default=STATES))
