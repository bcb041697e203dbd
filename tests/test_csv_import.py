"""CSV import: exact times, gaps as events, units checked against gravity, clear errors."""

from pathlib import Path

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from imu_square.errors import ImuSquareError, RecordingError
from imu_square.io.csv import read_csv
from imu_square.program import TestProgram
from imu_square.units import G

REAL = Path("/work/shared/realdata")
KLIPPER = REAL / "beattune-core__shaketune-cli-docker__raw_data_x_lis2dw_20260423_171429.HEAD50.csv"
PHONE = REAL / "Inkering__printnoser__rectangle_1__accel.csv"

HEADER = "time_s,accel_x,accel_y,accel_z"


def write(tmp_path, text, name="data.csv"):
    path = tmp_path / name
    path.write_text(text)
    return path


def level_rows(n=50, t0="1700000000.000000000", dt_ns=1_000_000, scale=1.0, skip=()):
    """CSV rows of a level sensor at rest: z reads 1 g (times as exact decimal strings)."""
    sec, frac = t0.split(".")
    base = int(sec) * 10**9 + int(frac)
    rows = []
    for k in range(n):
        if k in skip:
            continue
        t = base + k * dt_ns
        z = (G + 0.001 * (k % 7)) * scale
        rows.append(f"{t // 10**9}.{t % 10**9:09d},{0.01 * scale * (k % 3):.6f},0,{z:.6f}")
    return rows


def test_imu_square_format_keeps_times_exact(tmp_path):
    # 1700000000.000000001 s cannot be held by a float64 (its spacing there is ~240 ns).
    rows = level_rows(n=40, t0="1700000000.000000001", dt_ns=250_000)
    path = write(tmp_path, "\n".join([HEADER, *rows]) + "\n")
    rec = read_csv(path, TestProgram(), machine_id="m7")
    assert rec.n_samples == 40 and rec.dt_ns == 250_000
    assert rec.time_ns[0] == 1_700_000_000_000_000_001
    assert_array_equal(np.diff(rec.time_ns), 250_000)
    assert_array_equal(rec.seq, np.arange(40))
    expected_z = np.array([float(f"{G + 0.001 * (k % 7):.6f}") for k in range(40)])
    assert_array_equal(rec.accel[:, 2], expected_z.astype(np.float32))
    assert rec.accel.dtype == np.float32 and rec.machine_id == "m7"
    assert rec.program == TestProgram() and rec.events == []
    assert rec.metadata == {
        "producer": "imu-square import",
        "source_file": "data.csv",
        "source_format": "imu-square",
    }


def test_gaps_become_events_and_sequence_jumps_never_samples(tmp_path):
    rows = level_rows(n=100, skip={10, 11, 12, 50})  # 3 lost, then 1 lost
    path = write(tmp_path, "\n".join([HEADER, *rows]))
    rec = read_csv(path, None, relative_time=True)
    assert rec.n_samples == 96 and rec.dt_ns == 1_000_000
    assert rec.gaps() == [(10, 3), (47, 1)]
    assert rec.lost_samples == 4 and rec.seq[-1] == 99
    assert [(e.kind, e.detail) for e in rec.events] == [("gap", "lost=3"), ("gap", "lost=1")]
    assert rec.events[0].time_ns == rec.time_ns[10] == rec.time_ns[0] + 13_000_000


def test_temperature_column_and_comment_lines(tmp_path):
    rows = [r + f",{20 + 0.5 * i}" for i, r in enumerate(level_rows(n=5))]
    text = "# logger v2\n# units: s, m/s^2, degC\n" + HEADER + ",temperature_c\n" + "\n".join(rows)
    rec = read_csv(write(tmp_path, text), None, relative_time=True)
    assert_array_equal(rec.temperature_c, [20, 20.5, 21, 21.5, 22])


@pytest.mark.skipif(not KLIPPER.exists(), reason="real Klipper fixture not available")
def test_real_klipper_capture():
    rec = read_csv(KLIPPER, None, relative_time=True, fmt="klipper")
    assert rec.n_samples == 50
    # First row: 76.666231,267.996131,210.568389,9762.716208 (mm/s^2).
    assert rec.time_ns[0] == 76_666_231_000
    assert_allclose(rec.accel[0], [0.267996131, 0.210568389, 9.762716208], rtol=1e-7)
    assert rec.dt_ns == 623_000  # LIS2DW at ~1600 Hz, host-stamped with 1 us resolution
    assert rec.lost_samples == 0
    assert "mm/s^2 -> m/s^2" in rec.processing[0]


@pytest.mark.skipif(not KLIPPER.exists(), reason="real Klipper fixture not available")
def test_klipper_file_under_the_default_format_points_to_klipper():
    with pytest.raises(RecordingError, match=r"Klipper header .* use --format klipper"):
        read_csv(KLIPPER, None, relative_time=True)


@pytest.mark.skipif(not PHONE.exists(), reason="real phone recording not available")
def test_real_phone_recording_needs_its_columns_named():
    with pytest.raises(
        RecordingError,
        match=r"line 4: header must be 'time_s,accel_x,accel_y,accel_z'.*got "
        r"'t_s,ax_mps2,ay_mps2,az_mps2'; name the columns to use with --columns",
    ):
        read_csv(PHONE, None, relative_time=True)
    rec = read_csv(
        PHONE, None, relative_time=True, columns=["t_s", "ax_mps2", "ay_mps2", "az_mps2"]
    )
    assert rec.n_samples == 3145 and rec.dt_ns == 10_000_000
    assert_allclose(rec.accel[0], [0.299228, 0.082329, 9.695189], rtol=1e-7)
    assert_allclose(np.linalg.norm(rec.accel.mean(axis=0)), G, rtol=0.01)


@pytest.mark.parametrize(
    ("fmt", "scale", "message"),
    [
        (
            "imu-square",
            1e3,
            r"gravity axis z reads 98\d\d on average: this looks like mm/s\^2, "
            r"but format 'imu-square' expects m/s\^2; use --format klipper$",
        ),
        (
            "klipper",
            1.0,
            r"gravity axis z reads 9.8\d* on average: this looks like m/s\^2, "
            r"but format 'klipper' expects mm/s\^2; use --format imu-square$",
        ),
        (
            "imu-square",
            1 / G,
            r"reads 1 on average: this looks like g, but format 'imu-square' "
            r"expects m/s\^2; convert the data to m/s\^2 \(multiply by 9\.80665\)$",
        ),
        (
            # A logger writing mg: 1000 on the gravity axis is 1 g, not "no unit".
            "imu-square",
            1e3 / G,
            r"reads 1000 on average: this looks like mg, but format 'imu-square' "
            r"expects m/s\^2; convert the data to m/s\^2 \(multiply by 0\.00980665\)$",
        ),
        (
            "imu-square",
            0.01,
            r"gravity axis z reads 0.098\d* on average, which is not 1 g in any "
            r"unit .* --gravity-axis",
        ),
    ],
)
def test_units_are_checked_against_gravity(tmp_path, fmt, scale, message):
    header = "#time,accel_x,accel_y,accel_z" if fmt == "klipper" else HEADER
    path = write(tmp_path, "\n".join([header, *level_rows(scale=scale)]))
    with pytest.raises(RecordingError, match=message):
        read_csv(path, None, relative_time=True, fmt=fmt)


def test_gravity_axis_must_match_the_data(tmp_path):
    path = write(tmp_path, "\n".join([HEADER, *level_rows()]))
    assert read_csv(path, None, relative_time=True, gravity_axis="z").n_samples == 50
    with pytest.raises(RecordingError, match=r"gravity axis -z was given.*largest on z"):
        read_csv(path, None, relative_time=True, gravity_axis="-z")
    with pytest.raises(RecordingError, match=r"gravity axis x was given.*largest on z"):
        read_csv(path, None, relative_time=True, gravity_axis="x")
    with pytest.raises(ImuSquareError, match=r"gravity_axis must be one of .* got 'up'"):
        read_csv(path, None, relative_time=True, gravity_axis="up")


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("", r"data.csv: the CSV file is empty"),
        ("\n\n  \n", r"data.csv: the CSV file is empty"),
        ("time,ax,ay,az\n0,0,0,9.8\n", r"data.csv: line 1: header must be 'time_s,accel_x"),
        (f"{HEADER}\n0.000,0,0,9.8\n", r"data.csv: needs at least 2 samples, got 1"),
        (f"{HEADER}\n0.000,0,0,9.8\n0.001,0,x,9.8\n", r"line 3, column accel_y: not a number: 'x'"),
        (
            f"{HEADER}\n0.000,0,0,9.8\n0.001,0,nan,9.8\n",
            r"line 3, column accel_y: value must be "
            r"finite, got 'nan'",
        ),
        (f"{HEADER}\n0.000,0,0,9.8\n0.001,inf,0,9.8\n", r"line 3, column accel_x: .*'inf'"),
        (
            f"{HEADER}\n0.000,0,0,9.8\nabc,0,0,9.8\n",
            r"line 3, column time_s: not a finite number "
            r"of seconds: 'abc'",
        ),
        (f"{HEADER}\n0.000,0,0,9.8\nnan,0,0,9.8\n", r"line 3, column time_s"),
        (
            f"{HEADER}\n0.000,0,0,9.8\n0.002,0,0,9.8\n0.002,0,0,9.8\n",
            r"line 4: time 0.002 s does "
            r"not increase \(previous line has 0.002 s\)",
        ),
        (
            f"{HEADER}\n0.000,0,0,9.8\n0.001,0,0\n",
            r"line 3: expected 4 cells like the header, "
            r"got 3",
        ),
    ],
)
def test_errors_name_file_and_line(tmp_path, text, message):
    path = write(tmp_path, text)
    with pytest.raises(RecordingError, match=message) as exc:
        read_csv(path, None, relative_time=True)
    assert "\n" not in str(exc.value)


def test_missing_file(tmp_path):
    with pytest.raises(RecordingError, match=r"nope.csv: CSV file not found"):
        read_csv(tmp_path / "nope.csv", None, relative_time=True)


def test_columns_mapping_errors(tmp_path):
    path = write(tmp_path, "t,a,b,c\n0,0,0,9.8\n0.001,0,0,9.8\n")
    rec = read_csv(path, None, relative_time=True, columns=["t", "a", "b", "c"])
    assert rec.n_samples == 2
    with pytest.raises(RecordingError, match=r"header 't,a,b,c' has no column 'd'"):
        read_csv(path, None, relative_time=True, columns=["t", "a", "b", "d"])
    with pytest.raises(RecordingError, match=r"columns must name time, x, y, z"):
        read_csv(path, None, relative_time=True, columns=["t", "a"])
