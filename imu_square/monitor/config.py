"""The monitor file (``monitor.toml``): one machine's nightly squareness monitor.

Distinct from the simulator's machine and sensor files. Every field is checked
like the program file: one line names the field, the value and what is
allowed. Relative paths are taken from the monitor file's folder. A complete
file, as ``imu-square init`` writes it::

    [monitor]
    machine_id = "mill-3"
    history = ""                 # "" = the per-user default; a path; or postgresql://...
    data_dir = ""                # recordings, plots, report; "" = beside the history
    busy_timeout_s = 60.0        # a write waits this long for another process's

    [sensor]
    port = "emulated"            # or /dev/serial/by-id/usb-...; "emulated" = built-in board
    baud = 921600
    trigger = "marker"           # "marker" (CNC M-code), "motion" or "immediate"
    header_timeout_s = 5.0

    [emulated]                   # only with port = "emulated"
    machine = ""                 # simulator machine file; "" = a typical machine
    sensor = ""                  # simulator sensor file; "" = the paper's sensor
    speed = 20.0                 # times faster than real time
    uptime_s = 18000.0           # the board has been on this long (its sensor warm)

    [program]
    file = ""                    # the circle test's program file; "" = the paper's test
    motion = "trajectory"        # its commanded motion: "trajectory" (our own) or "linuxcnc"
                                 # (LinuxCNC's planner): the emulated board runs it, and the
                                 # nightly diagnostics fit takes it as its model

    [analysis]
    # cutoff_hz = 4.0            # unset: 8 pi x the program's circle frequency, as analyze
    order = 1
    bootstrap = 200

    [alarms]
    false_alarm_nights = 730     # accept one false alarm in this many nights
    step_um_per_m = 10.0         # the change to detect, for the out-of-control run length
    monte_carlo_nights = 4000000 # nights simulated to check the design

    [diagnostics] ...            # imu_square.monitor.diagnostics.settings
    [alerts] ...                 # imu_square.monitor.alerts.config
    [metrics] ...                # imu_square.monitor.report.metrics

The history's per-user default is :func:`imu_square.monitor.history.store.default_history_path`.
"""

import re
from dataclasses import dataclass, field, replace
from pathlib import Path

from imu_square.errors import MonitorConfigError
from imu_square.monitor.alerts.config import AlertsConfig, alerts_from_mapping
from imu_square.monitor.diagnostics.settings import DiagnosticSettings, diagnostics_from_mapping
from imu_square.monitor.report.metrics import MetricsConfig, metrics_from_mapping
from imu_square.simulate.sources import MOTION_SOURCES
from imu_square.textfile import read_toml
from imu_square.units import URAD
from imu_square.validation import TomlTable, check_sections

EMULATED = "emulated"
TRIGGERS = ("marker", "motion", "immediate")
SECTIONS = (
    "monitor",
    "sensor",
    "emulated",
    "program",
    "analysis",
    "alarms",
    "diagnostics",
    "alerts",
    "metrics",
)
_MACHINE_ID = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.-]{0,63}")


@dataclass(frozen=True)
class SensorLink:
    """How the nightly job reaches the sensor board.

    Attributes
    ----------
    port : str
        Serial port (a stable name) or a pyserial URL, or ``"emulated"``.
    baud : int
        Line speed. [bit/s]
    trigger : str
        When recording starts: ``"marker"``, ``"motion"`` or ``"immediate"``.
    header_timeout_s : float
        Give up when the board sends no header within this time. [s]
    """

    port: str = EMULATED
    baud: int = 921600
    trigger: str = "marker"
    header_timeout_s: float = 5.0

    @property
    def emulated(self):
        """Whether the built-in emulated board stands in for a real one."""
        return self.port == EMULATED


@dataclass(frozen=True)
class EmulatedBoard:
    """The emulated board's simulated machine and sensor.

    Attributes
    ----------
    machine, sensor : Path or None
        Simulator machine and sensor files; None for the built-in ones.
    speed : float
        Times faster than real time.
    uptime_s : float
        How long the emulated board has been on when the test starts (its
        sensor's warm-up). [s]
    """

    machine: Path | None = None
    sensor: Path | None = None
    speed: float = 20.0
    uptime_s: float = 18000.0


@dataclass(frozen=True)
class AlarmSettings:
    """What the user accepts and wants to see; the charts are designed from it.

    Attributes
    ----------
    false_alarm_nights : float
        In-control average run length: one false alarm in this many nights.
    step_rad : float
        The change the charts should find quickly (its out-of-control run
        length is reported). [rad]
    monte_carlo_nights : int
        Nights simulated to check the designed scheme (its false-alarm rate's
        relative standard error is about ``sqrt(false_alarm_nights / this)``).
    """

    false_alarm_nights: float = 730.0
    step_rad: float = 10 * URAD
    monte_carlo_nights: int = 4_000_000


@dataclass(frozen=True)
class AnalysisSettings:
    """The analysis options the monitor stores with every run.

    Attributes
    ----------
    cutoff_hz : float or None
        Low-pass cutoff; None follows the program, 8 pi x its circle
        frequency, as ``imu-square analyze`` does. [Hz]
    order : int
        Low-pass order.
    bootstrap : int
        Bootstrap resamples (0 to skip, else at least 2).
    """

    cutoff_hz: float | None = None
    order: int = 1
    bootstrap: int = 200

    @classmethod
    def from_table(cls, table):
        """Read ``cutoff_hz``, ``order`` and ``bootstrap`` from an ``[analysis]`` table.

        Parameters
        ----------
        table : imu_square.validation.TomlTable
            The ``[analysis]`` table of a monitor or settings file.

        Returns
        -------
        AnalysisSettings
        """
        cutoff_hz = None
        if table.has("cutoff_hz"):
            cutoff_hz = table.number("cutoff_hz", 0.0, 1000.0, lo_open=True)
        order = table.integer("order", 1, 8, default=1)
        bootstrap = table.integer("bootstrap", 0, 10_000, default=200)
        if bootstrap == 1:  # one resample has no spread
            table.fail("bootstrap", "0 (no bootstrap) or a whole number in [2, 10000]", 1)
        return cls(cutoff_hz=cutoff_hz, order=order, bootstrap=bootstrap)

    @classmethod
    def of_program_file(cls, path):
        """The ``[analysis]`` a program file carries (``imu-square plan -o`` writes one).

        Parameters
        ----------
        path : str or Path
            The program file.

        Returns
        -------
        AnalysisSettings or None
            None when the file has no ``[analysis]`` table.
        """
        doc = read_toml(path, MonitorConfigError)
        if "analysis" not in doc:
            return None
        fields = ("cutoff_hz", "order", "bootstrap")
        return cls.from_table(TomlTable(doc["analysis"], "[analysis]", fields, str(path)))

    def options(self):
        """The pipeline's :class:`~imu_square.pipeline.options.AnalysisOptions`."""
        from imu_square.pipeline.options import AnalysisOptions

        return AnalysisOptions(
            cutoff_hz=self.cutoff_hz, order=self.order, bootstrap_n=self.bootstrap
        )


@dataclass(frozen=True)
class MonitorConfig:
    """A validated monitor file.

    Attributes
    ----------
    path : Path
        The monitor file.
    machine_id : str
        The machine monitored.
    history : str
        Where the history is: a SQLite path or a ``postgresql://`` URL; "" for
        the per-user default.
    data_dir : Path or None
        Where nightly recordings, plots and the report go; None for beside the history.
    busy_timeout_s : float
        How long a write waits for another process's before the night is kept
        for later. [s]
    sensor : SensorLink
    emulated : EmulatedBoard
    program : Path or None
        The program file; None for the paper's test.
    analysis : AnalysisSettings
    alarms : AlarmSettings
    diagnostics : DiagnosticSettings
        The effects fitted after every valid night, and the diagnostics' alarms.
    alerts : AlertsConfig
    metrics : MetricsConfig or None
    """

    path: Path
    machine_id: str
    history: str = ""
    data_dir: Path | None = None
    busy_timeout_s: float = 60.0
    sensor: SensorLink = field(default_factory=SensorLink)
    emulated: EmulatedBoard = field(default_factory=EmulatedBoard)
    program: Path | None = None
    analysis: AnalysisSettings = field(default_factory=AnalysisSettings)
    alarms: AlarmSettings = field(default_factory=AlarmSettings)
    diagnostics: DiagnosticSettings = field(default_factory=DiagnosticSettings)
    alerts: AlertsConfig = field(default_factory=AlertsConfig)
    metrics: MetricsConfig | None = None

    @property
    def motion(self):
        """The program's commanded motion (:data:`~imu_square.simulate.sources.MOTION_SOURCES`),
        kept with the diagnostics, whose fit takes it as its model."""
        return self.diagnostics.motion

    def with_motion(self, source):
        """This monitor file with another commanded motion (``nightly --motion``).

        Parameters
        ----------
        source : str
            One of :data:`~imu_square.simulate.sources.MOTION_SOURCES`.

        Returns
        -------
        MonitorConfig
        """
        return replace(self, diagnostics=replace(self.diagnostics, motion=source))

    def test_program(self):
        """The program the monitor expects: read from :attr:`program`, else the paper's test.

        Returns
        -------
        TestProgram

        Raises
        ------
        MonitorConfigError
            The program runs several feeds: the monitor tracks one feed's
            ``theta_y - theta_x`` night to night, and a night of a two-feed
            program would be recorded only to be refused.
        """
        from imu_square.program import TestProgram, read_program
        from imu_square.units import MM_PER_MIN

        if self.program is None:
            return TestProgram()

        program = read_program(self.program)
        if program.n_feeds > 1:
            feeds = ", ".join(f"{v / MM_PER_MIN:g}" for v in program.feeds)
            raise MonitorConfigError(
                f"{self.path}: [program] file {self.program} runs {program.n_feeds} feeds "
                f"({feeds} mm/min); the monitor judges a one-feed test night to night: give "
                "it a one-feed program (imu-square plan without --separate-gravity), and "
                "analyse two-feed runs with 'imu-square analyze --separate-gravity'"
            )
        return program

    def history_location(self):
        """The history as :func:`~imu_square.monitor.history.store.open_history` takes it."""
        from imu_square.monitor.history.store import default_history_path

        return self.history or str(default_history_path())

    def open_history(self):
        """The history, open (:func:`~imu_square.monitor.history.store.open_history`)."""
        from imu_square.monitor.history.store import open_history

        return open_history(self.history_location(), busy_timeout_s=self.busy_timeout_s)

    def output_dir(self):
        """Folder of the nightly recordings, plots and report (created when written)."""
        if self.data_dir is not None:
            return self.data_dir
        from imu_square.monitor.history.store import default_history_path, is_postgres_url

        location = self.history_location()
        base = default_history_path().parent if is_postgres_url(location) else Path(location).parent
        return base / self.machine_id


def monitor_from_mapping(doc, path):
    """Validate a parsed monitor file.

    Parameters
    ----------
    doc : dict
        The parsed TOML.
    path : str or Path
        The file, for messages and for relative paths.

    Returns
    -------
    MonitorConfig

    Raises
    ------
    MonitorConfigError
        One line naming the file, the table, the field, what is allowed and what came.
    """
    path = Path(path)
    source, base = str(path), path.parent
    check_sections(doc, SECTIONS, source, MonitorConfigError)
    if "monitor" not in doc:
        raise MonitorConfigError(f"{source}: the [monitor] section with machine_id is missing")

    def table(name, fields):
        return TomlTable(doc.get(name, {}), f"[{name}]", fields, source, base, MonitorConfigError)

    mon = table("monitor", ("machine_id", "history", "data_dir", "busy_timeout_s"))
    machine_id = mon.text("machine_id")
    if not _MACHINE_ID.fullmatch(machine_id):
        mon.fail(
            "machine_id",
            "1-64 letters, digits, '_', '.' or '-', starting with a letter or digit",
            machine_id,
        )
    history = mon.text("history", default="", empty=True)
    if "://" in history and not history.startswith(("postgresql://", "postgres://")):
        mon.fail("history", "a file path or a postgresql:// URL", history)
    if history and not history.startswith(("postgresql://", "postgres://")):
        history = str(mon.path("history"))
    data_dir = mon.path("data_dir") if mon.text("data_dir", default="", empty=True) else None
    busy_timeout_s = mon.number("busy_timeout_s", 0.0, 3600.0, lo_open=True, default=60.0)

    sen = table("sensor", ("port", "baud", "trigger", "header_timeout_s"))
    sensor = SensorLink(
        port=sen.text("port", default=EMULATED),
        baud=sen.integer("baud", 1, 20_000_000, default=921600),
        trigger=sen.choice("trigger", TRIGGERS, default="marker"),
        header_timeout_s=sen.number("header_timeout_s", 0.0, 600.0, lo_open=True, default=5.0),
    )
    emu = table("emulated", ("machine", "sensor", "speed", "uptime_s"))
    emulated = EmulatedBoard(
        machine=emu.path("machine") if emu.text("machine", default="", empty=True) else None,
        sensor=emu.path("sensor") if emu.text("sensor", default="", empty=True) else None,
        speed=emu.number("speed", 0.0, 1000.0, lo_open=True, default=20.0),
        uptime_s=emu.number("uptime_s", 0.0, 1e9, default=18000.0),
    )
    prog = table("program", ("file", "motion"))
    program = prog.path("file") if prog.text("file", default="", empty=True) else None
    motion = prog.choice("motion", MOTION_SOURCES, default="trajectory")
    analysis = AnalysisSettings.from_table(table("analysis", ("cutoff_hz", "order", "bootstrap")))
    alarm = table("alarms", ("false_alarm_nights", "step_um_per_m", "monte_carlo_nights"))
    alarms = AlarmSettings(
        false_alarm_nights=alarm.number("false_alarm_nights", 10.0, 1e6, default=730.0),
        step_rad=alarm.number("step_um_per_m", 0.0, 1e4, lo_open=True, default=10.0) * URAD,
        monte_carlo_nights=alarm.integer(
            "monte_carlo_nights", 100_000, 100_000_000, default=4_000_000
        ),
    )
    metrics = None
    if "metrics" in doc:
        metrics = metrics_from_mapping(doc["metrics"], source, base)
    return MonitorConfig(
        path=path,
        machine_id=machine_id,
        history=history,
        data_dir=data_dir,
        busy_timeout_s=busy_timeout_s,
        sensor=sensor,
        emulated=emulated,
        program=program,
        analysis=analysis,
        alarms=alarms,
        diagnostics=replace(
            diagnostics_from_mapping(doc.get("diagnostics"), source), motion=motion
        ),
        alerts=alerts_from_mapping(doc.get("alerts"), source, base),
        metrics=metrics,
    )


def read_monitor(path):
    """Read and validate a monitor file.

    Parameters
    ----------
    path : str or Path
        The monitor file.

    Returns
    -------
    MonitorConfig
    """
    return monitor_from_mapping(read_toml(path, MonitorConfigError), path)
