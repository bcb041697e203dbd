"""Throughput and memory of MCAP recording I/O, against mcap_ros2's decoder.

For 200k and 2M samples at 1 kHz and 4 kHz: median of 5 runs of
``write_mcap`` and ``read_mcap`` (samples/s), the peak memory of one
``read_mcap`` under tracemalloc as a multiple of the sample array
(n * 3 * 4 bytes), and the time of decoding the same file's ``/imu/accel``
messages with mcap's reader and mcap_ros2's ``DecoderFactory`` into the same
arrays (the library reference), measured in the same run.

Run: ``.venv/bin/python benchmarks/recording_io.py`` (about 2 minutes).
Writes ``benchmarks/results/recording_io.json``.
"""

import json
import statistics
import tempfile
import time
import tracemalloc
from pathlib import Path

import numpy as np
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory

from imu_square.io.mcap import ACCEL_TOPIC, read_mcap, write_mcap
from imu_square.io.recording import Recording, SensorInfo

RESULTS = Path(__file__).parent / "results" / "recording_io.json"
REPEATS = 5


def make(n, dt_ns):
    rng = np.random.default_rng(0)
    accel = rng.normal(0.0, 0.05, (n, 3)).astype(np.float32)
    accel[:, 2] += np.float32(9.80665)
    seq = np.arange(n)
    seq[n // 2 :] += 3  # one gap
    return Recording(
        accel=accel,
        time_ns=1_700_000_000_000_000_000 + seq * dt_ns,
        seq=seq,
        dt_ns=dt_ns,
        sensor=SensorInfo("ADXL355"),
    )


def decode_with_mcap_ros2(path):
    """The library way: decode every AccelBatch to Python objects, then to arrays."""
    xs, ys, zs = [], [], []
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        for *_, msg in reader.iter_decoded_messages(topics=[ACCEL_TOPIC], log_time_order=False):
            xs.append(np.asarray(msg.x, np.float32))
            ys.append(np.asarray(msg.y, np.float32))
            zs.append(np.asarray(msg.z, np.float32))
    return np.column_stack([np.concatenate(xs), np.concatenate(ys), np.concatenate(zs)])


def median_time(fn, repeats=REPEATS):
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return statistics.median(times)


def bench(n, dt_ns, tmp):
    rec = make(n, dt_ns)
    path = Path(tmp) / f"bench_{n}_{dt_ns}.mcap"
    t_write = median_time(lambda: write_mcap(rec, path))
    t_read = median_time(lambda: read_mcap(path))
    back = read_mcap(path)
    assert np.array_equal(back.accel, rec.accel) and np.array_equal(back.time_ns, rec.time_ns)
    t_ref = median_time(lambda: decode_with_mcap_ros2(path))
    assert np.array_equal(decode_with_mcap_ros2(path), rec.accel)
    tracemalloc.start()
    read_mcap(path)
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    return {
        "samples": n,
        "rate_hz": 1e9 / dt_ns,
        "file_bytes_per_sample": path.stat().st_size / n,
        "write_samples_per_s": n / t_write,
        "read_samples_per_s": n / t_read,
        "mcap_ros2_samples_per_s": n / t_ref,
        "read_speedup_vs_mcap_ros2": t_ref / t_read,
        "read_peak_memory_x_sample_array": peak / (n * 3 * 4),
    }


def main():
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for dt_ns in (1_000_000, 250_000):
            for n in (200_000, 2_000_000):
                rows.append(bench(n, dt_ns, tmp))
                print(f"done {n} samples at {1e9 / dt_ns:g} Hz", flush=True)
    header = (
        f"{'samples':>9} {'rate':>6} {'B/sample':>8} {'write M/s':>9} {'read M/s':>8} "
        f"{'ros2 M/s':>8} {'speedup':>7} {'peak x':>6}"
    )
    print(header)
    for r in rows:
        print(
            f"{r['samples']:>9} {r['rate_hz']:>6.0f} {r['file_bytes_per_sample']:>8.2f} "
            f"{r['write_samples_per_s'] / 1e6:>9.2f} {r['read_samples_per_s'] / 1e6:>8.2f} "
            f"{r['mcap_ros2_samples_per_s'] / 1e6:>8.3f} {r['read_speedup_vs_mcap_ros2']:>7.0f} "
            f"{r['read_peak_memory_x_sample_array']:>6.2f}"
        )
    RESULTS.parent.mkdir(parents=True, exist_ok=True)
    RESULTS.write_text(
        json.dumps(
            {
                "targets": {"read_samples_per_s": 5e6, "read_peak_memory_x_sample_array": 3.0},
                "repeats": REPEATS,
                "statistic": "median",
                "rows": rows,
            },
            indent=2,
        )
    )
    print(f"wrote {RESULTS}")


if __name__ == "__main__":
    main()
