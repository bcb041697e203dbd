"""Emulated board -> pseudo-terminal -> `imu-square record` -> MCAP -> analysis.

Every test runs the real emulator in a thread behind a real pty and the real
``record`` command; the board streams 20 times faster than real time, so the
16.6 s test takes about a second.
"""

import json
import os
import re
import signal
import subprocess
import sys
import threading
import time
import warnings

import numpy as np
import pytest
from acq_board import PROGRAM, assert_accounted, assert_exact, running_board, write_inputs

from acquisition.faults import NO_HOST, SENT
from acquisition.protocol import Parser, SampleBlock
from acquisition.reader import open_port
from imu_square.cli import main
from imu_square.errors import ImuSquareWarning
from imu_square.io.mcap import read_mcap
from imu_square.io.runlog import parse_detail
from imu_square.pipeline.squareness import AnalysisOptions, analyze


def record(tmp_path, *extra):
    program, _ = write_inputs(tmp_path)
    out = tmp_path / "run.mcap"
    argv = ["record", "--port", str(tmp_path / "board"), "--program", str(program)]
    code = main([*argv, "-o", str(out), *extra])
    return code, out


def events(recording, kind):
    return [e for e in recording.events if e.kind == kind]


def test_clean_run_is_exact_complete_and_gives_the_true_squareness(tmp_path, capsys):
    with running_board(tmp_path) as (board, truth):
        code, out = record(tmp_path, "--until-done", "--trigger", "motion")
    assert code == 0, capsys.readouterr().err
    rec = read_mcap(out)
    assert_exact(rec, board)
    assert rec.lost_samples == 0
    assert rec.program == PROGRAM
    assert rec.sensor.resolution_m_s2 == board.header.scale_m_s2_per_count

    # The motion trigger fires within 0.2 s after the true start of motion, and the
    # pre-trigger buffer keeps the rest before it (3 s, all the lead-in there is).
    dt_s = board.header.dt_ns * 1e-9
    start_seq = board.seq[0] + truth["blocks"][0]["start_s"] / dt_s
    (run_start,) = events(rec, "run_start")
    trigger_seq = rec.seq[0] + (run_start.time_ns - rec.time_ns[0]) / board.header.dt_ns
    assert 0 <= (trigger_seq - start_seq) * dt_s < 0.2
    assert rec.seq[0] == board.seq[0]
    # --until-done stops 2 s after the last block_end marker.
    end_seq = board.seq[0] + np.ceil(truth["blocks"][-1]["end_s"] / dt_s)
    assert rec.seq[-1] == end_seq + round(2.0 / dt_s) - 1
    kinds = [(e.kind, e.direction, e.block) for e in rec.events if e.kind.startswith("block")]
    assert kinds == [
        ("block_start", "ccw", 0),
        ("block_end", "ccw", 0),
        ("block_start", "cw", 1),
        ("block_end", "cw", 1),
    ]

    # Three cycles per direction: no bootstrap over so few cycles, and the type A
    # scatter of three pairs is no better known than the Cramer-Rao bound (~70 urad).
    result = analyze(rec, AnalysisOptions(bootstrap_n=0))
    u = max(result.u_squareness_rad, result.crb_rad)
    assert 0 < u < 150e-6
    assert abs(result.squareness_rad - truth["squareness_rad"]) < 3 * u


def test_marker_trigger_starts_at_the_first_block_marker(tmp_path, capsys):
    with running_board(tmp_path, seq_start=123) as (board, truth):
        code, out = record(tmp_path, "--trigger", "marker", "--pretrigger", "1", "--duration", "4")
    assert code == 0
    rec = read_mcap(out)
    assert_exact(rec, board)
    (run_start,) = events(rec, "run_start")
    first_block = next(e for e in rec.events if e.kind == "block_start")
    assert run_start.time_ns == first_block.time_ns
    trigger_seq = rec.seq[0] + (run_start.time_ns - rec.time_ns[0]) // board.header.dt_ns
    dt_s = board.header.dt_ns * 1e-9
    assert trigger_seq == board.seq[0] + np.ceil(truth["blocks"][0]["start_s"] / dt_s)
    assert rec.seq[0] == trigger_seq - 1000, "1 s kept before the trigger"
    assert rec.seq[-1] == trigger_seq + 4000 - 1, "4 s of board time after it"


def test_every_injected_fault_is_detected_and_no_bad_sample_is_stored(tmp_path, capsys):
    faults = "corrupt=0.0003,drop=0.0003,garbage=4"
    with running_board(tmp_path, faults=faults, seq_start=2**32 - 5000) as (board, _):
        code, out = record(tmp_path, "--until-done")
    assert code == 3, "an incomplete run has its own exit code"
    assert "incomplete recording" in capsys.readouterr().err
    rec = read_mcap(out)
    # The file spans the 32-bit wrap of the board's counter.
    assert rec.seq[0] < 2**32 < rec.seq[-1]
    assert_exact(rec, board)
    # Stored == what the board's wire log says arrived intact; gap events == the rest.
    counts = assert_accounted(rec, board.log)
    assert counts["damaged"] > 0 and counts["garbage"] > 0
    reported_lost = sum(int(parse_detail(e.detail)["lost"]) for e in events(rec, "gap"))

    # Each damaged frame and each garbage burst is one rejected chunk at least.
    crc = sum(int(parse_detail(e.detail)["count"]) for e in events(rec, "crc_error"))
    assert crc >= counts["damaged"] + counts["garbage"]
    (run_end,) = events(rec, "run_end")
    assert f"crc_errors={crc}," in run_end.detail
    assert f"lost={reported_lost}," in run_end.detail


def test_line_mode_with_faults_is_exact(tmp_path, capsys):
    # One line per sample: 3 kHz of lines keeps the board and the recorder (one process,
    # one GIL) ahead of the stream. Garbage over the 16.9 s run: about 3 bursts in 4 s.
    faults = "corrupt=0.0005,drop=0.0003,garbage=12"
    with running_board(tmp_path, faults=faults, mode="line", speed=3.0) as (board, _):
        code, out = record(tmp_path, "--duration", "4")
    assert code == 3
    rec = read_mcap(out)
    assert_exact(rec, board)
    assert rec.seq[-1] - rec.seq[0] + 1 == 4000, "--duration counts board time"
    # Exact, as in binary mode: a line whose newline is lost merges with the next, and a
    # garbage burst glues itself to the start of the next line; the log knows both.
    counts = assert_accounted(rec, board.log)
    assert counts["damaged"] > 0 and counts["swallowed"] > 0 and counts["garbage"] > 0
    assert rec.n_samples > 3500


def test_unplugging_leaves_one_gap_of_the_right_length(tmp_path, capsys):
    with running_board(tmp_path, faults="disconnect=6:2") as (board, _):
        code, out = record(tmp_path, "--until-done")
    assert code == 3
    with warnings.catch_warnings():
        warnings.simplefilter("error", ImuSquareWarning)
        rec = read_mcap(out)  # a valid, finished file: no warning
    assert_exact(rec, board)
    ((first_lost, n_lost),) = board.log.disconnects
    assert n_lost >= 2000, "2 s of board time at 1 kHz, plus the time to reconnect"
    ((index, lost),) = rec.gaps()
    assert (rec.seq[index - 1] + 1, lost) == (first_lost, n_lost)
    (gap,) = events(rec, "gap")
    assert gap.detail == f"lost={n_lost},lost_s={n_lost * 1e-3:.3f}"
    (reconnect,) = events(rec, "reconnect")
    assert reconnect.time_ns == rec.time_ns[index]
    assert set(board.log.seqs(NO_HOST).tolist()) >= set(range(first_lost, first_lost + n_lost))


@pytest.mark.slow
def test_kill_9_loses_at_most_the_last_second(tmp_path, capsys):
    program, _ = write_inputs(tmp_path)
    out = tmp_path / "run.mcap"
    cmd = [
        os.path.join(os.path.dirname(sys.executable), "imu-square"),
        "record",
        "--port",
        str(tmp_path / "board"),
        "--program",
        str(program),
        "-o",
        str(out),
        "--duration",
        "60",
    ]
    with running_board(tmp_path, speed=1.0) as (board, _):
        proc = subprocess.Popen(cmd, stderr=subprocess.DEVNULL)
        deadline = time.monotonic() + 30
        while sum(board.log.n) < 4000 and time.monotonic() < deadline:
            time.sleep(0.05)
        os.kill(proc.pid, signal.SIGKILL)
        n_frames = len(board.log.seq0)
        proc.wait(10)
    sent = [
        s
        for s, n, f in zip(board.log.seq0[:n_frames], board.log.n, board.log.fate, strict=False)
        if f == SENT
    ]
    last_sent = sent[-1] + board.log.n[n_frames - 1] - 1
    assert proc.returncode == -signal.SIGKILL

    fixed = tmp_path / "fixed.mcap"
    capsys.readouterr()
    assert main(["recover", str(out), "-o", str(fixed)]) == 0
    said = capsys.readouterr().out  # recover's result
    assert re.search(r"recovered \d+ samples .* cut at byte \d+", said), said
    rec = read_mcap(fixed)
    assert_exact(rec, board)
    assert rec.lost_samples == 0
    lost_s = (last_sent - rec.seq[-1]) * board.header.dt_ns * 1e-9
    # Flushed (chunk closed and fsynced) every second of host time; a little more for
    # the frames in flight in the pty and the reader queue.
    assert 0 <= lost_s <= 1.2
    assert rec.n_samples >= 2500


def test_emulate_command_writes_truth_and_fault_log(tmp_path, capsys):
    program, machine = write_inputs(tmp_path)
    link = tmp_path / "board"
    argv = ["emulate", "--program", str(program), "--machine", str(machine), "--link", str(link)]
    argv += ["--speed", "50", "--seed", "3", "--faults", "drop=0.001,clock_ppm=50"]
    received = bytearray()

    def host():  # reads until the board falls silent, then lets go of the port
        deadline = time.monotonic() + 10
        while not link.exists() and time.monotonic() < deadline:
            time.sleep(0.01)
        port = open_port(str(link), 921600, 0.3)
        port.write(b"?\n")
        while chunk := port.read(65536):
            received.extend(chunk)
        port.close()

    reader = threading.Thread(target=host)
    reader.start()
    assert main(argv) == 0
    reader.join(10)
    printed = capsys.readouterr().out.strip()
    assert printed == str(link) + ".truth.json"
    truth = json.loads(open(printed, encoding="utf-8").read())
    assert truth["clock_ppm"] == 50.0
    assert truth["effects"]["sample_clock_error"] == {"ppm": 50.0}
    summary = truth["emulator"]["log"]["summary"]
    assert summary["bytes_dropped"] > 0
    lost = summary["samples_damaged"] + summary["samples_swallowed"]
    assert summary["samples_sent"] + lost == truth["n_samples"]
    parser = Parser()
    blocks = [m for m in parser.feed(bytes(received)) if isinstance(m, SampleBlock)]
    assert sum(b.n_samples for b in blocks) == summary["samples_sent"]
    assert parser.stats.crc_errors == summary["frames_damaged"]
    assert not link.exists(), "the board removes its link when done"


@pytest.mark.slow
def test_light_byte_errors_leave_a_run_that_analyses_like_the_clean_one(tmp_path, capsys):
    # A USB-serial link at a few errors per 10^4 bytes loses ~3 % of the samples in
    # short gaps: every cycle holds one. The samples that survive are analysed, and
    # the result stays within what those lost samples can move it.
    clean_dir, faulty_dir = tmp_path / "clean", tmp_path / "faulty"
    clean_dir.mkdir()
    faulty_dir.mkdir()
    with running_board(clean_dir) as (board, truth):
        code, out = record(clean_dir, "--until-done", "--trigger", "motion")
    assert code == 0
    clean = read_mcap(out)
    assert_exact(clean, board)
    faults = "corrupt=1e-4,drop=5e-5,garbage=1"
    with running_board(faulty_dir, faults=faults) as (board, _):
        code, out = record(faulty_dir, "--until-done", "--trigger", "motion")
    assert code == 3, "gaps make an incomplete run"
    faulty = read_mcap(out)
    assert_exact(faulty, board)
    span = faulty.seq[-1] - faulty.seq[0] + 1
    lost = 1 - faulty.n_samples / span
    assert len(faulty.gaps()) >= 5 and 0.005 < lost < 0.1

    opts = AnalysisOptions(bootstrap_n=0)
    a, b = analyze(clean, opts), analyze(faulty, opts)
    assert b.cycles_used == a.cycles_used, "no cycle dropped for a short gap"
    assert b.quality["gaps_bridged"] == len(faulty.gaps())
    # Same samples but the lost ones: the two results differ by the information in
    # the lost fraction, sd ~ sqrt(lost / (1 - lost)) of one run's (the CRB here).
    u_diff = a.crb_rad * np.sqrt(lost / (1 - lost))
    assert abs(b.squareness_rad - a.squareness_rad) < 4 * u_diff
    # ...and both lie within their stated uncertainty of the truth (k from Student's t).
    for r in (a, b):
        u = max(r.u_squareness_expanded_rad, 2 * r.crb_rad)
        assert abs(r.squareness_rad - truth["expected_squareness_rad"]) < u
