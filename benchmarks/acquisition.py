"""Acquisition throughput: how many samples per second each stage sustains on this machine.

Each section is a function returning ``{name: samples_per_s}`` (medians of 5 repeats).
Run ``python benchmarks/acquisition.py [section ...]`` (or ``python -m
benchmarks.acquisition``); results are merged into
``benchmarks/results/acquisition.json`` so sections can be run separately.

Sections: ``parser`` and ``encoder`` (the wire protocol). A board streams at most
4000 samples/s, so a ceiling is reported with its headroom over that rate.

Recorder sections: ``writer`` (the MCAP writer's ceiling, fed the way the recorder
feeds it) and ``stream``: an emulated 4 kHz board streams in real time through a
pseudo-terminal for ``--minutes`` (default 5) into ``imu-square record`` running as
a child process; reported are the samples lost (must be 0) and the recorder's CPU
time as a percentage of one core (``os.wait4`` rusage of the child over its wall
time; goal <= 10 %).
"""

import argparse
import json
import math
import os
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

# Run as a script, this file would shadow the package it measures: drop its folder.
sys.path[:] = [p for p in sys.path if Path(p or ".").resolve() != Path(__file__).resolve().parent]

from acquisition.protocol import (  # noqa: E402
    DeviceHeader,
    Parser,
    SampleBlock,
    encode_block,
    encode_header,
)
from imu_square.units import G  # noqa: E402

RESULTS = Path(__file__).resolve().parent / "results" / "acquisition.json"
REPEATS = 5
N_SAMPLES = 100_000
SAMPLES_PER_FRAME = 25
READ_SIZE = 4096  # bytes per serial read
MAX_DEVICE_RATE_HZ = 4000.0


def _header(mode):
    return DeviceHeader(
        model="ADXL355",
        serial="bench",
        firmware="1.0",
        sample_rate_hz=4000.0,
        dt_ns=250_000,
        scale_m_s2_per_count=G / 256000,
        range_m_s2=2.048 * G,
        noise_density_m_s2_rthz=22.5e-6 * G,
        has_temperature=True,
        mode=mode,
    )


def _blocks():
    rng = np.random.default_rng(0)
    counts = rng.integers(-(2**19), 2**19, size=(N_SAMPLES, 3), dtype=np.int32)
    return [
        SampleBlock(i, counts[i : i + SAMPLES_PER_FRAME], 24.5, 0)
        for i in range(0, N_SAMPLES, SAMPLES_PER_FRAME)
    ]


def _median_rate(run, n_samples):
    times = []
    for _ in range(REPEATS):
        t0 = time.perf_counter()
        run()
        times.append(time.perf_counter() - t0)
    return n_samples / statistics.median(times)


def bench_encoder():
    """Encoder ceiling in samples/s, binary frames and checksummed lines."""
    blocks = _blocks()
    return {
        f"encoder_{mode}_samples_per_s": _median_rate(
            lambda mode=mode: [encode_block(b, mode) for b in blocks], N_SAMPLES
        )
        for mode in ("binary", "line")
    }


def bench_parser():
    """Parser ceiling in samples/s, fed in serial-read-sized chunks; 1% damage variant."""
    blocks = _blocks()
    out = {}
    for mode in ("binary", "line"):
        frames = [encode_header(_header(mode))] + [encode_block(b, mode) for b in blocks]
        clean = b"".join(frames)
        damaged = bytearray(clean)
        rng = np.random.default_rng(1)
        for p in rng.integers(0, len(damaged), len(frames) // 100):
            damaged[p] ^= 0x5A
        for label, data in (("clean", clean), ("damaged1pct", bytes(damaged))):

            def run(data=data, mode=mode):
                parser = Parser()
                for i in range(0, len(data), READ_SIZE):
                    parser.feed(data[i : i + READ_SIZE])
                assert parser.mode == mode
                return parser

            samples = run().stats.samples_ok
            out[f"parser_{mode}_{label}_samples_per_s"] = _median_rate(run, samples)
    return out


WRITER_SAMPLES = 400_000
RECORDER_BLOCK = 25  # samples per write_samples call, as a binary frame delivers them


def bench_writer(args):
    """MCAP writer ceiling in samples/s: 25-sample calls with a flush per second of data."""
    from imu_square.io.mcap import RecordingWriter

    rng = np.random.default_rng(2)
    accel = rng.normal(0.0, 0.1, (WRITER_SAMPLES, 3)).astype(np.float32)
    seq = np.arange(WRITER_SAMPLES, dtype=np.int64)
    time_ns = seq * 250_000
    per_second = int(MAX_DEVICE_RATE_HZ)
    out = {}
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "bench.mcap"

        def blocks(fsync):
            with RecordingWriter(path, dt_ns=250_000, chunk_size=64 * 1024, fsync=fsync) as w:
                for i in range(0, WRITER_SAMPLES, RECORDER_BLOCK):
                    sl = slice(i, i + RECORDER_BLOCK)
                    w.write_samples(seq[sl], time_ns[sl], accel[sl])
                    if (i + RECORDER_BLOCK) % per_second == 0:
                        w.flush()

        def whole():
            with RecordingWriter(path, dt_ns=250_000) as w:
                w.write_samples(seq, time_ns, accel)

        out["writer_blocks25_flush1s_samples_per_s"] = _median_rate(
            lambda: blocks(False), WRITER_SAMPLES
        )
        out["writer_blocks25_flush1s_fsync_samples_per_s"] = _median_rate(
            lambda: blocks(True), WRITER_SAMPLES
        )
        out["writer_one_call_samples_per_s"] = _median_rate(whole, WRITER_SAMPLES)
    return out


def _board_recording(seconds):
    """A simulated 4 kHz circle test (paper's sensor noise) lasting about ``seconds``."""
    from dataclasses import replace

    from imu_square.program import program_from_mapping
    from imu_square.simulate import data_path, read_sensor, simulate_run

    sensor = replace(read_sensor(data_path("sensor_paper.toml")), sample_rate_hz=4000.0)
    # r = 100 mm at 6000 mm/min: 6.28 s per cycle, 2 s dwell, blocks of 15 cycles each way.
    per_run = 2 * (17 * 2 * math.pi) + 2 * 2.0
    runs = max(1, math.ceil((seconds - 6.0) / per_run))
    program = program_from_mapping(
        {"radius_mm": 100.0, "feed_mm_per_min": 6000.0, "cycles_per_direction": 15, "runs": runs}
    )
    recording, _ = simulate_run(program, None, sensor, seed=5)
    return program, recording


def bench_stream(args):
    """4 kHz through a pty into `imu-square record` (child process) for --minutes."""
    from acquisition.emulator import EmulatedBoard
    from imu_square.io.mcap import read_mcap

    seconds = 60.0 * args.minutes
    program, recording = _board_recording(seconds + 10.0)
    exe = Path(sys.executable).with_name("imu-square")
    with tempfile.TemporaryDirectory() as folder:
        folder = Path(folder)
        (folder / "program.toml").write_text(program.to_toml())
        board = EmulatedBoard(recording, folder / "board", speed=1.0, seed=5)
        thread = threading.Thread(target=board.run, daemon=True)
        thread.start()
        board.ready.wait(10)
        cmd = [str(exe), "-q", "record", "--port", str(folder / "board")]
        cmd += ["--program", str(folder / "program.toml"), "-o", str(folder / "run.mcap")]
        cmd += ["--duration", repr(seconds)]
        t0 = time.monotonic()
        proc = subprocess.Popen(cmd)
        _, status, usage = os.wait4(proc.pid, 0)
        wall = time.monotonic() - t0
        proc.returncode = os.waitstatus_to_exitcode(status)
        board.stop()
        thread.join(30)
        rec = read_mcap(folder / "run.mcap")
    # Start-up (imports, argument parsing) measured alone, to separate it from the stream.
    help_proc = subprocess.Popen([str(exe), "record", "--help"], stdout=subprocess.DEVNULL)
    _, _, start_usage = os.wait4(help_proc.pid, 0)
    startup_cpu_s = start_usage.ru_utime + start_usage.ru_stime
    cpu_s = usage.ru_utime + usage.ru_stime
    expected = round(seconds * MAX_DEVICE_RATE_HZ)
    bad = [e for e in rec.events if e.kind in ("gap", "crc_error", "reconnect")]
    return {
        "stream_minutes": args.minutes,
        "stream_exit_code": proc.returncode,
        "stream_samples_expected": expected,
        "stream_samples_in_file": rec.n_samples,
        "stream_samples_lost": expected - rec.n_samples + rec.lost_samples,
        "stream_fault_events": len(bad),
        "stream_recorder_cpu_percent_of_one_core": 100.0 * cpu_s / wall,
        "stream_recorder_startup_cpu_s": startup_cpu_s,
        "stream_recorder_cpu_percent_after_startup": 100.0 * (cpu_s - startup_cpu_s) / wall,
    }


SECTIONS = {
    "parser": bench_parser,
    "encoder": bench_encoder,
    "writer": bench_writer,
    "stream": bench_stream,
}


def _row(key, value):
    if key.endswith("_samples_per_s"):
        return f"{key:<44} {value:12.0f} {value / MAX_DEVICE_RATE_HZ:8.0f}"
    return f"{key:<44} {value:12.4g} {'':>8}"


def main(argv=None):
    """Run the named sections (all by default), print a table, merge into the JSON file."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("sections", nargs="*", metavar="SECTION", help=f"any of {list(SECTIONS)}")
    parser.add_argument(
        "--minutes", type=float, default=5.0, help="length of the stream section (default 5)"
    )
    args = parser.parse_args(argv)
    unknown = sorted(set(args.sections) - set(SECTIONS))
    if unknown:
        parser.error(f"unknown section {unknown[0]!r}; choose from {list(SECTIONS)}")
    names = args.sections or list(SECTIONS)
    results = json.loads(RESULTS.read_text()) if RESULTS.exists() else {}
    print(f"{'quantity':<44} {'value':>12} {'x 4 kHz':>8}")
    for name in names:
        section = SECTIONS[name]
        values = section(args) if name in ("writer", "stream") else section()
        for key, value in values.items():
            results[key] = value
            print(_row(key, value))
    RESULTS.parent.mkdir(parents=True, exist_ok=True)
    RESULTS.write_text(json.dumps(results, indent=2, sort_keys=True) + "\n")


if __name__ == "__main__":
    main()
