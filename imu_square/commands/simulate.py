"""``imu-square simulate``: simulate a circle test and write run.mcap + run.truth.json."""

import json
import sys
import time
from pathlib import Path

from imu_square.io.times import parse_start_time
from imu_square.program import read_program
from imu_square.simulate import (
    EFFECTS,
    data_path,
    read_machine,
    read_sensor,
    simulate_run,
    with_effects,
)
from imu_square.simulate.sources import MOTION_SOURCES, commanded_motion
from imu_square.units import SQUARENESS_UNIT, URAD

HELP = "simulate a circle test (physics of machine and sensor) with its ground truth"


def register(sub):
    """Add the ``simulate`` subcommand."""
    p = sub.add_parser(
        "simulate",
        help=HELP,
        description="Simulate the accelerometer recording of a circle test and write it as "
        "MCAP, with the ground truth as JSON next to it (run.mcap -> run.truth.json). "
        "Program, machine and sensor default to the built-in paper test, ideal machine "
        "and ideal noiseless sensor.",
    )
    p.add_argument("--program", help="program TOML (default: the paper's test)")
    p.add_argument("--machine", help="machine TOML (default: an ideal machine)")
    p.add_argument("--sensor", help="sensor TOML (default: an ideal, noiseless sensor)")
    p.add_argument("-o", "--output", required=True, help="output MCAP file")
    p.add_argument("--seed", type=int, help="seed of the noise (default: random, in the truth)")
    p.add_argument(
        "--effects",
        default="",
        help="comma-separated effects to switch on at their default size, on top of the "
        f"machine and sensor files: {', '.join(EFFECTS)}",
    )
    p.add_argument(
        "--motion",
        choices=MOTION_SOURCES,
        default="trajectory",
        help="the commanded motion: our own trajectory (default) or LinuxCNC's trajectory "
        "planner running the program in real time (Debian's linuxcnc-uspace; each program's "
        "motion is cached, see the README)",
    )
    p.add_argument("--no-events", action="store_true", help="write no block start/end events")
    p.add_argument("--truth", help="truth JSON path (default: OUTPUT with .truth.json)")
    p.add_argument(
        "--start-time",
        metavar="ISO8601",
        help="when the recording starts, with its time zone (default: now, to the second)",
    )
    p.set_defaults(func=run)


def run(args):
    """Simulate, write the recording and the truth, print a one-line summary."""
    from imu_square.io.mcap import write_mcap

    program = read_program(args.program or data_path("program_paper.toml"))
    machine = read_machine(args.machine or data_path("machine_ideal.toml"))
    sensor = read_sensor(args.sensor or data_path("sensor_ideal.toml"))
    machine, sensor = with_effects(args.effects, machine, sensor)
    if args.start_time is None:
        t0_ns = time.time_ns() // 1_000_000_000 * 1_000_000_000
    else:
        t0_ns = parse_start_time(args.start_time)
    motion = commanded_motion(program, args.motion, lambda text: print(text, file=sys.stderr))
    recording, truth = simulate_run(
        program,
        machine,
        sensor,
        seed=args.seed,
        events=not args.no_events,
        t0_ns=t0_ns,
        motion=motion,
    )
    out = Path(args.output)
    truth_path = Path(args.truth) if args.truth else out.with_name(out.stem + ".truth.json")
    out.parent.mkdir(parents=True, exist_ok=True)
    truth_path.parent.mkdir(parents=True, exist_ok=True)
    write_mcap(recording, out)
    truth_path.write_text(json.dumps(truth, indent=2) + "\n", encoding="utf-8")
    square = f"{round(truth['squareness_rad'] / URAD, 2) + 0.0:.2f} {SQUARENESS_UNIT}"
    expected = f"{round(truth['expected_squareness_rad'] / URAD, 2) + 0.0:.2f} {SQUARENESS_UNIT}"
    if program.n_feeds > 1:
        per_feed = ", ".join(
            f"{round(f['expected_squareness_rad'] / URAD, 2) + 0.0:.2f} {SQUARENESS_UNIT} at "
            f"{f['feed_mm_per_min']:g} mm/min"
            for f in truth["feeds"]
        )
        free = round(truth["expected_squareness_gravity_free_rad"] / URAD, 2) + 0.0
        square += (
            f" (expected theta_y - theta_x on this circle {per_feed}; "
            f"{free:.2f} {SQUARENESS_UNIT} freed of gravity coupling)"
        )
    elif expected != square:
        square += f" (expected theta_y - theta_x on this circle {expected})"
    print(
        f"{out}: {recording.n_samples} samples, {recording.duration_s:.1f} s, "
        f"truth squareness {square}; truth in {truth_path}",
        file=sys.stdout,
    )
    return 0
