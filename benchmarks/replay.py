"""Replay speed: files per second with local processes and a Dask LocalCluster.

Makes N recordings of the paper's test (200 s at 1 kHz, the paper's sensor,
a typical machine; generated once into a temporary folder, never committed),
then replays them into fresh SQLite histories:

- ``--jobs 1`` (a subset when ``--jobs1-files`` is smaller: the rate is what counts),
- ``--jobs 2`` (one process per core on this machine),
- a 2-worker ``distributed.LocalCluster``,

and reports the files per second, the speed-up of two processes over one, the
Dask overhead against the local pool, and the per-file cost from each worker's
own timing (median). A fleet estimate follows from the per-file cost.

Usage::

    python benchmarks/replay.py [--files 1000] [--jobs1-files 200] [--keep DIR]
"""

import argparse
import json
import shutil
import statistics
import sys
import tempfile
import time
from pathlib import Path

from imu_square.io.mcap import write_mcap
from imu_square.monitor.config import AnalysisSettings
from imu_square.monitor.history.store import open_history
from imu_square.monitor.replay import ReplayJob, run_dask, run_local, store_outcome
from imu_square.program import read_program
from imu_square.simulate import data_path, read_machine, read_sensor, simulate_run

RESULTS = Path(__file__).parent / "results" / "replay.json"


def make_recordings(folder, n):
    """``n`` recordings of the paper's test, one a night. [files]"""
    program = read_program(data_path("program_paper.toml"))
    machine = read_machine(data_path("machine_typical.toml"))
    sensor = read_sensor(data_path("sensor_paper.toml"))
    paths = []
    t0 = 1_790_000_000 * 10**9
    for i in range(n):
        rec, _ = simulate_run(program, machine, sensor, seed=i, t0_ns=t0 + i * 86_400 * 10**9)
        path = folder / f"run-{i:04d}.mcap"
        write_mcap(rec, path)
        paths.append(str(path))
    return paths


def replay(paths, history, engine, jobs):
    """Replay into a fresh history; wall time and the workers' own per-file seconds."""
    job = ReplayJob("bench", AnalysisSettings())
    for stale in history.parent.glob(history.name + "*"):  # a kept folder's last run (and -wal)
        stale.unlink()
    start = time.perf_counter()
    per_file = []
    with open_history(history) as h:
        outcomes = (
            run_dask(paths, job, workers=jobs)
            if engine == "dask"
            else run_local(paths, job, jobs=jobs)
        )
        for outcome in outcomes:
            if outcome.row is not None:
                store_outcome(h, outcome)
            per_file.append(outcome.seconds)
    return time.perf_counter() - start, per_file


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--files", type=int, default=1000)
    parser.add_argument("--jobs1-files", type=int, default=200)
    parser.add_argument("--keep", help="keep (or reuse) the recordings in this folder")
    args = parser.parse_args(argv)
    folder = Path(args.keep) if args.keep else Path(tempfile.mkdtemp(prefix="imu-replay-"))
    folder.mkdir(parents=True, exist_ok=True)
    try:
        existing = sorted(str(p) for p in folder.glob("run-*.mcap"))
        t0 = time.perf_counter()
        paths = existing if len(existing) >= args.files else make_recordings(folder, args.files)
        paths = paths[: args.files]
        made = time.perf_counter() - t0
        size = sum(Path(p).stat().st_size for p in paths)
        print(
            f"{len(paths)} recordings, {size / 1e6:.0f} MB, made in {made:.0f} s", file=sys.stderr
        )
        rows = {}
        for name, engine, jobs, subset in (
            ("local --jobs 1", "local", 1, paths[: args.jobs1_files]),
            ("local --jobs 2", "local", 2, paths),
            ("dask LocalCluster, 2 workers", "dask", 2, paths),
        ):
            wall, per_file = replay(subset, folder / f"{engine}-{jobs}.db", engine, jobs)
            rows[name] = {
                "files": len(subset),
                "wall_s": wall,
                "files_per_s": len(subset) / wall,
                "per_file_median_s": statistics.median(per_file),
            }
            print(
                f"  {name:30s} {len(subset):5d} files {wall:7.1f} s {len(subset) / wall:6.2f} "
                f"files/s, per file {statistics.median(per_file):.3f} s (median)",
                file=sys.stderr,
            )
        one, two, dask = (rows[k]["files_per_s"] for k in rows)
        result = {
            "files": len(paths),
            "mb": size / 1e6,
            "engines": rows,
            "speedup_2_over_1": two / one,
            "dask_overhead": two / dask - 1.0,
            "time_for_1000_files_jobs2_s": 1000 / two,
        }
        per_file = rows["local --jobs 2"]["per_file_median_s"]
        # 500 machines x 3 years of nights, re-analysed overnight (8 h) on workers like these
        fleet = 500 * 3 * 365
        result["fleet_files"] = fleet
        result["fleet_core_hours"] = fleet * per_file / 3600
        result["fleet_workers_for_8_h"] = fleet * per_file / (8 * 3600)
        print(
            f"speed-up of 2 processes over 1: {result['speedup_2_over_1']:.2f}; Dask overhead "
            f"against the local pool: {100 * result['dask_overhead']:+.0f} %; 1000 files with "
            f"--jobs 2: {result['time_for_1000_files_jobs2_s']:.0f} s\nfleet: {fleet} files x "
            f"{per_file:.3f} s = {result['fleet_core_hours']:.0f} core-hours; an 8-hour night "
            f"needs {result['fleet_workers_for_8_h']:.1f} worker cores like these",
            file=sys.stderr,
        )
        RESULTS.parent.mkdir(parents=True, exist_ok=True)
        RESULTS.write_text(json.dumps(result, indent=1))
        print(f"wrote {RESULTS}", file=sys.stderr)
    finally:
        if not args.keep:
            shutil.rmtree(folder, ignore_errors=True)


if __name__ == "__main__":
    main()
