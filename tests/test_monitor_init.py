"""``imu-square init``: a monitor file that reads back, systemd units that systemd accepts,
and a cron line that runs exactly the nightly job."""

import shlex
import shutil
import subprocess

import pytest

from imu_square.cli import main
from imu_square.monitor.config import read_monitor
from imu_square.monitor.schedule import EXIT_CODES, cron_line, systemd_units


def test_init_writes_a_monitor_file_that_reads_back(tmp_path, capsys):
    out = tmp_path / "cfg" / "monitor.toml"
    code = main(
        [
            "init",
            "--machine-id",
            "mill-3",
            "-o",
            str(out),
            "--port",
            "/dev/ttyUSB0",
            "--at",
            "01:05",
        ]
    )
    assert code == 0
    config = read_monitor(out)
    assert config.machine_id == "mill-3"
    assert config.sensor.port == "/dev/ttyUSB0" and config.sensor.trigger == "motion"
    assert config.alarms.false_alarm_nights == 730.0
    printed = capsys.readouterr().out
    assert "OnCalendar=*-*-* 01:05:00" in printed
    cron = printed.strip().splitlines()[-1]
    assert cron.startswith("5 1 * * * ")


def test_init_refuses_to_overwrite_and_bad_input(tmp_path, capsys):
    out = tmp_path / "monitor.toml"
    assert main(["init", "--machine-id", "a", "-o", str(out)]) == 0
    capsys.readouterr()
    assert main(["init", "--machine-id", "b", "-o", str(out)]) == 2
    assert "exists already; give --force" in capsys.readouterr().err
    assert read_monitor(out).machine_id == "a"
    assert main(["init", "--machine-id", "b", "-o", str(out), "--force"]) == 0
    assert read_monitor(out).machine_id == "b"
    capsys.readouterr()
    assert main(["init", "--machine-id", "m 1", "-o", str(tmp_path / "x.toml")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.endswith(
        "[monitor] machine_id must be 1-64 letters, digits, '_', '.' or '-', starting with a "
        "letter or digit, got 'm 1'"
    )
    assert not (tmp_path / "x.toml").exists() and not list(tmp_path.glob(".x.toml*"))
    assert main(["init", "--machine-id", "m", "-o", str(tmp_path / "y.toml"), "--at", "25:00"]) == 2
    assert "--at must be a time HH:MM from 00:00 to 23:59, got '25:00'" in capsys.readouterr().err


@pytest.mark.parametrize("folder", ["plain", "with space", "it's $(touch pwned) `x` %h"])
def test_cron_line_runs_exactly_the_nightly_job(tmp_path, folder):
    exe = tmp_path / folder / "imu-square"
    monitor = tmp_path / folder / "monitor.toml"
    line = cron_line(exe, monitor, at="23:59", log_file=tmp_path / folder / "log")
    minute, hour, dom, month, dow, command = line.split(" ", 5)
    assert (minute, hour, dom, month, dow) == ("59", "23", "*", "*", "*")
    words = shlex.split(command)
    assert words[:4] == [str(exe), "nightly", "--config", str(monitor)]
    assert words[4:] == [">>", str(tmp_path / folder / "log"), "2>&1"]
    assert not (tmp_path / "pwned").exists()


@pytest.mark.skipif(
    shutil.which("systemd-analyze") is None,
    reason="systemd-analyze is not installed (Debian package systemd; .ci/run installs it)",
)
@pytest.mark.parametrize("user", [None, "imu"])
def test_systemd_units_pass_systemd_analyze_verify(tmp_path, user, capsys):
    folder = tmp_path / "with space %h"
    folder.mkdir()
    exe = folder / "imu-square"
    exe.write_text("#!/bin/sh\nexit 0\n")
    exe.chmod(0o755)
    monitor = folder / "monitor.toml"
    units = systemd_units("mill-3", exe, monitor, at="02:30", user=user)
    paths = []
    for name, text in units.items():
        (tmp_path / name).write_text(text)
        paths.append(str(tmp_path / name))
    proc = subprocess.run(
        ["systemd-analyze", "verify", *paths], capture_output=True, text=True, timeout=60
    )
    # verify exits 0 even for lines it ignores: it must not complain about anything of ours
    complaints = [ln for ln in proc.stderr.splitlines() if "imu-square-nightly" in ln]
    assert proc.returncode == 0 and not complaints, proc.stderr
    service = units["imu-square-nightly-mill-3.service"]
    assert "SuccessExitStatus=10 14" in service  # warning, no_baseline; ok is 0
    assert {EXIT_CODES[s] for s in ("alarm", "invalid", "stale_baseline")} == {11, 12, 13}
    assert ('"' + str(exe).replace("%", "%%") + '"') in service


def test_systemd_units_broken_on_purpose_are_caught(tmp_path):
    """The verify check above can fail: a bad line is reported."""
    if shutil.which("systemd-analyze") is None:
        pytest.skip("systemd-analyze is not installed (Debian package systemd)")
    units = systemd_units("m", "/bin/true", tmp_path / "m.toml")
    name = "imu-square-nightly-m.service"
    (tmp_path / name).write_text(units[name].replace("Type=oneshot", "Type=sometimes"))
    proc = subprocess.run(
        ["systemd-analyze", "verify", str(tmp_path / name)], capture_output=True, text=True
    )
    assert "Failed to parse service type" in proc.stderr


def test_nightly_check_of_a_new_monitor_makes_no_history(tmp_path, capsys):
    monitor = tmp_path / "mill-3.toml"
    history = tmp_path / "histories" / "mill-3.db"
    (tmp_path / "histories").mkdir()
    argv = ["init", "--machine-id", "mill-3", "-o", str(monitor), "--history", str(history)]
    assert main(argv) == 0
    capsys.readouterr()
    assert main(["nightly", "--config", str(monitor), "--check"]) == 0
    assert "not made yet: the first night makes it" in capsys.readouterr().err
    assert not history.exists(), "a check must not create the history it checks"
    # a history whose folder is missing is a mistake the check finds
    shutil.rmtree(tmp_path / "histories")
    assert main(["nightly", "--config", str(monitor), "--check"]) == 2
    assert "does not exist" in capsys.readouterr().err


def test_outputs_under_a_missing_mount_point_are_refused_not_made(tmp_path, capsys):
    monitor = tmp_path / "mill-3.toml"
    argv = ["init", "--machine-id", "mill-3", "-o", str(monitor), "--history", "h.db"]
    assert main(argv) == 0
    share = tmp_path / "mnt" / "share"  # not mounted: the folder is missing
    text = monitor.read_text().replace('data_dir = ""', f'data_dir = "{share / "mill-3"}"')
    monitor.write_text(text)
    capsys.readouterr()
    for extra in (["--check"], []):
        assert main(["nightly", "--config", str(monitor), *extra]) == 2
        err = capsys.readouterr().err
        assert "cannot create the data folder" in err and "does not exist (not mounted?)" in err
    assert not (tmp_path / "mnt").exists()


def test_init_takes_the_program_and_the_analysis_its_plan_assumed(tmp_path, capsys):
    # init wrote [analysis] cutoff_hz = 4.0 whatever the program: a 3.2 Hz circle was
    # filtered at 4 Hz. It now follows the program unless a plan file says otherwise.
    plan = tmp_path / "plan.toml"
    argv = ["plan", "--noise-density-ug", "25", "--max-feed-mm-min", "30000"]
    argv += ["--max-accel-m-s2", "10", "--travel-mm", "500", "--time-s", "60", "-o", str(plan)]
    assert main(argv) == 0
    assert "cutoff_hz =" not in plan.read_text().split("[analysis]")[1]
    monitor = tmp_path / "mill-3.toml"
    assert main(["init", "--machine-id", "mill-3", "-o", str(monitor), "--program", str(plan)]) == 0
    config = read_monitor(monitor)
    assert config.program == plan and config.test_program().feed_m_per_s == 0.5
    assert config.analysis.cutoff_hz is None  # 8 pi x the circle frequency, as analyze
    # a plan's own [analysis] comes with it
    plan.write_text(plan.read_text() + "cutoff_hz = 30.0\n")
    assert main(["init", "--machine-id", "mill-3", "-o", str(monitor), "--program", str(plan),
                 "--force"]) == 0  # fmt: skip
    assert read_monitor(monitor).analysis.cutoff_hz == 30.0
    capsys.readouterr()
