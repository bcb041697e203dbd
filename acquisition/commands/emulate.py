"""``imu-square emulate``: an emulated accelerometer board on a pseudo-terminal."""

import json
import secrets
import sys
from pathlib import Path

from imu_square.simulate.sources import MOTION_SOURCES

HELP = "emulate a serial accelerometer board on a pseudo-terminal"


def register(sub):
    """Add the ``emulate`` subcommand."""
    p = sub.add_parser(
        "emulate",
        help=HELP,
        description="Simulate a circle test and stream it through the wire protocol on a "
        "pseudo-terminal symlinked at --link, in real time on the board's sample clock. "
        "Writes the simulator's truth and the exact fault log as JSON and prints its path. "
        "Exit codes: 0 streamed to the end, or stopped by Ctrl-C or SIGTERM (the truth is "
        "written either way); 2 a bad option, or --link cannot be made.",
    )
    p.add_argument("--program", required=True, help="program TOML")
    p.add_argument("--machine", help="machine TOML (default: an ideal machine)")
    p.add_argument(
        "--sensor", help="sensor TOML (default: the paper's ADXL355-like sensor at 1 kHz)"
    )
    p.add_argument(
        "--motion",
        choices=MOTION_SOURCES,
        default="trajectory",
        help="the commanded motion: our own trajectory (default) or LinuxCNC's planner "
        "(run in real time before streaming, or from its cache)",
    )
    p.add_argument("--link", required=True, help="path of the symlink to the pty's slave end")
    p.add_argument("--speed", type=float, default=1.0, help="run N times faster than real time")
    p.add_argument("--mode", choices=("binary", "line"), default="binary", help="wire mode")
    p.add_argument(
        "--baud",
        type=int,
        default=921600,
        help="line speed the board claims (a pty ignores it; recorded in the truth)",
    )
    p.add_argument("--seed", type=int, help="seed of noise and faults (default: random)")
    p.add_argument(
        "--faults",
        default="",
        help="e.g. corrupt=0.001,drop=0.0005,garbage=2,disconnect=30:5,clock_ppm=50 "
        "(per-byte probabilities; bursts over the run; unplug AT:FOR s of board time; "
        "sample clock error in ppm)",
    )
    p.add_argument(
        "--seq-start", type=int, default=0, help="first sequence number (wraps at 2**32)"
    )
    p.add_argument("--truth", help="truth JSON path (default: LINK.truth.json)")
    p.set_defaults(func=run)


def run(args):
    """Stream until the run is over (or Ctrl-C/SIGTERM), write the truth, print its path."""
    from acquisition.commands._session import stop_signals
    from acquisition.emulator import emulated_board
    from acquisition.faults import parse_faults
    from imu_square.program import read_program
    from imu_square.simulate import data_path, read_machine, read_sensor
    from imu_square.simulate.sources import commanded_motion

    program = read_program(args.program)
    machine = read_machine(args.machine or data_path("machine_ideal.toml"))
    sensor = read_sensor(args.sensor or data_path("sensor_paper.toml"))
    faults = parse_faults(args.faults)
    seed = args.seed if args.seed is not None else secrets.randbits(63)
    motion = commanded_motion(program, args.motion, lambda text: print(text, file=sys.stderr))
    board, truth = emulated_board(
        program,
        machine,
        sensor,
        faults=faults,
        seed=seed,
        link=args.link,
        speed=args.speed,
        mode=args.mode,
        seq_start=args.seq_start,
        motion=motion,
    )
    truth_path = Path(args.truth) if args.truth else Path(args.link + ".truth.json")
    print(
        f"emulated board on {args.link}: {len(board.counts)} samples at "
        f"{board.header.sample_rate_hz:g} Hz, speed x{args.speed:g}, {args.mode} mode",
        file=sys.stderr,
    )
    with stop_signals(board.stop):
        log = board.run()
    truth["emulator"] = {
        "link": args.link,
        "mode": args.mode,
        "speed": args.speed,
        "baud": args.baud,
        "faults": args.faults,
        "seq_start": args.seq_start,
        "scale_m_s2_per_count": board.header.scale_m_s2_per_count,
        "log": log.as_dict(),
    }
    truth_path.write_text(json.dumps(truth, indent=1) + "\n", encoding="utf-8")
    summary = log.summary()
    print(
        f"sent {summary['samples_sent']}, damaged {summary['samples_damaged']}, swallowed by "
        f"a neighbour's damage {summary['samples_swallowed']}, lost with no host "
        f"{summary['samples_no_host']}, overflow {summary['samples_overflow']} samples",
        file=sys.stderr,
    )
    print(truth_path)
    return 0
