"""End to end through the CLI: import a CSV, inspect the MCAP, recover a cut one."""

import json
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from imu_square.cli import main
from imu_square.io.mcap import RecordingWriter, read_mcap
from imu_square.io.recording import Event

REAL = Path("/work/shared/realdata")
KLIPPER = REAL / "beattune-core__shaketune-cli-docker__raw_data_x_lis2dw_20260423_171429.HEAD50.csv"
PHONE = REAL / "Inkering__printnoser__rectangle_1__accel.csv"
PROGRAM = """\
[program]
radius_mm = 100.0
feed_mm_per_min = 6000.0
cycles_per_direction = 15
"""
# The CSVs count seconds from the logger's power-on: import needs the start.
START = "2026-09-01T02:30:00Z"


@pytest.fixture
def program(tmp_path):
    path = tmp_path / "p.toml"
    path.write_text(PROGRAM)
    return str(path)


def _csv(tmp_path, n=2000, skip=(500, 501)):
    lines = ["time_s,accel_x,accel_y,accel_z"]
    for k in range(n):
        if k not in skip:
            lines.append(f"{k / 1000:.3f},0.01,-0.02,{9.80665 + 0.001 * (k % 5):.5f}")
    path = tmp_path / "data.csv"
    path.write_text("\n".join(lines) + "\n")
    return str(path)


def test_import_then_info(tmp_path, program, capsys):
    out = str(tmp_path / "run.mcap")
    code = main(
        [
            "import",
            "--start-time",
            START,
            _csv(tmp_path),
            "--program",
            program,
            "-o",
            out,
            "--machine-id",
            "VF2",
        ]
    )
    captured = capsys.readouterr()
    assert code == 0 and captured.err == ""  # the summary is the result: on stdout
    assert captured.out.strip() == (
        f"imported 1998 samples (1.999 s at 1000 Hz, 1 gaps, 2 lost) from "
        f"{tmp_path / 'data.csv'} to {out}"
    )

    assert main(["info", out]) == 0
    text = capsys.readouterr().out
    assert f"{out}: complete" in text
    assert "samples    1998 over 1.999 s at 1000 Hz (dt 1000000 ns)" in text
    assert "gaps       1 (2 samples lost)" in text
    # 500 samples before the gap (5 batches of 100, 50 previews of 10 samples), 1498 after
    # (14 batches of 100 and one of 98, 150 previews); one gap event.
    assert "/imu/accel 20, /imu/preview 200, /test/events 1" in text
    assert "program    r=100 mm, v=6000 mm/min, 15 cycles x 2 blocks" in text
    assert "machine    VF2" in text and "events     gap 1" in text

    assert main(["info", out, "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["samples"] == 1998 and info["gaps"] == {"count": 1, "lost": 2}
    assert info["file"]["complete"] is True
    assert info["file"]["messages"] == {"/imu/accel": 20, "/imu/preview": 200, "/test/events": 1}
    assert info["program"]["radius_mm"] == 100.0 and info["machine_id"] == "VF2"


def test_import_refuses_wrong_units_in_one_line(tmp_path, program, capsys):
    path = tmp_path / "mm.csv"
    path.write_text("time_s,accel_x,accel_y,accel_z\n0,0,0,9806\n0.001,0,0,9807\n")
    code = main(
        [
            "import",
            "--start-time",
            START,
            str(path),
            "--program",
            program,
            "-o",
            str(tmp_path / "x.mcap"),
        ]
    )
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1
    assert "looks like mm/s^2, but format 'imu-square' expects m/s^2; use --format klipper" in err
    assert not (tmp_path / "x.mcap").exists()


@pytest.mark.skipif(not KLIPPER.exists(), reason="real Klipper fixture not available")
def test_import_real_klipper_capture(tmp_path, program, capsys):
    out = str(tmp_path / "klipper.mcap")
    assert (
        main(
            [
                "import",
                "--relative-time",
                str(KLIPPER),
                "--program",
                program,
                "-o",
                out,
                "--format",
                "klipper",
            ]
        )
        == 0
    )
    assert "imported 50 samples" in capsys.readouterr().out
    rec = read_mcap(out)
    assert rec.time_ns[0] == 76_666_231_000 and rec.dt_ns == 623_000
    np.testing.assert_allclose(rec.accel[0, 2], 9.762716208, rtol=1e-7)


@pytest.mark.skipif(not PHONE.exists(), reason="real phone recording not available")
def test_import_real_phone_recording_as_a_user_would(tmp_path, program, capsys):
    out = str(tmp_path / "phone.mcap")
    assert main(["import", "--start-time", START, str(PHONE), "--program", program, "-o", out]) == 2
    assert "--columns" in capsys.readouterr().err
    columns = "t_s,ax_mps2,ay_mps2,az_mps2"
    assert (
        main(
            [
                "import",
                "--start-time",
                START,
                str(PHONE),
                "--program",
                program,
                "-o",
                out,
                "--columns",
                columns,
            ]
        )
        == 0
    )
    assert "imported 3145 samples (31.368 s at 100 Hz" in capsys.readouterr().out


def test_recover_a_cut_recording(tmp_path, capsys):
    whole = tmp_path / "whole.mcap"
    n = 6000
    t = 5_000_000_000 + np.arange(n) * 1_000_000
    with RecordingWriter(whole, dt_ns=1_000_000, chunk_size=8192) as w:
        w.write_event(Event(int(t[10]), "block_start", "ccw", 0))
        w.write_samples(np.arange(n), t, np.tile([0.0, 0.0, 9.8], (n, 1)))
    data = whole.read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: len(data) // 2])
    fixed = tmp_path / "fixed.mcap"

    assert main(["info", str(cut)]) == 3, "a cut file is incomplete"
    assert (
        "INCOMPLETE: it ends in the middle of a record; read up to byte" in capsys.readouterr().out
    )

    assert main(["recover", str(cut), "-o", str(fixed)]) == 0
    err = capsys.readouterr().out
    rec = read_mcap(fixed)  # whole again: no warning
    assert 0 < rec.n_samples < n
    assert err.startswith(
        f"recovered {rec.n_samples} samples ({rec.duration_s:.3f} s) and 1 events; "
        f"the file was cut at byte "
    )
    assert f" of {len(data) // 2}, after time {t[rec.n_samples - 1] * 1e-9:.3f} s" in err

    garbage = tmp_path / "garbage.mcap"
    garbage.write_bytes(data[:100])
    assert main(["recover", str(garbage), "-o", str(tmp_path / "none.mcap")]) == 2
    assert "no complete samples" in capsys.readouterr().err


def test_installed_script_prints_json(tmp_path, program):
    out = tmp_path / "run.mcap"
    assert (
        main(
            [
                "import",
                "--start-time",
                START,
                _csv(tmp_path, n=300, skip=()),
                "--program",
                program,
                "-o",
                str(out),
            ]
        )
        == 0
    )
    script = Path(sys.executable).with_name("imu-square")
    result = subprocess.run(
        [str(script), "info", str(out), "--json"], capture_output=True, text=True, check=True
    )
    assert json.loads(result.stdout)["samples"] == 300


def test_import_with_a_range_lets_the_analysis_see_clipping(tmp_path, capsys):
    from imu_square.program import read_program
    from imu_square.simulate import simulate_run

    prog_path = tmp_path / "p.toml"
    prog_path.write_text(
        "[program]\nradius_mm = 25.0\nfeed_mm_per_min = 9000.0\ncycles_per_direction = 6\n"
    )
    rec, _ = simulate_run(read_program(prog_path), seed=1)
    accel = rec.accel.astype(np.float64)
    t = rec.time_s
    # A saturating burst of 20 samples (2 g on x) in the CW block (it runs 12.5-19.9 s).
    i = int(np.searchsorted(t, 14.0))
    accel[i : i + 20, 0] = 2 * 9.80665
    csv = tmp_path / "run.csv"
    rows = "\n".join(
        f"{ts:.6f},{x:.6f},{y:.6f},{z:.6f}" for ts, (x, y, z) in zip(t, accel, strict=True)
    )
    csv.write_text("time_s,accel_x,accel_y,accel_z\n" + rows + "\n")
    used = {}
    for extra in ([], ["--range-g", "2"]):
        out = tmp_path / f"run{len(extra)}.mcap"
        argv = [
            "import",
            "--start-time",
            START,
            str(csv),
            "--program",
            str(prog_path),
            "-o",
            str(out),
            *extra,
        ]
        assert main(argv) == 0
        capsys.readouterr()
        assert main(["analyze", str(out), "--json"]) == 0
        used[bool(extra)] = json.loads(capsys.readouterr().out)["cycles_used"]
    assert read_mcap(out).sensor.range_m_s2 == pytest.approx(2 * 9.80665)
    # Without the range the burst is invisible; with it, the cycles it touches (the
    # burst plus the filter's settling time) are dropped.
    assert used[False] == {"ccw": 6, "cw": 6}
    assert used[True]["ccw"] == 6 and 4 <= used[True]["cw"] <= 5


def test_import_refuses_a_nonsense_range(tmp_path, program, capsys):
    csv = tmp_path / "x.csv"
    csv.write_text("time_s,accel_x,accel_y,accel_z\n0,0,0,9.81\n0.001,0,0,9.81\n")
    argv = [
        "import",
        "--start-time",
        START,
        str(csv),
        "--program",
        str(program),
        "-o",
        str(tmp_path / "x.mcap"),
    ]
    assert main([*argv, "--range-g", "-1"]) == 2
    assert "--range-g must be a number > 0, got -1.0" in capsys.readouterr().err


def test_import_takes_the_start_time_and_refuses_a_clock_since_power_on(tmp_path, program, capsys):
    # Times from 0 are no date: stored as they are, a night would be dated 1970.
    csv = _csv(tmp_path)
    out = str(tmp_path / "r.mcap")
    assert main(["import", csv, "--program", program, "-o", out]) == 2
    err = capsys.readouterr().err
    assert re.search(r"its times start at 0\.0+ s, which is no date .* --start-time", err)
    assert err.count("\n") == 1 and not Path(out).exists()
    argv = ["import", csv, "--program", program, "-o", out, "--start-time"]
    assert main([*argv, "2026-09-01T04:30:00+02:00"]) == 0
    assert read_mcap(out).time_ns[0] == 1_788_229_800_000_000_000  # 02:30 UTC
    for bad, why in (
        ("2026-09-01T02:30:00", "must say its time zone"),
        ("1999-12-31T23:00:00Z", "must be in 2000 or later"),
        ("yesterday", "must be a date and time like"),
    ):
        assert main([*argv, bad]) == 2
        assert why in capsys.readouterr().err


def test_import_checks_the_machine_against_the_monitor_file(tmp_path, capsys):
    monitor = tmp_path / "monitor.toml"
    monitor.write_text('[monitor]\nmachine_id = "mill-3"\nhistory = "h.db"\n')
    csv, out = _csv(tmp_path), str(tmp_path / "r.mcap")
    argv = ["import", csv, "--config", str(monitor), "-o", out, "--start-time", START]
    assert main([*argv, "--machine-id", "mill-4"]) == 2
    assert "--machine-id 'mill-4' is not the machine of" in capsys.readouterr().err
    assert main(argv) == 0
    recording = read_mcap(out)
    assert recording.machine_id == "mill-3"
    assert recording.program.radius_m == pytest.approx(0.1)  # the monitor's: the paper's test
