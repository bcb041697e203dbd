"""``imu-square simulate`` end to end: files in, run.mcap + run.truth.json out."""

import json
import subprocess
import sys
import time

import numpy as np
from numpy.testing import assert_allclose

from imu_square.cli import main
from imu_square.io.mcap import read_mcap
from imu_square.program import read_program
from imu_square.simulate import data_path, read_machine, read_sensor, simulate_run, with_effects

SHORT_PROGRAM = """[program]
radius_mm = 50.0
feed_mm_per_min = 3000.0
cycles_per_direction = 2
dwell_s = 0.5
"""
SENSOR = """[sensor]
sample_rate_hz = 200.0
noise_density_ug_rthz = 7.0
eps_c_deg = 2.1
"""


def write_inputs(tmp_path):
    program = tmp_path / "p.toml"
    program.write_text(SHORT_PROGRAM)
    sensor = tmp_path / "s.toml"
    sensor.write_text(SENSOR)
    return program, sensor


def test_simulate_writes_recording_and_truth(tmp_path, capsys):
    program, sensor = write_inputs(tmp_path)
    out = tmp_path / "out" / "run.mcap"
    argv = [
        "simulate",
        "--start-time",
        "2023-11-14T22:13:20Z",  # the library's default: the same run bit for bit
        "--program",
        str(program),
        "--machine",
        str(data_path("machine_typical.toml")),
        "--sensor",
        str(sensor),
        "-o",
        str(out),
        "--seed",
        "7",
        "--effects",
        "gravity_coupling,sample_clock_error",
    ]
    assert main(argv) == 0
    err = capsys.readouterr().out
    assert "samples" in err and "truth squareness 15.00 µm/m" in err
    truth = json.loads((tmp_path / "out" / "run.truth.json").read_text())
    # gravity coupling adds ~980 urad to what theta_y - theta_x will show
    shown = truth["expected_squareness_rad"] * 1e6
    assert f"(expected theta_y - theta_x on this circle {shown:.2f} µm/m)" in err
    assert shown > 900
    recording = read_mcap(out)
    # the same run through the library, bit for bit
    machine, sens = with_effects(
        "gravity_coupling,sample_clock_error",
        read_machine(data_path("machine_typical.toml")),
        read_sensor(sensor),
    )
    expected, expected_truth = simulate_run(read_program(program), machine, sens, seed=7)
    assert np.array_equal(recording.accel, expected.accel)
    assert np.array_equal(recording.time_ns, expected.time_ns)
    assert [(e.kind, e.time_ns) for e in recording.events] == [
        (e.kind, e.time_ns) for e in expected.events
    ]
    assert truth == json.loads(json.dumps(expected_truth))
    assert truth["seed"] == 7 and truth["clock_ppm"] == 50.0
    assert_allclose(truth["squareness_rad"], 15e-6, rtol=1e-12)
    assert_allclose(truth["servo_mismatch_rad"], 0.5e-3 * 1.0, rtol=1e-9)
    assert set(truth["effects"]) >= {"gravity_coupling", "sample_clock_error", "backlash"}


def test_simulate_defaults_and_no_events(tmp_path, capsys):
    program, _ = write_inputs(tmp_path)
    out = tmp_path / "run.mcap"
    truth_path = tmp_path / "t.json"
    args = ["simulate", "--program", str(program), "-o", str(out), "--no-events"]
    assert main([*args, "--truth", str(truth_path)]) == 0
    recording = read_mcap(out)
    assert recording.events == []
    assert recording.sample_rate_hz == 1000.0
    truth = json.loads(truth_path.read_text())
    assert truth["squareness_rad"] == 0.0 and isinstance(truth["seed"], int)
    assert truth["expected_squareness_rad"] == 0.0
    assert "truth squareness 0.00 µm/m; truth in" in capsys.readouterr().out
    assert len(truth["blocks"]) == 2


def test_simulate_user_errors_are_one_line(tmp_path):
    program, _ = write_inputs(tmp_path)
    bad = tmp_path / "m.toml"
    bad.write_text("[backlash]\nx_um = -1001\n")  # negative is over-compensated, allowed
    for extra, needle in (
        (["--effects", "wobble"], "unknown effect 'wobble'"),
        (["--machine", str(bad)], "[backlash] x_um must be in [-1000, 1000], got -1001.0"),
    ):
        argv = ["simulate", "--program", str(program), "-o", str(tmp_path / "r.mcap"), *extra]
        proc = subprocess.run(
            [sys.executable, "-m", "imu_square.cli", *argv],
            capture_output=True,
            text=True,
        )
        assert proc.returncode == 2
        lines = proc.stderr.strip().splitlines()
        assert len(lines) == 1 and needle in lines[0], proc.stderr


def test_simulate_stamps_the_time_it_ran_or_the_time_asked(tmp_path):
    before = time.time_ns()
    assert main(["simulate", "-o", str(tmp_path / "now.mcap"), "--seed", "1"]) == 0
    t0 = read_mcap(tmp_path / "now.mcap").time_ns[0]
    assert before - 1_000_000_000 <= t0 <= time.time_ns()
    argv = ["simulate", "-o", str(tmp_path / "then.mcap"), "--seed", "1"]
    assert main([*argv, "--start-time", "2026-09-01T02:30:00Z"]) == 0
    assert read_mcap(tmp_path / "then.mcap").time_ns[0] == 1_788_229_800_000_000_000
