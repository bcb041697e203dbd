"""Shared helpers of the acquisition tests: an emulated board in a thread, exact checks."""

import os
import threading
from contextlib import contextmanager

import numpy as np

from acquisition.emulator import emulated_board
from acquisition.faults import DAMAGED, SENT, SWALLOWED, parse_faults
from imu_square.io.runlog import parse_detail
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


def assert_accounted(recording, log):
    """The file holds exactly what the board's log says arrived intact, and counts the rest.

    Over the file's span, the samples stored are the samples the log marks as sent (no
    more: nothing damaged slipped through; no fewer: nothing intact was dropped), and the
    gap events add up to every other sample of the span. Every sample lost with intact
    bytes of its own was swallowed by damage next to it: a damaged or swallowed
    neighbour, or a garbage burst just before it or just after it.

    Returns
    -------
    dict
        Frames and samples per fate within the span, and the garbage bursts in it.
    """
    first, last = int(recording.seq[0]), int(recording.seq[-1])
    sent = log.seqs(SENT)
    np.testing.assert_array_equal(recording.seq, sent[(sent >= first) & (sent <= last)])
    gaps = [e for e in recording.events if e.kind == "gap" and e.time_ns <= recording.time_ns[-1]]
    lost = sum(int(parse_detail(e.detail)["lost"]) for e in gaps)
    assert recording.n_samples == last - first + 1 - lost
    assert log.undetected == []

    seq0 = np.asarray(log.seq0)
    fate = np.asarray(log.fate)
    inside = (seq0 >= first) & (seq0 <= last)
    bad = np.isin(fate, (DAMAGED, SWALLOWED))
    garbage_before = {s for s, _ in log.garbage_bursts}
    for j in np.flatnonzero(inside & (fate == SWALLOWED)):
        neighbours = bad[max(j - 1, 0)] or (j + 1 < fate.size and bad[j + 1])
        glued = seq0[j] in garbage_before or (j + 1 < seq0.size and seq0[j + 1] in garbage_before)
        assert neighbours or glued, f"frame at {seq0[j]} lost with no damage next to it"
    counts = {
        name: int(np.sum(inside & (fate == code)))
        for name, code in (("damaged", DAMAGED), ("swallowed", SWALLOWED))
    }
    counts["garbage"] = sum(first < s <= last for s, _ in log.garbage_bursts)
    return counts


def make_pty(link):
    """A bare pty whose slave end is symlinked at ``link``; returns the master's descriptor."""
    master, slave = os.openpty()
    name = os.ttyname(slave)
    os.close(slave)
    tmp = link.with_name("tmp-link")
    os.symlink(name, tmp)
    os.replace(tmp, link)
    return master
