"""Simulator speed as a multiple of real time, for a ~200 s recording at 1 kHz.

The program is the paper's test (r = 100 mm, 6000 mm/min, 15 cycles each way,
180 deg overshoots, 2 s dwell), recorded without idle lead-in/out: 203 s.
Three cases: an ideal machine and sensor; the paper's sensor (7 ug/sqrt(Hz),
ADC steps, clipping); every named effect on, with the paper's sensor plus 1/f
noise. Median of 5 runs each.

Run: ``.venv/bin/python benchmarks/simulator_speed.py``; writes
``benchmarks/results/simulator_speed.json``.
"""

import json
import statistics
import time
from dataclasses import replace
from pathlib import Path

from imu_square.program import read_program
from imu_square.simulate import (
    EFFECTS,
    MachineModel,
    SensorModel,
    data_path,
    read_sensor,
    simulate_run,
    with_effects,
)

REPEATS = 5


def main():
    program = read_program(data_path("program_paper.toml"))
    paper = read_sensor(data_path("sensor_paper.toml"))
    machine_all, sensor_all = with_effects(EFFECTS, None, replace(paper, flicker_corner_hz=0.5))
    cases = {
        "ideal": (MachineModel(), SensorModel()),
        "paper sensor": (MachineModel(), paper),
        "all effects": (machine_all, sensor_all),
    }
    rows = []
    for name, (machine, sensor) in cases.items():
        times = []
        for seed in range(REPEATS):
            start = time.perf_counter()
            recording, _ = simulate_run(
                program, machine, sensor, seed=seed, lead_in_s=0.0, lead_out_s=0.0
            )
            times.append(time.perf_counter() - start)
        wall = statistics.median(times)
        rows.append(
            {
                "case": name,
                "recording_s": recording.duration_s,
                "samples": recording.n_samples,
                "median_wall_s": wall,
                "times_real_time": recording.duration_s / wall,
            }
        )
    print(f"{'case':<14} {'recording s':>11} {'samples':>8} {'wall s':>8} {'x real time':>12}")
    for r in rows:
        print(
            f"{r['case']:<14} {r['recording_s']:>11.1f} {r['samples']:>8d} "
            f"{r['median_wall_s']:>8.4f} {r['times_real_time']:>12.0f}"
        )
    out = Path(__file__).parent / "results" / "simulator_speed.json"
    out.parent.mkdir(exist_ok=True)
    out.write_text(json.dumps({"repeats": REPEATS, "rows": rows}, indent=2) + "\n")


if __name__ == "__main__":
    main()
