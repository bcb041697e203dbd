"""Shared helpers of the acquisition tests: an emulated board in a thread, exact checks."""

import threading
from contextlib import contextmanager

import numpy as np

from acquisition.emulator import emulated_board
from acquisition.faults import parse_faults
from imu_square.program import program_from_mapping
from imu_square.simulate import data_path, read_machine, read_sensor

# A short test: r = 20 mm at 6000 mm/min (0.5 m/s^2, period 1.26 s), 3 cycles each way;
# 16.6 s of board time with the simulator's 3 s lead-in and lead-out.
PROGRAM = program_from_mapping(
    {"radius_mm": 20.0, "feed_mm_per_min": 6000.0, "cycles_per_direction": 3, "dwell_s": 0.5}
)
SQUARENESS_UM_PER_M = 80.0
MACHINE_TOML = f"""\
[machine]
name = "test"
ramp_s = 0.15
ramp_profile = "trapezoid"

[geometry]
machine_squareness_um_per_m = {SQUARENESS_UM_PER_M}
axis_length_mm = [400.0, 400.0]
axis_centre_mm = [0.0, 0.0]
"""


def write_inputs(folder):
    """Write the program and machine TOML files; return their paths."""
    program = folder / "program.toml"
    program.write_text(PROGRAM.to_toml(), encoding="utf-8")
    machine = folder / "machine.toml"
    machine.write_text(MACHINE_TOML, encoding="utf-8")
    return program, machine


@contextmanager
def running_board(folder, *, faults="", speed=20.0, seed=7, mode="binary", **kwargs):
    """An emulated board streaming in a thread; yields (board, truth)."""
    _, machine = write_inputs(folder)
    board, truth = emulated_board(
        PROGRAM,
        read_machine(machine),
        read_sensor(data_path("sensor_paper.toml")),
        faults=parse_faults(faults),
        seed=seed,
        link=folder / "board",
        speed=speed,
        mode=mode,
        **kwargs,
    )
    thread = threading.Thread(target=board.run, daemon=True)
    thread.start()
    assert board.ready.wait(10)
    try:
        yield board, truth
    finally:
        board.stop()
        thread.join(20)
        assert not thread.is_alive()


def sent_values(board, seq):
    """What the board sent for sequence numbers ``seq``, as the recorder must store it."""
    index = np.asarray(seq, np.int64) - board.seq[0]
    assert index.min() >= 0
    assert index.max() < len(board.counts)
    return (board.counts[index] * board.header.scale_m_s2_per_count).astype(np.float32)


def assert_exact(recording, board):
    """Every sample in the file is bit for bit what the board sent, on an exact time base."""
    np.testing.assert_array_equal(recording.accel, sent_values(board, recording.seq))
    expected_t = recording.time_ns[0] + (recording.seq - recording.seq[0]) * board.header.dt_ns
    np.testing.assert_array_equal(recording.time_ns, expected_t)
    assert recording.dt_ns == board.header.dt_ns
