"""``imu-square compare``: the reference methods and the IMU side by side on a simulated machine."""

import json
import re
import sys

from imu_square.commands._output import result_stream
from imu_square.errors import ImuSquareError
from imu_square.reference import REFERENCE_LINES
from imu_square.units import MM

HELP = "ballbar, diagonal, L/T/+ and the IMU circle test side by side on a machine file"


def register(sub):
    """Add the ``compare`` subcommand."""
    p = sub.add_parser(
        "compare",
        help=HELP,
        description="Simulate on the machine file's errors what each squareness method reads, "
        "in the layout of Chapman's figures (a ballbar, full circle and 220° arc, per location "
        "and averaged; b diagonal; c +, d T, e L in four orientations), and the IMU circle test "
        "on the ballbar's circles through the simulator and the pipeline. The IMU row is "
        "theta_y - theta_x minus the simulated sensor's non-orthogonality beta: the machine's "
        "squareness as the IMU infers it. Each row says where and why it departs from the "
        "machine's squareness. A table in µm/m on stdout, or --json (the table then on stderr).",
    )
    p.add_argument("--machine", required=True, help="machine TOML file (as for simulate)")
    p.add_argument(
        "--locations",
        help="circle centres: a number N (N circles in a row along the longer axis, evenly "
        "spaced; default: as many as fit, ceil(long / short)) or 'x,y;x,y;...' in mm "
        "(use --locations='-250,0;0,0' for negative values)",
    )
    p.add_argument(
        "--radius-mm",
        type=float,
        help="ballbar and IMU circle radius (default: half the shorter travel)",
    )
    p.add_argument(
        "--program",
        help="IMU program TOML: its cycles, overshoot, dwell and centripetal acceleration are "
        "run on each ballbar circle (default: the paper's program at 2 m/s²)",
    )
    p.add_argument("--sensor", help="sensor TOML (default: the paper's sensor, 7 µg/√Hz)")
    p.add_argument(
        "--seed", type=int, default=0, help="noise seed of the first circle (default: %(default)s)"
    )
    p.add_argument(
        "--reference-line",
        choices=REFERENCE_LINES,
        default="least_squares",
        help="reference line of the L/T/+ traces (default: %(default)s)",
    )
    p.add_argument(
        "--local",
        action="store_true",
        help="also run the diagonal and L/T/+ tests on the square around each circle",
    )
    p.add_argument("--no-imu", action="store_true", help="skip the IMU rows (the slow part)")
    p.add_argument("--json", action="store_true", help="print the comparison as JSON on stdout")
    p.set_defaults(func=run)


def parse_locations(text):
    """``--locations``: a count, or ``x,y`` pairs in mm separated by ``;``.

    Parameters
    ----------
    text : str
        The option's value.

    Returns
    -------
    int or list of tuple of float
        A count, or centres in metres. [m]

    Raises
    ------
    ImuSquareError
        If the text is neither.
    """
    text = text.strip()
    if re.fullmatch(r"\d+", text):
        return int(text)
    centres = []
    for item in filter(None, (s.strip() for s in text.split(";"))):
        parts = item.split(",")
        try:
            if len(parts) != 2:
                raise ValueError
            centres.append(tuple(float(v) * MM for v in parts))
        except ValueError:
            raise ImuSquareError(
                f"--locations must be a count or 'x,y;x,y;...' in mm, got {text!r}"
            ) from None
    if not centres:
        raise ImuSquareError(f"--locations must be a count or 'x,y;x,y;...' in mm, got {text!r}")
    return centres


def run(args):
    """Print the table of methods and, with --json, the same as JSON."""
    from imu_square.program import read_program
    from imu_square.reference.compare import compare_methods
    from imu_square.simulate import read_machine, read_sensor

    machine = read_machine(args.machine)
    locations = parse_locations(args.locations) if args.locations else None
    radius_m = None if args.radius_mm is None else args.radius_mm * MM
    comparison = compare_methods(
        machine,
        locations,
        radius_m,
        program=read_program(args.program) if args.program else None,
        sensor=read_sensor(args.sensor) if args.sensor else None,
        seed=args.seed,
        reference_line=args.reference_line,
        local=args.local,
        imu=not args.no_imu,
    )
    print(comparison.to_text(), file=result_stream(args))
    if args.json:
        doc = {"machine": args.machine, **comparison.to_json_dict()}
        json.dump(doc, sys.stdout, indent=2)
        sys.stdout.write("\n")
    return 0
