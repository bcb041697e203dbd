"""The monitor's Prometheus metrics, as a text file for node_exporter's textfile collector.

Point node_exporter at a folder (``--collector.textfile.directory``, on
Debian ``/var/lib/prometheus/node-exporter``) and set ``[metrics] textfile``
to a ``NAME.prom`` file in it, one file per machine. The file is replaced
atomically after every run: written to ``.NAME.prom.XXXX.tmp`` in the same
folder (node_exporter reads only ``*.prom``), synced, then renamed.

Every metric has the label ``machine_id``:

=================================================== ======= ==============================
``imu_square_squareness_change_radians``            gauge   change of θy − θx since the
                                                            baseline, latest valid run
``imu_square_squareness_change_uncertainty_radians`` gauge  its standard uncertainty (k=1)
``imu_square_sensor_rotation_radians``              gauge   ε_c, latest valid run
``imu_square_sensor_rotation_uncertainty_radians``  gauge   its standard uncertainty
``imu_square_state{state="..."}``                   gauge   1 for the current state, 0 for
                                                            the five others
``imu_square_last_run_timestamp_seconds``           gauge   Unix time of the latest run
``imu_square_last_valid_run_timestamp_seconds``     gauge   Unix time of the latest valid run
``imu_square_runs_total``                           counter runs in the history
``imu_square_invalid_runs_total``                   counter of which invalid
=================================================== ======= ==============================

Units follow Prometheus's rule of base units without prefixes: angles are
in radians, as everywhere inside imu-square (1 µm/m = 1 µrad = 1e-6 rad); a
dashboard shows µm/m with ``imu_square_squareness_change_radians * 1e6``.
A value that does not exist yet (no baseline, no valid run) is left out
rather than written as NaN, so ``absent()`` alerts work.

The state is one-hot, the exposition format's way of writing an enum (the
OpenMetrics "StateSet"): ``imu_square_state{state="alarm"} == 1`` selects it
and every state has a series, so none vanishes when the state changes.

Ages are not exported: node_exporter serves the file as it was last
written, so an age computed at write time would stand still exactly when the
nightly job stops running, the failure an age alert exists to catch. Export
the timestamp and let Prometheus compute the age:
``time() - imu_square_last_valid_run_timestamp_seconds > 2 * 86400``.
"""

import datetime as dt
import math
from dataclasses import dataclass
from pathlib import Path

from imu_square.errors import MonitorConfigError, MonitorError
from imu_square.io.atomic import write_atomic
from imu_square.monitor.alerts.alert import STATES
from imu_square.validation import TomlTable

METRICS_FIELDS = ("textfile",)
PREFIX = "imu_square_"

# name, help, snapshot attribute: gauges
_SCALARS = (
    (
        "squareness_change_radians",
        "Change of the squareness theta_y - theta_x since the baseline, latest valid run "
        "(1e-6 rad = 1 um/m).",
        "change_rad",
    ),
    (
        "squareness_change_uncertainty_radians",
        "Standard uncertainty (k=1) of the squareness change.",
        "u_change_rad",
    ),
    (
        "sensor_rotation_radians",
        "Rotation eps_c of the sensor about Z on the table, latest valid run.",
        "eps_c_rad",
    ),
    (
        "sensor_rotation_uncertainty_radians",
        "Standard uncertainty (k=1) of the sensor rotation.",
        "u_eps_c_rad",
    ),
)
_TIMES = (
    (
        "last_run_timestamp_seconds",
        "Unix time of the latest run, valid or not.",
        "last_run_at",
    ),
    (
        "last_valid_run_timestamp_seconds",
        "Unix time of the latest valid run.",
        "last_valid_run_at",
    ),
)
_COUNTS = (
    ("runs_total", "Runs in the monitor's history.", "runs"),
    ("invalid_runs_total", "Runs in the history that failed quality (invalid).", "invalid_runs"),
)


@dataclass(frozen=True)
class MetricsSnapshot:
    """What the metrics file shows after a run.

    Attributes
    ----------
    machine_id : str
        The machine.
    state : str
        One of :data:`~imu_square.monitor.alerts.alert.STATES`.
    runs : int
        Runs in the history.
    invalid_runs : int
        Of which invalid.
    change_rad, u_change_rad : float or None
        Squareness change since the baseline and its standard uncertainty,
        latest valid run; None without a baseline. [rad]
    eps_c_rad, u_eps_c_rad : float or None
        Sensor rotation about Z and its standard uncertainty, latest valid
        run. [rad]
    last_run_at, last_valid_run_at : datetime or None
        Times of the latest run and the latest valid run (timezone-aware).
    """

    machine_id: str
    state: str
    runs: int
    invalid_runs: int
    change_rad: float | None = None
    u_change_rad: float | None = None
    eps_c_rad: float | None = None
    u_eps_c_rad: float | None = None
    last_run_at: dt.datetime | None = None
    last_valid_run_at: dt.datetime | None = None


@dataclass(frozen=True)
class MetricsConfig:
    """The validated ``[metrics]`` section.

    Attributes
    ----------
    textfile : Path or None
        The ``.prom`` file to write, or None for no metrics.
    """

    textfile: Path | None = None


def escape_label_value(value):
    """A label value as the exposition format writes it between double quotes.

    Parameters
    ----------
    value : str
        Any text.

    Returns
    -------
    str
        With ``\\`` as ``\\\\``, ``"`` as ``\\"`` and a line feed as ``\\n``.
    """
    return value.replace("\\", "\\\\").replace('"', '\\"').replace("\n", "\\n")


def _number(value):
    if isinstance(value, int) and not isinstance(value, bool):
        return str(value)
    return repr(float(value))


def _present(value):
    return value is not None and math.isfinite(value)


def render_metrics(snapshot):
    """The metrics file's text (module docstring).

    Parameters
    ----------
    snapshot : MetricsSnapshot
        What to show.

    Returns
    -------
    str
    """
    if snapshot.state not in STATES:
        raise ValueError(f"state must be one of {STATES!r}, got {snapshot.state!r}")
    machine = f'machine_id="{escape_label_value(snapshot.machine_id)}"'
    lines = []

    def family(name, kind, help_text, samples):
        lines.append(f"# HELP {PREFIX}{name} {help_text}")
        lines.append(f"# TYPE {PREFIX}{name} {kind}")
        lines.extend(f"{PREFIX}{name}{{{labels}}} {value}" for labels, value in samples)

    for name, help_text, attr in _SCALARS:
        value = getattr(snapshot, attr)
        if _present(value):
            family(name, "gauge", help_text, [(machine, _number(value))])
    family(
        "state",
        "gauge",
        "Monitor state after the latest run: 1 for the current one, 0 for the others.",
        [(f'{machine},state="{s}"', "1" if s == snapshot.state else "0") for s in STATES],
    )
    for name, help_text, attr in _TIMES:
        when = getattr(snapshot, attr)
        if when is not None:
            if when.tzinfo is None:
                raise ValueError(f"{attr} must be timezone-aware, got {when!r}")
            family(name, "gauge", help_text, [(machine, f"{when.timestamp():.3f}")])
    for name, help_text, attr in _COUNTS:
        count = getattr(snapshot, attr)
        if isinstance(count, bool) or not isinstance(count, int) or count < 0:
            raise ValueError(f"{attr} must be a whole number >= 0, got {count!r}")
        family(name, "counter", help_text, [(machine, str(count))])
    return "\n".join(lines) + "\n"


def write_metrics(path, snapshot):
    """Replace the metrics file atomically (module docstring).

    Parameters
    ----------
    path : str or Path
        The ``.prom`` file; its folder must exist.
    snapshot : MetricsSnapshot
        What to show.

    Returns
    -------
    Path
        ``path``.

    Raises
    ------
    MonitorError
        If the file cannot be written, naming it.
    """
    path = Path(path)
    try:
        return write_atomic(path, render_metrics(snapshot).encode("utf-8"), mode=0o644)
    except OSError as exc:
        raise MonitorError(
            f"{path}: cannot write the metrics file: {exc.strerror or exc}"
        ) from None


def metrics_from_mapping(table, source="<monitor file>", base_dir=None):
    """Validate the ``[metrics]`` table of a loaded monitor file.

    Parameters
    ----------
    table : dict or None
        ``doc.get("metrics")`` of the parsed TOML; None means no metrics.
    source : str
        The monitor file's name, for messages.
    base_dir : str or Path, optional
        Folder that a relative path is taken from (the monitor file's folder).

    Returns
    -------
    MetricsConfig

    Raises
    ------
    MonitorConfigError
        One line naming the field, what is allowed and the value received.
    """
    if table is None:
        return MetricsConfig()
    t = TomlTable(table, "[metrics]", METRICS_FIELDS, source, base_dir, MonitorConfigError)
    path = t.path("textfile")
    if path.suffix != ".prom":
        t.fail(
            "textfile",
            "a file name ending in '.prom' (node_exporter's textfile collector reads no other)",
            t.get("textfile", None),
        )
    return MetricsConfig(textfile=path)
