"""What the monitor's commands share: the monitor file option and opening its history."""

from contextlib import contextmanager


def add_config_argument(parser, required=True):
    """Add ``--config M``, the monitor file."""
    parser.add_argument(
        "--config",
        required=required,
        metavar="MONITOR.toml",
        help="the machine's monitor file (imu-square init writes one)",
    )


@contextmanager
def monitor_session(path):
    """The monitor file read and its history open, closed on exit.

    Parameters
    ----------
    path : str
        The monitor file.

    Yields
    ------
    config : MonitorConfig
    history : History
    """
    from imu_square.monitor.config import read_monitor

    config = read_monitor(path)
    with config.open_history() as history:
        yield config, history
