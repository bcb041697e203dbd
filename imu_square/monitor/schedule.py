"""Running ``nightly`` every night: the monitor file ``init`` writes, systemd units, a cron line.

The nightly job's exit code is the monitor's state (:data:`EXIT_CODES`). In the
systemd service the states that need nobody (ok, warning, no baseline yet) are
success; an alarm, an invalid run or a stale baseline leave the unit *failed*,
so ``systemctl --failed`` and any ``OnFailure=`` hook show them even without an
alert sink.
"""

import re
import shlex
from pathlib import Path

# The nightly job's exit code of each state, clear of the codes every command
# shares: 2 (a user's mistake), 3 (an incomplete recording), 4 (writing failed
# part-way) and 130 (interrupted).
EXIT_CODES = {
    "ok": 0,
    "warning": 10,
    "alarm": 11,
    "invalid": 12,
    "stale_baseline": 13,
    "no_baseline": 14,
}
_QUIET_STATES = ("ok", "warning", "no_baseline")
_TIME = re.compile(r"([01]\d|2[0-3]):([0-5]\d)")

MONITOR_TEMPLATE = """\
# imu-square monitor file for machine {machine_id}: the nightly squareness monitor.
# Check it with: imu-square nightly --config {name} --check
# Every field is optional but machine_id; relative paths are taken from this file's folder.

[monitor]
machine_id = {machine_id_toml}
# Where the history of runs is kept: "" = the per-user default
# ($XDG_DATA_HOME/imu-square/history.db, else ~/.local/share/imu-square/history.db),
# a path to an SQLite file, or postgresql://user@host/db for a central history.
history = {history_toml}
# Recordings, plots and the report: "" = a folder named after the machine beside the history.
data_dir = ""

[sensor]
# The board's serial port by a stable name (/dev/serial/by-id/usb-...), or "emulated"
# for the built-in emulated board (a simulated machine, for trying the monitor out).
port = {port_toml}
baud = 921600
# When recording starts: "marker" (the CNC's M-code marker; see imu-square program
# --marker-mcode), "motion" (when the table moves) or "immediate".
trigger = {trigger_toml}
header_timeout_s = 5.0

[emulated]
# Only used with port = "emulated": the simulator's machine and sensor files.
machine = ""
sensor = ""
speed = 20.0
uptime_s = 18000.0

[program]
# The circle test the machine runs (imu-square program writes its NC code); "" = the paper's test.
file = {program_toml}
# Its commanded motion: "trajectory" (our own model of a controller) or "linuxcnc" (LinuxCNC's
# planner run on this computer, Debian's linuxcnc-uspace): the nightly diagnostics fit takes
# it as its model, and the emulated board runs it.
motion = "trajectory"

[analysis]
# The analysis of every night; a baseline is of one set of settings. Unset, the low-pass
# cutoff follows the program: 8 pi x its circle frequency, as imu-square analyze.
{analysis}

[alarms]
# The false-alarm rate you accept: one false alarm in this many nights.
false_alarm_nights = 730
# The change you want found quickly; its detection delay is reported.
step_um_per_m = 10.0

# After every valid night the effects a ballbar reports are fitted and trended, each with
# its uncertainty (imu-square history). Default: all six; [] fits none.
# [diagnostics]
# effects = ["servo_mismatch", "backlash", "reversal_spikes", "scale_mismatch",
#            "straightness_yaw", "structural_vibration"]
# A diagnostic's own alarm, off by default: the change it should find quickly.
# [diagnostics.alarms]
# backlash_x_um = 3.0

# Alert sinks (see the README, "Alerts and metrics"). Without them the nightly job
# logs its verdict and sets its exit code.
# [alerts.email]
# host = "smtp.example.com"
# sender = "imu-square <noreply@example.com>"
# to = ["maintenance@example.com"]
#
# [[alerts.webhook]]
# url = "https://hooks.example.com/imu-square"
#
# [metrics]
# textfile = "/var/lib/prometheus/node-exporter/imu_square_{machine_id}.prom"
"""


def _toml_string(text):
    return '"' + text.replace("\\", "\\\\").replace('"', '\\"') + '"'


def monitor_file_text(
    machine_id, port="emulated", history="", trigger=None, program="", analysis=None
):
    """The commented monitor file ``init`` writes.

    Parameters
    ----------
    machine_id : str
        The machine monitored.
    port : str
        Serial port, or ``"emulated"``.
    history : str
        History location; "" for the per-user default.
    trigger : str, optional
        ``"marker"`` for the emulated board, ``"motion"`` for a real port unless given.
    program : str
        The program file; "" for the paper's test.
    analysis : AnalysisSettings, optional
        The analysis the program was planned for; the defaults if None.

    Returns
    -------
    str
    """
    from imu_square.monitor.config import AnalysisSettings

    trigger = trigger or ("marker" if port == "emulated" else "motion")
    analysis = analysis or AnalysisSettings()
    cutoff = (
        "# cutoff_hz = 4.0" if analysis.cutoff_hz is None else f"cutoff_hz = {analysis.cutoff_hz!r}"
    )
    return MONITOR_TEMPLATE.format(
        machine_id=machine_id,
        machine_id_toml=_toml_string(machine_id),
        name="monitor.toml",
        history_toml=_toml_string(history),
        port_toml=_toml_string(port),
        trigger_toml=_toml_string(trigger),
        program_toml=_toml_string(program),
        analysis=f"{cutoff}\norder = {analysis.order}\nbootstrap = {analysis.bootstrap}",
    )


def check_time(text):
    """Validate a wall-clock time ``HH:MM``.

    Parameters
    ----------
    text : str
        The time.

    Returns
    -------
    tuple of int
        ``(hour, minute)``.

    Raises
    ------
    ValueError
        If it is not ``HH:MM`` in 00:00-23:59.
    """
    m = _TIME.fullmatch(text)
    if not m:
        raise ValueError(f"--at must be a time HH:MM from 00:00 to 23:59, got {text!r}")
    return int(m.group(1)), int(m.group(2))


def systemd_units(machine_id, executable, monitor_file, at="02:30", user=None):
    """A systemd service and timer that run ``nightly`` at a time each night.

    Parameters
    ----------
    machine_id : str
        The machine monitored.
    executable : str or Path
        Absolute path of the ``imu-square`` script.
    monitor_file : str or Path
        Absolute path of the monitor file.
    at : str
        Local time of day, ``HH:MM``.
    user : str, optional
        The account the job runs as (a system unit); None for a user unit.

    Returns
    -------
    dict of str to str
        ``{"NAME.service": text, "NAME.timer": text}``.
    """
    hour, minute = check_time(at)
    name = f"imu-square-nightly-{machine_id}"
    success = " ".join(str(EXIT_CODES[s]) for s in _QUIET_STATES if EXIT_CODES[s])
    command = " ".join(
        _systemd_quote(a) for a in (str(executable), "nightly", "--config", str(monitor_file))
    )
    service = [
        "[Unit]",
        f"Description=imu-square nightly squareness run of machine {machine_id}",
        "",
        "[Service]",
        "Type=oneshot",
        f"ExecStart={command}",
        # a path setting takes the rest of the line: no quotes, only % doubled
        f"WorkingDirectory={str(Path(monitor_file).parent).replace('%', '%%')}",
        "# ok, warning and no_baseline are success; alarm (11), invalid (12) and",
        "# stale_baseline (13) leave the unit failed, so systemctl --failed shows them.",
        f"SuccessExitStatus={success}",
        "TimeoutStartSec=2h",
        "Nice=5",
    ]
    if user:
        service.insert(service.index("Type=oneshot") + 1, f"User={user}")
    timer = [
        "[Unit]",
        f"Description=Run the imu-square nightly squareness run of machine {machine_id}",
        "",
        "[Timer]",
        f"OnCalendar=*-*-* {hour:02d}:{minute:02d}:00",
        "# No catch-up after a power cut: the warm-up cycle needs the machine ready.",
        "Persistent=false",
        "AccuracySec=1min",
        f"Unit={name}.service",
        "",
        "[Install]",
        "WantedBy=timers.target",
    ]
    return {f"{name}.service": "\n".join(service) + "\n", f"{name}.timer": "\n".join(timer) + "\n"}


def cron_line(executable, monitor_file, at="02:30", log_file=None):
    """The crontab line that runs ``nightly`` at a time each night.

    Parameters
    ----------
    executable : str or Path
        Absolute path of the ``imu-square`` script.
    monitor_file : str or Path
        Absolute path of the monitor file.
    at : str
        Local time of day, ``HH:MM``.
    log_file : str or Path, optional
        Where the job's output is appended; none if None.

    Returns
    -------
    str
    """
    hour, minute = check_time(at)
    command = " ".join(
        shlex.quote(a) for a in (str(executable), "nightly", "--config", str(monitor_file))
    )
    if log_file is not None:
        command += f" >> {shlex.quote(str(log_file))} 2>&1"
    return f"{minute} {hour} * * * {command}"


def _systemd_quote(word):
    """A word of an ExecStart= line: quoted when it holds a space, quote or backslash."""
    if re.fullmatch(r"[A-Za-z0-9_@+=:,./-]+", word):
        return word
    escaped = word.replace("\\", "\\\\").replace('"', '\\"').replace("%", "%%")
    return f'"{escaped}"'
