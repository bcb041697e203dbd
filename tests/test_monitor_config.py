"""The monitor file: validated like the program file, one line per mistake."""

from pathlib import Path

import pytest

from imu_square.cli import main
from imu_square.errors import MonitorConfigError
from imu_square.monitor.config import read_monitor

MINIMAL = '[monitor]\nmachine_id = "m1"\n'


def _write(tmp_path, text):
    path = tmp_path / "monitor.toml"
    path.write_text(text)
    return path


def test_minimal_file_takes_the_defaults(tmp_path):
    c = read_monitor(_write(tmp_path, MINIMAL))
    assert c.machine_id == "m1" and c.sensor.emulated and c.sensor.trigger == "marker"
    assert c.program is None and c.history == "" and c.metrics is None
    assert c.analysis.options().cutoff_hz is None  # follows the program, as analyze
    assert c.alarms.step_rad == pytest.approx(10e-6)
    assert c.motion == "trajectory" and "motion" not in c.diagnostics.stored()


def test_relative_paths_are_taken_from_the_file(tmp_path):
    text = (
        MINIMAL.replace('"m1"\n', '"m1"\nhistory = "h/hist.db"\ndata_dir = "out"\n')
        + '[program]\nfile = "p.toml"\n[emulated]\nmachine = "~/m.toml"\n'
    )
    c = read_monitor(_write(tmp_path, text))
    assert c.history == str(tmp_path / "h" / "hist.db")
    assert c.data_dir == tmp_path / "out" and c.program == tmp_path / "p.toml"
    assert c.emulated.machine == Path("~/m.toml").expanduser()
    lcnc = read_monitor(
        _write(tmp_path, text.replace('"p.toml"\n', '"p.toml"\nmotion = "linuxcnc"\n'))
    )
    assert lcnc.motion == "linuxcnc" and lcnc.diagnostics.stored()["motion"] == "linuxcnc"
    url = MINIMAL.replace('"m1"\n', '"m1"\nhistory = "postgresql://u@db/hist"\n')
    assert read_monitor(_write(tmp_path, url)).history == "postgresql://u@db/hist"


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("", r"the \[monitor\] section with machine_id is missing"),
        ("[monitor]\n", r"\[monitor\] is missing the required field 'machine_id'"),
        (MINIMAL + "[sensr]\n", r"unknown section \[sensr\]"),
        (MINIMAL + "[sensor]\nbaud = 0\n", r"\[sensor\] baud must be a whole number in \[1, "),
        (MINIMAL + '[sensor]\ntrigger = "now"\n', r"trigger must be one of \('marker', "),
        (MINIMAL + "[sensor]\nport = 3\n", r"port must be a non-empty string"),
        (MINIMAL + '[program]\nmotion = "fanuc"\n', r"\[program\] motion must be one of \('traj"),
        (MINIMAL + "[alarms]\nfalse_alarm_nights = 2\n", r"false_alarm_nights must be in \[10"),
        (MINIMAL + "[alarms]\nstep_um_per_m = 0\n", r"step_um_per_m must be in \(0, 10000\]"),
        (MINIMAL + "[analysis]\ncutoff = 4\n", r"\[analysis\] has unknown field 'cutoff'"),
        (MINIMAL + "[analysis]\nbootstrap = 1\n", r"\[analysis\] bootstrap must be 0 \(no boo"),
        (MINIMAL + "[analysis]\nbootstrap = -2\n", r"\[analysis\] bootstrap must be a whole"),
        (MINIMAL + "[monitor]\n", r"not valid TOML"),
        ('[monitor]\nmachine_id = "a/b"\n', r"machine_id must be 1-64 letters"),
        ('[monitor]\nmachine_id = ".."\n', r"starting with a letter or digit, got '\.\.'"),
        (MINIMAL + 'history = "mysql://db/x"\n', r"history must be a file path or a postgresql://"),
    ],
)
def test_mistakes_are_one_line_naming_file_field_and_value(tmp_path, text, message):
    path = _write(tmp_path, text)
    with pytest.raises(MonitorConfigError, match=message) as info:
        read_monitor(path)
    assert str(info.value).startswith(f"{path}: ") and "\n" not in str(info.value)


def test_missing_file(tmp_path):
    with pytest.raises(MonitorConfigError, match=r"nowhere\.toml"):
        read_monitor(tmp_path / "nowhere.toml")


# The monitor file's checks are now those of every file (imu_square.validation);
# each of these it said differently from the program, machine and sensor files.
OWN = MINIMAL + 'history = "h.db"\n'  # a file read right is no reason to touch ~


@pytest.mark.parametrize(
    ("text", "line"),
    [
        # an infinity is told "finite", as by the program file (was "in (0, 600]")
        (
            OWN + "[sensor]\nheader_timeout_s = inf\n",
            "[sensor] header_timeout_s must be finite, got inf",
        ),
        # the number as it is read, as every file gives it (was "got 0")
        (
            OWN + "[alarms]\nstep_um_per_m = 0\n",
            "[alarms] step_um_per_m must be in (0, 10000], got 0.0",
        ),
        # blank text is no text (was taken as the port "  ")
        (
            OWN + '[sensor]\nport = "  "\n',
            "[sensor] port must be a non-empty string on one line (no control characters), "
            "got '  '",
        ),
        # the sections sorted, as every file lists its sections and fields
        (
            OWN + "[sensr]\n",
            "unknown section [sensr]; allowed: ['alarms', 'alerts', 'analysis', 'diagnostics', "
            "'emulated', 'metrics', 'monitor', 'program', 'sensor']",
        ),
    ],
)
def test_the_monitor_file_is_checked_like_every_file(tmp_path, capsys, text, line):
    path = _write(tmp_path, text)
    assert main(["history", "--config", str(path)]) == 2
    assert capsys.readouterr().err == f"imu-square history: error: {path}: {line}\n"
