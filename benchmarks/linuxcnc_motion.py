"""What LinuxCNC's trajectory planner does with the circle test, against our own trajectory.

For the paper's test (r = 100 mm at 6000 mm/min, 15 cycles each way) and a
fast test (r = 25 mm at 30,000 mm/min on axes limited to 10 m/s^2, 40 cycles),
both run by LinuxCNC on the project's simulated machining centre
(``imu_square/data/linuxcnc/``) and by our own trajectory (the machine file's
default 150 ms trapezoidal ramps), it measures:

- the feed ramps at block starts and ends: their length (to 99 % of the cruise
  speed) in time and in arc, the tangential acceleration in them and how
  constant it is (a trapezoidal ramp has one acceleration; a jerk-limited one
  starts and ends at zero), and whether the end mirrors the start;
- how far the tool is past the middle of the block's arc at the middle of its
  motion, where the pipeline anchors the position angle (0 when the ramps
  mirror each other);
- the feed along the full circles (the analysed cycles): its ripple and its
  deepest dip, and where the dip sits (the arcs of a block join at its start
  angle, every 360 deg);
- the largest radial deviation of the commanded path from the circle, where
  it sits, and that of the cruise;
- the squareness the pipeline reads on the motion with an ideal machine and a
  noiseless sensor turned by 2.1 deg (should be 0), and with +40 µm/m and the
  paper's sensor over ``--seeds`` noise seeds: the bias against the truth in
  units of the stated u (the mean error over the mean u; its standard error in
  brackets), and the spread of the errors over the mean u (about 1 when u is
  honest).

LinuxCNC runs each program once (the motion cache); the first call takes
about 5 minutes. It prints a Markdown table and writes
``benchmarks/results/linuxcnc_motion.json``.

Usage::

    python benchmarks/linuxcnc_motion.py [--seeds 20]
"""

import argparse
import json
import math
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from imu_square.linuxcnc import linuxcnc_motion
from imu_square.linuxcnc.runner import linuxcnc_version
from imu_square.pipeline.squareness import analyze
from imu_square.program import program_from_mapping, read_program
from imu_square.simulate import Geometry, MachineModel, data_path, read_sensor, simulate_run
from imu_square.simulate.trajectory import build_timeline
from imu_square.units import URAD

RESULTS = Path(__file__).parent / "results" / "linuxcnc_motion.json"
PERIOD_S = 1e-3
TESTS = {
    "paper": read_program(data_path("program_paper.toml")),
    "fast": program_from_mapping(
        {"radius_mm": 25.0, "feed_mm_per_min": 30000.0, "cycles_per_direction": 40, "dwell_s": 1.0}
    ),
}
ALPHA = 40e-6


class OurTrajectory:
    """Our own trajectory sampled as the controller's, for the same measures."""

    def __init__(self, program):
        machine = MachineModel()
        self.timeline = build_timeline(program, machine.ramp_s, machine.ramp_profile, 3.0, 3.0)
        t = np.arange(math.floor(self.timeline.duration_s / PERIOD_S) + 1) * PERIOD_S
        self.xy = np.column_stack([self.timeline.axis_path(t, a)[0] for a in (0, 1)])
        self.blocks = self.timeline.blocks


def _windows(motion):
    """Sample index ranges of each block's motion and of its analysed cycles."""
    out = []
    for b in motion.blocks:
        span = [round(x / PERIOD_S) for x in (b.t_start_s, b.t_end_s)]
        cyc = [round(x / PERIOD_S) for x in b.analysed_window_s]
        out.append((span, cyc))
    return out


def _xy(motion):
    if isinstance(motion, OurTrajectory):
        return motion.xy
    t = np.arange(math.floor(motion.duration_s / PERIOD_S) + 1) * PERIOD_S
    return np.column_stack([motion.axis_path(t, a)[0] for a in (0, 1)])


def measure_motion(motion, program):
    """Ramps, ripple and radial deviation of a motion sampled every servo period."""
    xy = _xy(motion)
    centre, r = np.asarray(program.centre_m), program.radius_m
    rel = xy - centre
    radial = np.hypot(rel[:, 0], rel[:, 1]) - r
    phi = np.arctan2(rel[:, 1], rel[:, 0])
    speed = np.hypot(*np.diff(xy, axis=0).T) / PERIOD_S  # step k: t_k .. t_k+1
    accel = np.diff(speed) / PERIOD_S  # tangential, at t_k+1
    cruise = float(np.median(np.concatenate([speed[c0:c1] for _, (c0, c1) in _windows(motion)])))
    ramps, ripple, deviation, anchors = [], [], [], []
    for (s0, s1), (c0, c1) in _windows(motion):
        up = s0 + int(np.argmax(speed[s0:s1] >= 0.99 * cruise))
        down = s1 - int(np.argmax(speed[s0:s1][::-1] >= 0.99 * cruise))
        for a, b in ((s0, up), (down, s1)):
            acc = np.abs(accel[a : b - 1])
            typical = float(np.median(acc))
            ramps.append(
                {
                    "length_ms": (b - a) * PERIOD_S * 1e3,
                    "arc_deg": math.degrees(np.sum(speed[a:b]) * PERIOD_S / r),
                    "accel_m_s2": typical,
                    # a trapezoidal ramp holds one acceleration; a jerk-limited one does not
                    "constant_share": float(np.mean(np.abs(acc - typical) <= 0.02 * typical)),
                }
            )
        # the pipeline anchors the angle at the motion's midpoint: where is the tool then?
        mid = (s0 + s1) // 2
        travelled = np.sum(speed[s0:mid]) * PERIOD_S / r
        anchors.append(math.degrees(travelled - 0.5 * np.sum(speed[s0:s1]) * PERIOD_S / r))
        seg = speed[c0:c1]
        k = c0 + int(np.argmin(seg))
        ripple.append(
            {
                "ripple": float((np.max(seg) - np.min(seg)) / cruise),
                "dip_mm_per_min": float((cruise - np.min(seg)) * 6e4),
                "dip_at_deg": math.degrees(phi[k]),
            }
        )
        worst = s0 + int(np.argmax(np.abs(radial[s0 : s1 + 1])))
        deviation.append(
            {
                "max_um": float(radial[worst] / 1e-6),
                "at_deg": math.degrees(phi[worst]),
                "at_ms_into_block": (worst - s0) * PERIOD_S * 1e3,
                "cruise_um": [
                    float(np.min(radial[c0:c1])) / 1e-6,
                    float(np.max(radial[c0:c1])) / 1e-6,
                ],
            }
        )
    starts, ends = ramps[0::2], ramps[1::2]
    worst = max(deviation, key=lambda d: abs(d["max_um"]))
    dip = max(ripple, key=lambda d: d["dip_mm_per_min"])
    return {
        "cruise_mm_per_min": cruise * 6e4,
        "ramp_start": {k: float(np.mean([x[k] for x in starts])) for k in starts[0]},
        "ramp_end": {k: float(np.mean([x[k] for x in ends])) for k in ends[0]},
        "midpoint_ahead_deg": float(np.mean(anchors)),
        "ripple": max(d["ripple"] for d in ripple),
        "dip_mm_per_min": dip["dip_mm_per_min"],
        "dip_at_deg": dip["dip_at_deg"],
        "radial_max_um": worst["max_um"],
        "radial_at_deg": worst["at_deg"],
        "radial_at_ms_into_block": worst["at_ms_into_block"],
        "radial_cruise_um": [
            min(d["cruise_um"][0] for d in deviation),
            max(d["cruise_um"][1] for d in deviation),
        ],
    }


def squareness(program, motion, seeds):
    """The pipeline on the motion: noiseless (should read 0), then +40 µm/m with noise."""
    ideal_sensor = read_sensor(data_path("sensor_ideal.toml"))
    turned = type(ideal_sensor)(eps_c_rad=math.radians(2.1))
    rec, truth = simulate_run(program, MachineModel(), turned, seed=1, motion=motion)
    zero = analyze(rec)
    eps_error_deg = math.degrees(zero.eps_c_rad - turned.eps_c_rad)
    paper = read_sensor(data_path("sensor_paper.toml"))
    machine = MachineModel(geometry=Geometry(machine_squareness_rad=ALPHA))
    errors, us = [], []
    for seed in range(seeds):
        rec, truth = simulate_run(program, machine, paper, seed=100 + seed, motion=motion)
        result = analyze(rec)
        errors.append(result.squareness_rad - truth["expected_squareness_rad"])
        us.append(result.u_squareness_rad)
    errors, u = np.array(errors), float(np.mean(us))
    return {
        "noiseless_urad": zero.squareness_rad / URAD,
        "noiseless_warnings": zero.quality["warnings"],
        "noiseless_eps_c_error_deg": eps_error_deg,
        "bias_over_u": float(np.mean(errors) / u),
        "bias_over_u_se": float(np.std(errors, ddof=1) / math.sqrt(seeds) / u),
        "spread_over_u": float(np.std(errors, ddof=1) / u),
        "u_urad": u / URAD,
        "seeds": seeds,
    }


def _row(name, m, s):
    rs, re_ = m["ramp_start"], m["ramp_end"]
    return (
        f"| {name} | {m['cruise_mm_per_min']:.0f} | "
        f"{rs['length_ms']:.0f} ms / {rs['arc_deg']:.2f}° at {rs['accel_m_s2']:.3g} m/s² "
        f"({rs['constant_share']:.0%} constant) | {re_['length_ms']:.0f} ms / "
        f"{re_['arc_deg']:.2f}° at {re_['accel_m_s2']:.3g} m/s² ({re_['constant_share']:.0%}) | "
        f"{m['midpoint_ahead_deg']:+.1f}° | "
        f"{m['ripple']:.1e} (dip {m['dip_mm_per_min']:.2g} mm/min at {m['dip_at_deg']:.0f}°) | "
        f"{m['radial_max_um']:+.3f} µm at {m['radial_at_deg']:.0f}°, "
        f"{m['radial_at_ms_into_block']:.0f} ms in (cruise {m['radial_cruise_um'][0]:+.3f} to "
        f"{m['radial_cruise_um'][1]:+.3f}) | {s['noiseless_urad']:+.3f} | "
        f"{s['bias_over_u']:+.2f} ({s['bias_over_u_se']:.2f}) u, spread {s['spread_over_u']:.2f} u "
        f"(u = {s['u_urad']:.1f} µm/m) |"
    )


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=20, help="noise seeds per test and motion")
    args = parser.parse_args()
    commit = subprocess.run(
        ["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True, check=False
    ).stdout.strip()
    doc = {"linuxcnc": linuxcnc_version(), "commit": commit, "tests": {}}
    lines = [
        "| test, motion | feed run [mm/min] | ramp at block start | at block end | tool ahead at "
        "the motion's midpoint | feed ripple over the full circles | largest radial deviation | "
        "noiseless [µm/m] | +40 µm/m, paper's noise: bias |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for name, program in TESTS.items():
        start = time.monotonic()
        lcnc = linuxcnc_motion(program, progress=lambda text: print(text, file=sys.stderr))
        for source, motion, sim in (
            ("LinuxCNC", lcnc, lcnc),
            ("ours", OurTrajectory(program), None),
        ):
            m = measure_motion(motion, program)
            s = squareness(program, sim, args.seeds)
            doc["tests"][f"{name}, {source}"] = {"motion": m, "squareness": s}
            lines.append(_row(f"{name}, {source}", m, s))
        print(f"{name}: {time.monotonic() - start:.0f} s", file=sys.stderr)
    RESULTS.parent.mkdir(exist_ok=True)
    RESULTS.write_text(json.dumps(doc, indent=1) + "\n")
    print(f"LinuxCNC {doc['linuxcnc']}, commit {commit}")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
