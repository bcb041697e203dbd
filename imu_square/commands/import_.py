"""``imu-square import``: convert a CSV recording into an MCAP recording."""

import sys

from imu_square.csv_import import FORMATS, GRAVITY_AXES, read_csv
from imu_square.mcap_io import write_mcap
from imu_square.program import read_program


def register(sub):
    """Add the ``import`` subcommand."""
    p = sub.add_parser(
        "import",
        help="convert a CSV recording to MCAP",
        description="Read accelerometer samples from CSV, check their units against gravity, "
        "and write them with the test program to an MCAP recording.",
    )
    p.add_argument("csv", help="CSV file")
    p.add_argument("--program", required=True, help="test program TOML the machine ran")
    p.add_argument("-o", "--output", required=True, help="MCAP file to write")
    p.add_argument(
        "--format",
        choices=sorted(FORMATS),
        default="imu-square",
        help="imu-square: time_s,accel_x,accel_y,accel_z[,temperature_c] in s and m/s^2; "
        "klipper: #time,accel_x,accel_y,accel_z in s and mm/s^2 (default: %(default)s)",
    )
    p.add_argument(
        "--gravity-axis",
        choices=GRAVITY_AXES,
        help="sensor axis that carries gravity (default: the axis with the largest mean)",
    )
    p.add_argument(
        "--columns",
        metavar="TIME,X,Y,Z[,TEMP]",
        help="header names of the columns to use, for a file with other column names",
    )
    p.add_argument("--machine-id", default="", help="machine the test ran on")
    p.set_defaults(func=run)


def run(args):
    """Import the CSV and write the MCAP file."""
    program = read_program(args.program)
    columns = None if args.columns is None else [c.strip() for c in args.columns.split(",")]
    recording = read_csv(
        args.csv,
        program,
        fmt=args.format,
        gravity_axis=args.gravity_axis,
        machine_id=args.machine_id,
        columns=columns,
    )
    write_mcap(recording, args.output)
    gaps = recording.gaps()
    print(
        f"imported {recording.n_samples} samples ({recording.duration_s:.3f} s at "
        f"{recording.sample_rate_hz:.6g} Hz, {len(gaps)} gaps, {recording.lost_samples} lost) "
        f"from {args.csv} to {args.output}",
        file=sys.stderr,
    )
    return 0
