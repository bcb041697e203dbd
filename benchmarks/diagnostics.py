"""Cost of the monitor's nightly diagnostics on a nightly recording, before and after.

The recording: the paper's test (r = 100 mm at 6000 mm/min, 15 cycles each way,
about 200 s) at 1 kHz with the paper's sensor (7 ug/sqrt(Hz)), simulated on
three machines: no effect; a servo mismatch with friction spikes at the
reversals; and the typical machine (``machine_typical.toml``: all six effects
the monitor trends, at once).

- **before**: the discrepancy workflow (:func:`~imu_square.discrepancy.find_discrepancy`,
  ``imu-square discrepancy``), the only way to get the effects' sizes until
  now: it searches the vocabulary for the effects the recording needs (last
  measured at 5.8 s with no effect, 27 s with servo plus spikes);
- **after**: what the monitor runs after every valid night
  (:func:`~imu_square.monitor.diagnostics.fit.diagnose_recording` with the
  default ``[diagnostics]``): the base model and the fixed set of effects
  fitted at once, every size with its uncertainty, named or not
  (:func:`~imu_square.discrepancy.diagnose.fit_effects`).

Times are on one core: the process is pinned to one CPU and the BLAS to one
thread (``--cores`` changes that), median of ``--repeat`` recordings; both
the wall time and the process's CPU time are kept (on a shared machine the
CPU time is the figure: the wall time counts other processes' turns). From the
"after" figure of the typical machine (the slowest), the cost of rebuilding a
fleet's archive with ``imu-square replay --cluster``: 500 machines x 3 years
of nights, in core-hours and in hours on a Dask cluster of a given size (the
per-file function is independent, so the work divides by the workers; Dask's
overhead is milliseconds a task, negligible against seconds).

Usage::

    python benchmarks/diagnostics.py [--repeat 3] [--no-before] [--cores 1]
"""

import argparse
import os
import sys

if __name__ == "__main__" and "--cores" not in sys.argv:
    # one core: before numpy loads its BLAS
    for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ[var] = "1"

import json
import statistics
import time
from pathlib import Path

from imu_square import __version__
from imu_square.discrepancy import find_discrepancy
from imu_square.monitor.config import AnalysisSettings
from imu_square.monitor.diagnostics.fit import diagnose_recording
from imu_square.monitor.diagnostics.settings import DiagnosticSettings
from imu_square.program import TestProgram
from imu_square.simulate import data_path, read_sensor, simulate_run, with_effects
from imu_square.simulate.machine import MachineModel, read_machine

RESULTS = Path(__file__).parent / "results" / "diagnostics.json"
PROGRAM = TestProgram()  # the paper's test
FLEET_MACHINES = 500
FLEET_YEARS = 3
CLUSTER_CORES = (64, 256)


def machines(sensor):
    """The three machines: label to (MachineModel, SensorModel)."""
    return {
        "no effect": (MachineModel(), sensor),
        "servo mismatch + friction spikes": with_effects(
            ["servo_mismatch", "reversal_spikes"], MachineModel(), sensor
        ),
        "typical machine (all six effects)": (
            read_machine(data_path("machine_typical.toml")),
            sensor,
        ),
    }


def time_case(machine, sensor, repeat, before):
    """Median times of the workflow (before) and the monitor's nightly fit (after)."""
    settings, analysis = DiagnosticSettings(), AnalysisSettings()
    rows = []
    for seed in range(repeat):
        rec, _ = simulate_run(PROGRAM, machine, sensor, seed=100 + seed)
        row = {"samples": rec.n_samples}
        if before:
            t0, c0 = time.perf_counter(), time.process_time()
            result = find_discrepancy(rec)
            row["before_s"] = time.perf_counter() - t0
            row["before_cpu_s"] = time.process_time() - c0
            row["before_named"] = list(result.named_effects)
        t0, c0 = time.perf_counter(), time.process_time()
        fit = diagnose_recording(settings, rec, PROGRAM, analysis)
        row["after_s"] = time.perf_counter() - t0
        row["after_cpu_s"] = time.process_time() - c0
        if fit.failure:
            raise SystemExit(f"the diagnostic fit failed: {fit.failure}")
        row |= {
            "after_base_fit_s": fit.fit["timings_s"]["base_fit"],
            "after_steps": fit.fit["steps"],
            "after_settled": fit.fit["settled"],
            "after_simulator_runs": fit.fit["simulator_runs"],
        }
        rows.append(row)
    out = {"samples": rows[0]["samples"], "runs": rows}
    keys = ("before_s", "before_cpu_s", "after_s", "after_cpu_s", "after_base_fit_s")
    for key in (*keys, "after_simulator_runs"):
        if key in rows[0]:
            out[key] = statistics.median(r[key] for r in rows)
    return out


def fleet(seconds_per_night):
    """What a fleet's archive costs to rebuild from a night's figure."""
    nights = FLEET_MACHINES * FLEET_YEARS * 365
    core_hours = nights * seconds_per_night / 3600
    return {
        "machines": FLEET_MACHINES,
        "years": FLEET_YEARS,
        "nights": nights,
        "seconds_per_night": seconds_per_night,
        "core_hours": core_hours,
        "wall_hours": {str(n): core_hours / n for n in CLUSTER_CORES},
    }


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3, help="recordings per machine")
    ap.add_argument("--no-before", action="store_true", help="skip the workflow's timing")
    ap.add_argument("--cores", type=int, default=1, help="CPUs the process may use")
    args = ap.parse_args()
    if hasattr(os, "sched_setaffinity"):
        cpus = sorted(os.sched_getaffinity(0))[: args.cores]
        os.sched_setaffinity(0, cpus)
    sensor = read_sensor(data_path("sensor_paper.toml"))
    cases = {}
    for label, (machine, s) in machines(sensor).items():
        print(f"{label} ...", file=sys.stderr, flush=True)
        cases[label] = time_case(machine, s, args.repeat, not args.no_before)
    worst = max(c["after_cpu_s"] for c in cases.values())
    doc = {
        "software": __version__,
        "program": PROGRAM.to_mapping(),
        "cores": args.cores,
        "repeat": args.repeat,
        "effects": list(DiagnosticSettings().effects),
        "cases": cases,
        "fleet": fleet(worst),
    }
    print(
        f"The monitor's nightly diagnostics on the paper's test ({cases['no effect']['samples']} "
        f"samples at 1 kHz), {args.cores} core(s), median of {args.repeat} [s]"
    )
    print("CPU time (wall time) of one night's fit")
    print(f"{'machine':36} {'before (workflow)':>18} {'after (nightly fit)':>20} {'sim runs':>9}")
    for label, c in cases.items():
        before = f"{c['before_cpu_s']:.1f} ({c['before_s']:.1f})" if "before_s" in c else "-"
        after = f"{c['after_cpu_s']:.1f} ({c['after_s']:.1f})"
        print(f"{label:36} {before:>18} {after:>20} {c['after_simulator_runs']:>9.0f}")
    f = doc["fleet"]
    walls = ", ".join(f"{h:.1f} h on {n} cores" for n, h in f["wall_hours"].items())
    print(
        f"\nA fleet's archive, {f['machines']} machines x {f['years']} years = {f['nights']} "
        f"nights at {f['seconds_per_night']:.1f} s: {f['core_hours']:.0f} core-hours "
        f"({walls})"
    )
    RESULTS.parent.mkdir(parents=True, exist_ok=True)
    RESULTS.write_text(json.dumps(doc, indent=1, default=float) + "\n", encoding="utf-8")
    print(f"wrote {RESULTS}")


if __name__ == "__main__":
    main()
