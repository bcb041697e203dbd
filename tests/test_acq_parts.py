"""The recorder's parts on their own: faults, trigger, sequence stream, reader, progress, CLI."""

import io
import math
import os
import queue
import signal
import threading
import time
from dataclasses import replace

import numpy as np
import pytest
from acq_board import make_pty, running_board, write_inputs

from acquisition.faults import (
    DAMAGED,
    SENT,
    SWALLOWED,
    FaultInjector,
    FaultLog,
    FaultPlan,
    ReadBack,
    parse_faults,
)
from acquisition.progress import ProgressPrinter
from acquisition.protocol import DeviceHeader, SampleBlock, encode_block, encode_header
from acquisition.reader import SerialSupervisor
from acquisition.recorder import RecorderStatus, parse_block_marker
from acquisition.stream import SampleStream
from acquisition.trigger import ImmediateTrigger, MarkerTrigger, MotionTrigger, make_trigger
from imu_square.cli import main
from imu_square.errors import ConfigError, ImuSquareError
from imu_square.io.mcap import read_mcap

# -- faults ----------------------------------------------------------------------------------


def test_fault_spec_is_parsed_in_full():
    plan = parse_faults("corrupt=0.001, drop=0.0005,garbage=2,disconnect=30:5,clock_ppm=50")
    assert plan == FaultPlan(0.001, 0.0005, 2, ((30.0, 5.0),), 50.0)
    assert parse_faults("disconnect=9:1,disconnect=3:2").disconnects == ((3.0, 2.0), (9.0, 1.0))
    assert parse_faults("") == FaultPlan()


@pytest.mark.parametrize(
    ("spec", "message"),
    [
        ("corrupt=2", r"corrupt must be a probability in \[0, 1\), got '2'"),
        ("garbage=-1", r"garbage must be a whole number of bursts, got '-1'"),
        ("disconnect=30", r"disconnect must be AT:FOR in seconds .* got '30'"),
        ("disconnect=3:0", r"disconnect must be AT:FOR .* got '3:0'"),
        ("clock_ppm=fast", r"clock_ppm must be a number, got 'fast'"),
        ("jitter=1", r"unknown item 'jitter'; allowed: corrupt, drop"),
        ("corrupt", r"item must be key=value, got 'corrupt'"),
    ],
)
def test_bad_fault_spec_names_the_item(spec, message):
    with pytest.raises(ConfigError, match=message):
        parse_faults(spec)


def test_injector_damages_at_the_planned_rate_and_logs_every_byte():
    rng = np.random.default_rng(0)
    inj = FaultInjector(FaultPlan(corrupt_per_byte=0.01, drop_per_byte=0.01), 1000, rng)
    frame = bytes(range(1, 201))
    n_damaged = 0
    for _ in range(500):  # 100 000 bytes
        wire, damaged = inj.damage(frame)
        n_damaged += damaged
        assert damaged == (wire != frame)
    # Binomial counts: mean n p = 1000, sd ~ 31; 5 sd either way.
    assert abs(inj.log.bytes_corrupted - 1000) < 160
    assert abs(inj.log.bytes_dropped - 1000) < 160
    # A frame is damaged unless all 200 bytes escape both faults: 1 - 0.99**400 = 0.98.
    assert n_damaged == pytest.approx(500 * (1 - 0.99**400), abs=25)


def test_a_lost_delimiter_does_not_damage_a_frame_but_a_changed_one_does():
    rng = np.random.default_rng(1)
    inj = FaultInjector(FaultPlan(drop_per_byte=0.5), 10, rng)
    frame = b"\x00" + bytes(range(1, 9)) + b"\x00"
    for _ in range(200):
        wire, damaged = inj.damage(frame, delimited=True)
        assert damaged == (wire.strip(b"\x00") != frame[1:-1])
    inj = FaultInjector(FaultPlan(corrupt_per_byte=0.5), 10, rng)
    for _ in range(200):
        wire, damaged = inj.damage(frame, delimited=True)
        assert damaged == (wire != frame)


def test_garbage_bursts_are_spread_over_the_run_and_logged():
    inj = FaultInjector(FaultPlan(garbage_bursts=5), 10_000, np.random.default_rng(2))
    total = b"".join(inj.garbage_before(i, 100 + i) for i in range(0, 10_000, 25))
    assert len(inj.log.garbage_bursts) == 5
    assert len(total) == sum(n for _, n in inj.log.garbage_bursts)
    assert all(16 <= n <= 256 for _, n in inj.log.garbage_bursts)


READBACK_HEADER = DeviceHeader(
    model="rb",
    serial="1",
    firmware="1",
    sample_rate_hz=1000.0,
    dt_ns=1_000_000,
    scale_m_s2_per_count=1e-4,
    range_m_s2=10.0,
    noise_density_m_s2_rthz=math.nan,
    has_temperature=False,
)


def wire_fates(mode, damage, per_frame=1):
    """Fates the read-back gives six frames after ``damage(k, bytes) -> (bytes, damaged)``.

    ``damage`` may return bytes for frame k with a prefix (garbage) or cut short.
    """
    log = FaultLog()
    back = ReadBack(log, mode)
    back.restart()
    back.feed(encode_header(replace(READBACK_HEADER, mode=mode)))
    for k in range(6):
        counts = np.full((per_frame, 3), k + 1, np.int32)
        wire, damaged = damage(k, encode_block(SampleBlock(k * per_frame, counts), mode))
        log.add_frame(k * per_frame, per_frame, DAMAGED if damaged else SENT)
        back.feed(wire, k, k * per_frame, counts)
    back.finish()
    assert log.undetected == []
    return log.fate


def test_a_lost_newline_swallows_the_next_line_and_the_log_says_so():
    def drop_newline_of_2(k, line):
        return (line[:-1], True) if k == 2 else (line, False)

    assert wire_fates("line", drop_newline_of_2) == [SENT, SENT, DAMAGED, SWALLOWED, SENT, SENT]


def test_garbage_swallows_the_start_of_the_next_line():
    def garbage_before_4(k, line):
        return (b"\x07junk" + line, False) if k == 4 else (line, False)

    assert wire_fates("line", garbage_before_4) == [SENT, SENT, SENT, SENT, SWALLOWED, SENT]

    def garbage_ending_in_a_newline(k, line):  # a line of its own: nothing lost
        return (b"junk\n" + line, False) if k == 4 else (line, False)

    assert wire_fates("line", garbage_ending_in_a_newline) == [SENT] * 6


def test_a_harmless_change_is_logged_as_sent_and_two_lost_delimiters_merge_frames():
    def lower_case_checksum(k, line):  # the CRC's hex digits may be in either case
        if k != 1:
            return line, False
        assert line != line.lower(), "the checksum has a letter to change"
        return line.lower(), True

    fates = wire_fates("line", lower_case_checksum)
    assert fates == [SENT] * 6, "arrived intact although the injector damaged a byte"

    def drop_delimiters_between_1_and_2(k, frame):
        if k == 1:
            return frame[:-1], False  # one lost delimiter alone costs nothing
        if k == 2:
            return frame[1:], False
        return frame, False

    fates = wire_fates("binary", drop_delimiters_between_1_and_2, per_frame=25)
    assert fates == [SENT, SWALLOWED, SWALLOWED, SENT, SENT, SENT]


# -- trigger ---------------------------------------------------------------------------------


def rest_then_motion(n_rest, n_move, dt, noise, rng):
    t = np.arange(n_rest + n_move) * dt
    accel = rng.normal(0.0, noise, (t.size, 3))
    accel[:, 2] += 9.81
    accel[:, :2] += [0.02, -0.01]  # a tilted table: the rest level is not zero
    u = (t[n_rest:] - n_rest * dt) / 0.15
    accel[n_rest:, 1] += 0.5 * np.minimum(u, 1.0)  # a feed ramp: tangential acceleration
    return np.arange(t.size, dtype=np.int64) + 10_000, accel


def test_motion_trigger_fires_at_the_start_of_motion():
    dt = 1e-3
    rng = np.random.default_rng(3)
    seq, accel = rest_then_motion(3000, 2000, dt, 7e-6 * 9.81 * math.sqrt(500), rng)
    trigger = MotionTrigger(dt)
    fired = None
    for i in range(0, seq.size, 25):  # block by block, as the recorder feeds it
        fired = trigger.update(seq[i : i + 25], accel[i : i + 25])
        if fired is not None:
            break
    assert trigger.level_m_s2 == pytest.approx((0.02, -0.01), abs=1e-3)
    # The ramp reaches 6 sigma of a 20 ms mean within one window of the start.
    assert 13_000 - 20 <= fired <= 13_000 + 20


def test_motion_trigger_ignores_rest_and_a_single_spike():
    dt = 1e-3
    rng = np.random.default_rng(4)
    seq, accel = rest_then_motion(6000, 0, dt, 1e-3, rng)
    accel[4000:4010, 0] += 1.0  # a knock: one 20 ms window, shorter than hold_s
    assert MotionTrigger(dt).update(seq, accel) is None


def test_other_triggers():
    seq = np.arange(5, 10)
    assert ImmediateTrigger().update(seq, np.zeros((5, 3))) == 5
    assert MarkerTrigger().update(seq, np.zeros((5, 3))) is None
    assert MarkerTrigger().on_marker(7, "block_start ccw 0") == 7
    with pytest.raises(ImuSquareError, match=r"trigger must be one of .* got 'soon'"):
        make_trigger("soon", 1e-3)


def test_block_markers_become_block_events():
    assert parse_block_marker("block_start ccw 0") == ("block_start", "ccw", 0, "")
    assert parse_block_marker("block_end cw 13") == ("block_end", "cw", 13, "")
    assert parse_block_marker("M30 program end") == ("marker", "", -1, "M30 program end")


# -- sequence stream ---------------------------------------------------------------------------


def block(seq0, n):
    counts = np.arange(3 * n, dtype=np.int32).reshape(n, 3)
    return seq0 % 2**32, counts, np.full(n, np.nan)


def test_stream_unwraps_counts_gaps_and_drops_stale_blocks():
    s = SampleStream(0.5)
    seq, accel, temp, lost = s.push(*block(2**32 - 10, 5))
    assert seq.tolist() == list(range(2**32 - 10, 2**32 - 5)) and lost == 0
    np.testing.assert_array_equal(accel, (np.arange(15).reshape(5, 3) * 0.5).astype(np.float32))
    assert np.isnan(temp).all()
    seq, _, _, lost = s.push(*block(2**32 + 3, 5))  # raw seq wrapped to 3
    assert seq[0] == 2**32 + 3 and lost == 8
    assert s.push(*block(2**32 + 3, 5))[0] is None  # a repeated frame
    assert (s.stale, s.lost, s.last_seq) == (1, 8, 2**32 + 7)
    assert s.unwrap(2) == 2**32 + 2


# -- reader ------------------------------------------------------------------------------------


def wait_for(q, kind, timeout=5.0):
    deadline = time.monotonic() + timeout
    data = b""
    while time.monotonic() < deadline:
        try:
            item = q.get(timeout=0.1)
        except queue.Empty:
            continue
        if item[0] == kind:
            return item, data
        if item[0] == "data":
            data += item[1]
    raise AssertionError(f"no {kind!r} within {timeout} s")


def test_supervisor_reconnects_to_the_same_name(tmp_path):
    link = tmp_path / "board"
    master = make_pty(link)
    q = queue.Queue()
    sup = SerialSupervisor(str(link), 115200, q, backoff_s=0.01, backoff_max_s=0.05)
    sup.start()
    try:
        wait_for(q, "connect")
        assert sup.write(b"?\n")
        os.write(master, b"abc")
        time.sleep(0.1)
        assert os.read(master, 10) == b"?\n"
        os.close(master)  # unplugged
        link.unlink()
        _, data = wait_for(q, "disconnect")
        assert data == b"abc"
        master = make_pty(link)  # plugged back in, on another pty
        wait_for(q, "connect")
        os.write(master, b"xyz")
        time.sleep(0.2)
        items = []
        while not q.empty():
            items.append(q.get())
        assert b"".join(i[1] for i in items if i[0] == "data") == b"xyz"
        assert sup.reconnects == 1
    finally:
        sup.stop()
        os.close(master)


def test_record_names_a_missing_port(tmp_path, capsys):
    program, _ = write_inputs(tmp_path)
    argv = ["record", "--port", str(tmp_path / "nothing"), "--program", str(program)]
    assert main([*argv, "-o", str(tmp_path / "x.mcap")]) == 2
    err = capsys.readouterr().err
    assert f"serial port '{tmp_path / 'nothing'}' not found: is the board plugged in?" in err
    assert err.count("\n") == 1
    assert not (tmp_path / "x.mcap").exists()


def test_record_needs_a_board_that_talks(tmp_path, capsys):
    program, _ = write_inputs(tmp_path)
    link = tmp_path / "silent"
    master = make_pty(link)
    try:
        argv = ["record", "--port", str(link), "--program", str(program)]
        started = time.monotonic()
        code = main([*argv, "-o", str(tmp_path / "x.mcap"), "--header-timeout", "0.5"])
    finally:
        os.close(master)
    assert code == 2
    assert time.monotonic() - started < 5
    assert "no header from the board on" in capsys.readouterr().err
    assert not (tmp_path / "x.mcap").exists()


def test_sigterm_stops_cleanly_with_a_finished_file(tmp_path, capsys):
    program, _ = write_inputs(tmp_path)
    out = tmp_path / "run.mcap"
    argv = ["record", "--port", str(tmp_path / "board"), "--program", str(program)]
    with running_board(tmp_path, speed=5.0):
        timer = threading.Timer(1.0, os.kill, (os.getpid(), signal.SIGTERM))
        timer.start()
        code = main([*argv, "-o", str(out), "--duration", "60"])
        timer.join()
    assert code == 3, "stopped early: incomplete"
    assert "stopped: interrupted" in capsys.readouterr().err
    rec = read_mcap(out)  # finished: no warning about a cut file
    assert 2000 < rec.n_samples < 8000
    assert rec.events[-1].kind == "run_end"
    assert rec.events[-1].detail.startswith("stop=interrupted,")
    assert signal.getsignal(signal.SIGTERM) is signal.SIG_DFL


# -- progress ----------------------------------------------------------------------------------


def test_progress_is_a_bar_on_a_terminal_and_lines_otherwise():
    status = RecorderStatus(
        state="recording", samples_written=1500, recorded_s=1.5, expected_s=6.0, rate_hz=1000.0
    )
    out = io.StringIO()
    bar = ProgressPrinter(out, bar=True)
    bar(status)
    bar.close()
    assert out.getvalue().startswith("\r[######..................]  25% recording: 1500 samples")
    assert out.getvalue().endswith("\n")
    out = io.StringIO()
    bar = ProgressPrinter(out, bar=True)
    bar(status)
    assert bar.filter(None) is True  # a log line is coming: the bar is wiped first
    assert out.getvalue().endswith("\r\033[K")
    bar.close()
    assert not out.getvalue().endswith("\n"), "nothing left to end"
    out = io.StringIO()
    plain = ProgressPrinter(out, interval_s=60.0)
    plain(status)
    plain(status)  # within the interval: nothing more
    assert out.getvalue() == (
        "recording: 1500 samples, 1000 Hz, 1.5/6.0 s, gaps 0 (lost 0), CRC errors 0, reconnects 0\n"
    )


def test_a_board_that_restarts_ends_the_file_cleanly(tmp_path, capsys):
    program, _ = write_inputs(tmp_path)
    link = tmp_path / "board"
    master = make_pty(link)
    header = DeviceHeader(
        model="hand",
        serial="1",
        firmware="1",
        sample_rate_hz=1000.0,
        dt_ns=1_000_000,
        scale_m_s2_per_count=1e-4,
        range_m_s2=10.0,
        noise_density_m_s2_rthz=math.nan,
        has_temperature=False,
    )

    def board():  # 3 s of samples, then the counter starts again at 0 (a reset)
        time.sleep(0.3)
        frames = [encode_header(header)]
        frames += [
            encode_block(SampleBlock(s % 3000, np.ones((25, 3), np.int32)))
            for s in range(0, 4000, 25)
        ]
        os.write(master, b"".join(frames))

    feeder = threading.Timer(0.0, board)
    feeder.start()
    try:
        argv = ["record", "--port", str(link), "--program", str(program), "--duration", "60"]
        code = main([*argv, "-o", str(tmp_path / "run.mcap")])
    finally:
        feeder.join()
        os.close(master)
    assert code == 3
    assert "stopped: board restarted" in capsys.readouterr().err
    rec = read_mcap(tmp_path / "run.mcap")
    assert rec.seq.tolist() == list(range(3000))
    marker = next(e for e in rec.events if e.kind == "marker")
    assert marker.detail == "board restarted: sequence went back from 2999 to 0"


def test_emulate_refuses_to_replace_a_file(tmp_path, capsys):
    program, _ = write_inputs(tmp_path)
    precious = tmp_path / "data.txt"
    precious.write_text("keep me")
    argv = ["emulate", "--program", str(program), "--link", str(precious)]
    assert main(argv) == 2
    assert "exists and is not a symlink; refusing to replace it" in capsys.readouterr().err
    assert precious.read_text() == "keep me"
    assert main(["emulate", "--program", str(program), "--link", str(tmp_path / "no/x")]) == 2
    assert "does not exist" in capsys.readouterr().err


def test_a_repeated_frame_joined_to_new_ones_keeps_the_new_samples():
    s = SampleStream(1e-3)
    s.push(0, np.zeros((25, 3), np.int32), np.full(25, np.nan))
    s.push(25, np.zeros((25, 3), np.int32), np.full(25, np.nan))
    # One read: frame 25 again, then the new frames 50 and 75, joined into one run.
    counts = np.arange(75 * 3, dtype=np.int32).reshape(75, 3)
    seq, accel, temperature, lost = s.push(25, counts, np.full(75, np.nan))
    assert seq.tolist() == list(range(50, 100)) and lost == 0
    np.testing.assert_array_equal(accel, (counts[25:] * 1e-3).astype(np.float32))
    assert temperature.shape == (50,)
    assert (s.stale, s.lost, s.last_seq) == (1, 0, 99)
