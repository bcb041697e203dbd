"""A board that goes away for good is never a clean run.

The emulator runs as its own process (``imu-square emulate``) behind a real
pty and is killed with SIGKILL or SIGTERM at a chosen moment of the test;
``imu-square record --until-done --trigger marker`` records it. The missing
tail must be a ``gap`` event of the exact length up to where the recorder
stopped, the exit code 3, and ``info`` and ``analyze`` must say why.
"""

import json
import logging
import math
import os
import signal
import subprocess
import sys
import threading
import time
import warnings

import numpy as np
import pytest
from acq_board import PROGRAM, make_pty, write_inputs
from doc_quotes import quoted_form

from acquisition.faults import SENT
from acquisition.protocol import DeviceHeader, SampleBlock, encode_block, encode_header
from acquisition.recorder import until_done_margin_s
from imu_square.cli import main
from imu_square.errors import ImuSquareWarning
from imu_square.io.mcap import read_mcap
from imu_square.io.runlog import parse_detail, run_outcome

SPEED = 10.0
SCRIPT = os.path.join(os.path.dirname(sys.executable), "imu-square")
# The test program's blocks in board time (simulator truth, see acq_board.PROGRAM): the
# first block_start marker (the trigger) at 3.0 s, block 0 until 8.18 s, block 1 from 8.68
# to 13.85 s; --until-done stops 2 s after the last block_end marker.
TRIGGER_S = 3.0
LAST_BLOCK_END_S = 13.853


def read_run(path):
    """The recording, with the warning every reader gives about its missing end."""
    with pytest.warns(ImuSquareWarning, match="the run's end is missing") as caught:
        rec = read_mcap(path)
    assert len(caught) == 1
    return rec


class KillAt(logging.Filter):
    """Kills the emulator a set host time after the recorder logs the board's header or trigger.

    A logging filter on the package logger: the CLI replaces handlers, not filters.
    """

    def __init__(self, proc, link, signum, after, delay_s):
        super().__init__()
        self.proc, self.link, self.signum = proc, link, signum
        self.after, self.delay_s = after, delay_s
        self.timer = None

    def filter(self, record):
        text = record.getMessage()
        start = text.startswith("board ") if self.after == "header" else text.startswith("trigger")
        if start and self.timer is None:
            self.timer = threading.Timer(self.delay_s, self.kill)
            self.timer.start()
        return True

    def kill(self):
        self.proc.send_signal(self.signum)
        if self.signum == signal.SIGKILL:
            # The board died: its stable name goes, as udev removes /dev/serial/by-id links
            # (and a pty number left behind may be reused by someone else's terminal).
            self.link.unlink(missing_ok=True)


def record_until_killed(tmp_path, signum, after, delay_s, *extra, speed=SPEED):
    program, machine = write_inputs(tmp_path)
    link = tmp_path / "board"
    truth = tmp_path / "truth.json"
    emulate = [SCRIPT, "emulate", "--program", str(program), "--machine", str(machine)]
    emulate += ["--link", str(link), "--speed", str(speed), "--seed", "7", "--truth", str(truth)]
    proc = subprocess.Popen(emulate, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    deadline = time.monotonic() + 30
    while not link.exists() and time.monotonic() < deadline:
        time.sleep(0.02)
    assert link.exists(), "the emulator did not start"
    killer = KillAt(proc, link, signum, after, delay_s)
    logger = logging.getLogger("imu_square")
    logger.addFilter(killer)
    out = tmp_path / "run.mcap"
    argv = ["record", "--port", str(link), "--program", str(program), "-o", str(out)]
    try:
        code = main([*argv, "--until-done", "--trigger", "marker", *extra])
    finally:
        logger.removeFilter(killer)
        if killer.timer is not None:
            killer.timer.join()
        if proc.poll() is None:
            proc.kill()
        proc.wait(20)
    assert proc.returncode == -signum if signum == signal.SIGKILL else proc.returncode == 0
    log = json.loads(truth.read_text())["emulator"]["log"] if truth.exists() else None
    return code, out, log


def tail_gap(rec):
    (gap,) = [e for e in rec.events if e.kind == "gap" and e.time_ns > rec.time_ns[-1]]
    assert gap.time_ns == rec.time_ns[-1] + rec.dt_ns, "at the first missing sample"
    return parse_detail(gap.detail)


def last_sent(log):
    frames = log["frames"]
    runs = zip(frames["seq0"], frames["n"], frames["fate"], strict=True)
    return max(s + n - 1 for s, n, f in runs if f == SENT)


@pytest.mark.slow
@pytest.mark.parametrize(
    ("signum", "board_s"),
    [
        (signal.SIGKILL, 6.5),  # in the middle of the first block
        (signal.SIGKILL, 11.0),  # during the last block
        (signal.SIGTERM, 11.0),
        (signal.SIGTERM, 14.8),  # after the last block, within the 2 s kept after it
    ],
)
def test_a_board_killed_during_the_run_leaves_a_tail_gap_up_to_the_planned_stop(
    tmp_path, capsys, signum, board_s
):
    delay_s = (board_s - TRIGGER_S) / SPEED
    code, out, log = record_until_killed(tmp_path, signum, "trigger", delay_s)
    err = capsys.readouterr().err
    assert code == 3, err
    assert "stopped: port lost" in err
    assert "incomplete recording (the file is valid): the last " in err

    rec = read_run(out)
    dt_s = rec.dt_ns * 1e-9
    (run_start,) = [e for e in rec.events if e.kind == "run_start"]
    trigger = int(rec.seq[0] + (run_start.time_ns - rec.time_ns[0]) // rec.dt_ns)
    ends = [e for e in rec.events if e.kind == "block_end" and e.block == 1]
    if ends:  # --until-done: 2 s after the last block_end marker
        planned = int(rec.seq[0] + (ends[0].time_ns - rec.time_ns[0]) // rec.dt_ns) + 2000
    else:  # or the program's duration plus its margin after the trigger
        planned = trigger + round((PROGRAM.duration_s + until_done_margin_s(PROGRAM)) / dt_s)
    # The kill landed where it was aimed (the file ends there), within 1 s of board time.
    killed_s = (rec.seq[-1] - trigger) * dt_s + TRIGGER_S
    assert abs(killed_s - board_s) < 1.0, killed_s
    assert bool(ends) == (killed_s > LAST_BLOCK_END_S)

    # The missing tail: from the first sample not received up to the planned stop, exactly.
    gap = tail_gap(rec)
    lost = int(gap["lost"])
    assert rec.seq[-1] + 1 + lost == planned
    assert gap["lost_s"] == f"{lost * dt_s:.3f}" and gap["cause"] == "port lost"
    assert rec.lost_samples == 0, "nothing lost before the kill"
    (run_end,) = [e for e in rec.events if e.kind == "run_end"]
    assert parse_detail(run_end.detail)["stop"] == "port lost"
    assert parse_detail(run_end.detail)["lost"] == str(lost)
    outcome = run_outcome(rec)
    assert not outcome.complete and outcome.lost_at_end == lost

    if log is not None:  # SIGTERM: the board wrote its log
        # Every sample in the file is one it sent; the last ones sent may still have been
        # in the pty when its master end closed: less than the reader's 20 ms pace and the
        # pty's 4 kB, 0.05 s of host time here.
        assert set(rec.seq.tolist()) <= set(range(rec.seq[0], last_sent(log) + 1))
        assert 0 <= last_sent(log) - rec.seq[-1] <= 0.05 * SPEED * 1000

    assert main(["info", str(out)]) == 3
    text = capsys.readouterr().out
    # One gap count: the tail the board lost is a gap for info as for record.
    assert f"gaps       1 ({lost} samples lost)" in text
    assert (
        f"run        INCOMPLETE: the last {lost * dt_s:.3f} s ({lost} samples) are missing "
        f"(port lost) (stop: port lost)" in text
    )
    # the line as the user guide quotes it
    assert quoted_form("docs/user-guide/hardware.md", "run  INCOMPLETE:").search(text)
    with warnings.catch_warnings():
        warnings.simplefilter("always", ImuSquareWarning)  # printed by the CLI, on one line
        code = main(["analyze", str(out), "--bootstrap", "0"])
    err = capsys.readouterr().err
    assert "imu-square: warning: " in err and "the run's end is missing" in err
    if ends:  # both blocks whole: analysed, and the missing end is flagged
        assert code == 0
    else:  # a block cut off: refused
        assert code == 2 and "error" in err


@pytest.mark.slow
@pytest.mark.parametrize("signum", [signal.SIGKILL, signal.SIGTERM])
def test_a_board_killed_before_the_trigger_keeps_the_buffer_and_the_silence(
    tmp_path, capsys, signum
):
    # Killed 2 s into the 3 s lead-in, before the first block_start marker: there is no
    # planned stop yet, so the recorder gives up after --silence-timeout. At 2x, 1 s of
    # streaming is enough to measure the board's rate.
    started = time.monotonic()
    code, out, _ = record_until_killed(
        tmp_path, signum, "header", 1.0, "--silence-timeout", "1", speed=2.0
    )
    assert time.monotonic() - started < 15
    err = capsys.readouterr().err
    assert code == 3, err
    assert "no sample from the board on" in err and "the port stayed lost" in err
    rec = read_run(out)
    assert 1.5 < rec.n_samples * rec.dt_ns * 1e-9 < 2.5, "the lead-in up to the kill"
    (run_start,) = [e for e in rec.events if e.kind == "run_start"]
    assert run_start.detail == "trigger=marker,fired=no"
    # 1 s of host time at 2x: 2000 board samples, plus up to two 0.1 s ticks of the loop,
    # give or take 10 % for the rate measured over 1 s of arrivals.
    lost = int(tail_gap(rec)["lost"])
    assert 0.9 * 2000 <= lost <= 1.1 * 2400, lost
    assert main(["info", str(out)]) == 3


def hand_board_header():
    return DeviceHeader(
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


def test_a_board_that_hangs_with_the_port_open_is_given_up_after_the_timeout(tmp_path, capsys):
    program, _ = write_inputs(tmp_path)
    link = tmp_path / "board"
    master = make_pty(link)

    def board():  # 1 s of samples at 1 kHz, then it hangs with the port open
        time.sleep(0.3)
        os.write(master, encode_header(hand_board_header()))
        for s in range(0, 1000, 25):
            os.write(master, encode_block(SampleBlock(s, np.ones((25, 3), np.int32))))
            time.sleep(0.025)

    feeder = threading.Thread(target=board)
    feeder.start()
    started = time.monotonic()
    try:
        argv = ["record", "--port", str(link), "--program", str(program), "--duration", "60"]
        code = main([*argv, "-o", str(tmp_path / "run.mcap"), "--silence-timeout", "0.5"])
    finally:
        feeder.join()
        os.close(master)
    assert code == 3
    assert time.monotonic() - started < 3
    err = capsys.readouterr().err
    assert "(the port is open but silent)" in err and "stopped: board silent" in err
    rec = read_run(tmp_path / "run.mcap")
    assert rec.seq.tolist() == list(range(1000))
    # 0.5 s of silence at the measured ~1 kHz, plus up to two 0.1 s ticks of the loop; the
    # board's own pacing (sleep) makes it a little slower than 1 kHz.
    gap = tail_gap(rec)
    assert gap["cause"] == "board silent"
    assert 400 <= int(gap["lost"]) <= 750, gap
    capsys.readouterr()
    assert main(["info", str(tmp_path / "run.mcap"), "--json"]) == 3
    summary = json.loads(capsys.readouterr().out)
    run = summary["run"]
    lost = int(gap["lost"])
    assert summary["gaps"] == {"count": 1, "lost": lost}
    assert run == {
        "stop": "board silent",
        "complete": False,
        "problems": [f"the last {lost * 1e-3:.3f} s ({lost} samples) are missing (board silent)"],
        "lost_at_end": lost,
        "lost_at_end_s": float(f"{lost * 1e-3:.3f}"),
    }


def write_while_read(master, data, timeout_s=2.0):
    """Write to a pty's master end as the reader takes it; stop when it no longer reads.

    A blocking write would wait for ever once the recorder has stopped and the pty's
    buffer is full.
    """
    os.set_blocking(master, False)
    view = memoryview(data)
    deadline = time.monotonic() + timeout_s
    while view and time.monotonic() < deadline:
        try:
            view = view[os.write(master, view) :]
        except BlockingIOError:
            time.sleep(0.01)


def test_another_board_on_the_same_port_name_ends_the_recording(tmp_path, capsys):
    program, _ = write_inputs(tmp_path)
    link = tmp_path / "board"
    master = make_pty(link)
    ours = hand_board_header()
    other = DeviceHeader(**{**ours.__dict__, "serial": "2"})

    def blocks(first, stop, count):
        return [
            encode_block(SampleBlock(s, np.full((25, 3), count, np.int32)))
            for s in range(first, stop, 25)
        ]

    def boards():
        time.sleep(0.3)
        write_while_read(master, b"".join([encode_header(ours), *blocks(0, 1000, 1)]))
        time.sleep(0.3)
        # Another board answers on the same name (a reused pty, a swapped cable): its
        # samples must never enter the file.
        write_while_read(master, b"".join([encode_header(other), *blocks(1000, 3000, 7)]))

    feeder = threading.Thread(target=boards)
    feeder.start()
    try:
        argv = ["record", "--port", str(link), "--program", str(program), "--duration", "60"]
        code = main([*argv, "-o", str(tmp_path / "run.mcap")])
    finally:
        feeder.join()
        os.close(master)
    assert code == 3
    err = capsys.readouterr().err
    assert "is not the one the recording started with" in err and "stopped: board changed" in err
    rec = read_run(tmp_path / "run.mcap")
    assert rec.seq.tolist() == list(range(1000))
    np.testing.assert_array_equal(rec.accel, np.float32(1e-4))
    assert tail_gap(rec)["cause"] == "board changed"
