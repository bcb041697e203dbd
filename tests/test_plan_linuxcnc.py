"""``plan --linuxcnc-ini``: a machine's limits from its controller, arcs at LinuxCNC's limit."""

import json

import pytest

from imu_square.cli import main
from imu_square.linuxcnc.configuration import default_configuration
from imu_square.linuxcnc.ini import read_limits
from imu_square.program import read_program

SIM_INI = str(default_configuration().folder / "imu-square-sim.ini")


@pytest.mark.parametrize(
    ("noise_ug", "extra"),
    [
        ("7", []),
        # a noisy sensor wants the largest acceleration: the arc limit holds it,
        # not the 10 m/s^2 of the flag (the axes' limit)
        ("400", ["--max-accel-m-s2", "10", "--max-feed-mm-min", "40000"]),
    ],
)
def test_the_plan_keeps_within_linuxcnc_s_arc_limit(tmp_path, capsys, noise_ug, extra):
    out = tmp_path / "plan.toml"
    argv = ["plan", "--linuxcnc-ini", SIM_INI, "--noise-density-ug", noise_ug]
    argv += ["--travel-mm", "50", "--time-s", "20", "--json", "-o", str(out), *extra]
    assert main(argv) == 0
    captured = capsys.readouterr()
    doc = json.loads(captured.out)
    limits = read_limits(SIM_INI)
    program = read_program(out)
    assert doc["centripetal_m_s2"][0] <= limits.arc_accel_m_s2
    # LinuxCNC runs it at the programmed feed: no faster than its arc speed on this circle
    assert program.feed_m_per_s <= limits.arc_feed_m_s(program.radius_m)
    assert "arcs at up to 8.66 m/s² (sqrt(3)/2 of the axes' 10 m/s²" in captured.err
    if noise_ug == "400":
        assert doc["centripetal_m_s2"][0] > 0.95 * limits.arc_accel_m_s2


def test_without_limits_or_an_ini_file_one_line_says_what_is_needed(capsys):
    argv = ["plan", "--noise-density-ug", "7", "--travel-mm", "50", "--time-s", "20"]
    assert main([*argv, "--max-feed-mm-min", "9000"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1
    assert "give --max-accel-m-s2, or the machine's LinuxCNC INI file with --linuxcnc-ini" in err


def test_a_bad_ini_file_is_one_line(tmp_path, capsys):
    ini = tmp_path / "machine.ini"
    ini.write_text("[TRAJ]\nLINEAR_UNITS = mm\n[AXIS_X]\nMAX_VELOCITY = 100\n")
    argv = ["plan", "--noise-density-ug", "7", "--travel-mm", "50", "--time-s", "20"]
    assert main([*argv, "--linuxcnc-ini", str(ini)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "machine.ini: [AXIS_Y] MAX_VELOCITY is missing" in err
