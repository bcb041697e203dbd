"""Output errors of ``record`` and ``recover``: one line, a documented exit code, no lost run.

The output is checked before the port is opened, and the disk's room before the
trigger. A disk that fills up mid-run is made two honest ways: a file-size
limit (``RLIMIT_FSIZE``) on the recorder's process, which always works, and a
small tmpfs mounted in a private mount namespace (``unshare``), filled by
another process while the recorder runs.
"""

import os
import resource
import shutil
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
from acq_board import assert_exact, running_board, write_inputs

from imu_square.cli import main
from imu_square.io.mcap import RecordingWriter, read_mcap, scan_mcap

SCRIPT = os.path.join(os.path.dirname(sys.executable), "imu-square")


def record_argv(tmp_path, out, *extra, port=None):
    program, _ = write_inputs(tmp_path)
    port = port or str(tmp_path / "board")
    return ["record", "--port", port, "--program", str(program), "-o", str(out), *extra]


def one_line(err):
    assert "Traceback" not in err
    assert err.count("\n") == 1, err
    return err


def error_line(err, command="record"):
    """The one error line among progress lines; no traceback."""
    assert "Traceback" not in err
    (line,) = [e for e in err.splitlines() if e.startswith(f"imu-square {command}: error:")]
    return line


@pytest.mark.parametrize(
    ("output", "message"),
    [
        ("missing/dir/x.mcap", "x.mcap: the folder '{tmp}/missing/dir' does not exist"),
        (".", "{tmp}: is a directory; give a file name inside it"),
        ("taken.mcap", "taken.mcap: already exists; refusing to replace it (--overwrite does)"),
    ],
)
def test_a_bad_output_is_refused_before_the_port_is_opened(tmp_path, capsys, output, message):
    (tmp_path / "taken.mcap").write_bytes(b"a night's run")
    out = tmp_path / output if output != "." else tmp_path
    # No board at all: the output is the first thing checked, so that is what is said.
    argv = record_argv(tmp_path, out, "--trigger", "marker", port=str(tmp_path / "no-board"))
    assert main(argv) == 2
    err = one_line(capsys.readouterr().err)
    assert message.format(tmp=tmp_path) in err
    assert (tmp_path / "taken.mcap").read_bytes() == b"a night's run"


def test_overwrite_replaces_an_existing_recording(tmp_path, capsys):
    out = tmp_path / "run.mcap"
    out.write_bytes(b"old")
    with running_board(tmp_path) as (board, _):
        code = main(record_argv(tmp_path, out, "--duration", "2", "--overwrite"))
    assert code == 0, capsys.readouterr().err
    rec = read_mcap(out)
    assert_exact(rec, board)
    assert rec.n_samples == 2000


@pytest.mark.parametrize(
    ("option", "value", "message"),
    [
        ("--baud", "0", "baud rate (--baud) must be a whole number > 0, got 0"),
        ("--baud", "-9600", "baud rate (--baud) must be a whole number > 0, got -9600"),
        ("--header-timeout", "-1", "header timeout (--header-timeout) must be a number of "),
        ("--header-timeout", "0", "seconds > 0, got 0.0"),
        ("--silence-timeout", "inf", "silence timeout (--silence-timeout) must be a number of"),
        ("--pretrigger", "-1", "pre-trigger time (--pretrigger) must be a number of seconds >= 0"),
        ("--duration", "nan", "duration (--duration) must be a number of seconds > 0, got nan"),
    ],
)
def test_numeric_options_are_checked(tmp_path, capsys, option, value, message):
    argv = record_argv(tmp_path, tmp_path / "x.mcap", option, value)
    assert main(argv) == 2
    assert message in one_line(capsys.readouterr().err)


def test_recover_refuses_a_bad_output_in_one_line(tmp_path, capsys):
    src = tmp_path / "run.mcap"
    with running_board(tmp_path) as _:
        assert main(record_argv(tmp_path, src, "--duration", "1")) == 0
    capsys.readouterr()
    bad = tmp_path / "nonexistent" / "x.mcap"
    assert main(["recover", str(src), "-o", str(bad)]) == 2
    assert f"the folder '{tmp_path / 'nonexistent'}' does not exist" in one_line(
        capsys.readouterr().err
    )
    assert main(["recover", str(src), "-o", str(src)]) == 2
    assert "is the damaged file itself" in one_line(capsys.readouterr().err)
    assert main(["recover", str(src), "-o", str(tmp_path)]) == 2
    assert "is a directory" in one_line(capsys.readouterr().err)


def test_sigterm_while_waiting_for_the_trigger_keeps_the_buffer(tmp_path):
    out = tmp_path / "run.mcap"
    argv = [SCRIPT, *record_argv(tmp_path, out, "--trigger", "marker", "--until-done")]
    # Real time: the first block_start marker comes 3 s after the board starts.
    with running_board(tmp_path, speed=1.0):
        proc = subprocess.Popen(argv, stderr=subprocess.PIPE, text=True)
        lines = []
        for line in proc.stderr:  # wait for the board's header, then stop the recorder
            lines.append(line)
            if line.startswith("board "):
                break
        time.sleep(1.0)  # a second of the lead-in arrives
        proc.send_signal(signal.SIGTERM)
        err = "".join(lines) + proc.stderr.read()
        proc.wait(10)
    assert proc.returncode == 3, err
    assert "Traceback" not in err
    assert "stopped: interrupted" in err
    rec = read_mcap(out)
    assert 500 < rec.n_samples < 3000
    (run_start,) = [e for e in rec.events if e.kind == "run_start"]
    assert run_start.detail == "trigger=marker,fired=no"
    assert rec.events[-1].detail.startswith("stop=interrupted,")


def limit_file_size(n_bytes):
    def apply():
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # a write past it fails with EFBIG
        resource.setrlimit(resource.RLIMIT_FSIZE, (n_bytes, n_bytes))

    return apply


@pytest.mark.slow
def test_a_full_disk_mid_run_keeps_the_flushed_chunks_and_says_how_much(tmp_path, capsys):
    out = tmp_path / "run.mcap"
    argv = [SCRIPT, *record_argv(tmp_path, out, "--duration", "60")]
    limit = 100_000  # about 6 s of samples at 16 B each
    with running_board(tmp_path, speed=2.0) as (board, _):
        proc = subprocess.run(
            argv, stderr=subprocess.PIPE, text=True, timeout=60, preexec_fn=limit_file_size(limit)
        )
    assert proc.returncode == 4, proc.stderr
    line = error_line(proc.stderr)
    assert f"{out}: writing failed: File too large; the file keeps " in line
    kept = scan_mcap(out).report
    assert f"the file keeps {kept.samples} samples ({kept.duration_s:.3f} s)" in line
    assert f"'imu-square recover {out} -o FIXED.mcap'" in line
    assert os.path.getsize(out) <= limit
    assert kept.samples > 2000, "every flushed second is kept"
    fixed = tmp_path / "fixed.mcap"
    assert main(["recover", str(out), "-o", str(fixed)]) == 0
    rec = read_mcap(fixed)
    assert_exact(rec, board)
    assert rec.n_samples == kept.samples and rec.lost_samples == 0


def test_recover_onto_a_full_disk_removes_its_partial_output(tmp_path):
    n = 30_000  # about 0.5 MB; the limit lets half of its rewrite through
    t = np.arange(n) * 1_000_000
    accel = np.random.default_rng(0).normal(0.0, 0.01, (n, 3))
    src = tmp_path / "run.mcap"
    with RecordingWriter(src, dt_ns=1_000_000) as writer:
        writer.write_samples(np.arange(n), t, accel)
    out = tmp_path / "fixed.mcap"
    proc = subprocess.run(
        [SCRIPT, "recover", str(src), "-o", str(out)],
        stderr=subprocess.PIPE,
        text=True,
        timeout=60,
        preexec_fn=limit_file_size(os.path.getsize(src) // 2),
    )
    assert proc.returncode == 4, proc.stderr
    line = one_line(proc.stderr)
    assert f"{out}: writing failed: File too large; the partial file was removed" in line
    assert not out.exists()


def mount_namespace():
    """The command prefix that runs a shell in a private mount namespace, or None."""
    if shutil.which("unshare") is None:
        return None
    prefix = ["unshare", "--mount"] if os.geteuid() == 0 else ["unshare", "-r", "--mount"]
    probe = subprocess.run(
        [*prefix, "sh", "-c", "mount -t tmpfs -o size=64k tmpfs /mnt"], capture_output=True
    )
    return prefix if probe.returncode == 0 else None


NAMESPACE = mount_namespace()
needs_tmpfs = pytest.mark.skipif(
    NAMESPACE is None,
    reason="cannot mount a tmpfs in a private mount namespace here (no unshare, or no "
    "CAP_SYS_ADMIN and no unprivileged user namespaces)",
)


def in_small_disk(tmp_path, size, command, fill_after_bytes=None):
    """Run ``command`` with ``tmp_path/disk`` a tmpfs of ``size``; copy out run.mcap."""
    disk = tmp_path / "disk"
    disk.mkdir()
    fill = ""
    if fill_after_bytes is not None:  # another process takes the rest of the disk mid-run
        fill = (
            f"while [ $(stat -c %s {disk}/run.mcap 2>/dev/null || echo 0) -lt "
            f"{fill_after_bytes} ]; do sleep 0.05; done; "
            f"dd if=/dev/zero of={disk}/filler bs=4k 2>/dev/null; "
        )
    script = (
        f'mount -t tmpfs -o size={size} tmpfs {disk} || exit 99; "$@" & pid=$!; {fill}'
        f"wait $pid; code=$?; cp {disk}/run.mcap {tmp_path}/cut.mcap 2>/dev/null; exit $code"
    )
    return subprocess.run(
        [*NAMESPACE, "sh", "-c", script, "sh", *command],
        stderr=subprocess.PIPE,
        text=True,
        timeout=60,
    )


@needs_tmpfs
@pytest.mark.slow
def test_a_disk_that_fills_up_mid_run(tmp_path):
    argv = [SCRIPT, *record_argv(tmp_path, tmp_path / "disk" / "run.mcap", "--duration", "60")]
    with running_board(tmp_path, speed=2.0) as (board, _):
        # The disk fills once the recorder has flushed about 2 s of samples (16 B each).
        proc = in_small_disk(tmp_path, "3m", argv, fill_after_bytes=32_000)
    assert proc.returncode == 4, proc.stderr
    line = error_line(proc.stderr)
    assert "writing failed: No space left on device; the file keeps " in line
    kept = scan_mcap(tmp_path / "cut.mcap").report
    assert f"the file keeps {kept.samples} samples ({kept.duration_s:.3f} s)" in line
    assert kept.samples >= 2000, "at least the flushed second before the disk filled"
    fixed = tmp_path / "fixed.mcap"
    assert main(["recover", str(tmp_path / "cut.mcap"), "-o", str(fixed)]) == 0
    rec = read_mcap(fixed)
    assert_exact(rec, board)
    np.testing.assert_array_equal(rec.seq, np.arange(rec.seq[0], rec.seq[0] + kept.samples))


@needs_tmpfs
def test_a_disk_too_small_for_the_run_is_refused_before_the_trigger(tmp_path):
    argv = [SCRIPT, *record_argv(tmp_path, tmp_path / "disk" / "run.mcap", "--duration", "60")]
    argv += ["--trigger", "marker"]
    with running_board(tmp_path, speed=1.0):
        proc = in_small_disk(tmp_path, "512k", argv)
    assert proc.returncode == 2, proc.stderr
    err = error_line(proc.stderr)
    assert "run.mcap: the disk has 0.5 MB free, and the recording (63 s at 1000 Hz) needs " in err
    assert "up to 2.6 MB: free some space or write elsewhere" in err
    assert not (tmp_path / "cut.mcap").exists(), "nothing written"
