"""``imu-square reference``: what a ballbar, a laser or a square would read on a machine.

``--json`` gives each method's ``machine_squareness_rad``; the ballbar and
diagonal entries also keep the old key ``squareness_rad`` (same value) for one
release, for scripts written against it.
"""

import json
import sys

from imu_square.commands._output import result_stream
from imu_square.errors import ConfigError
from imu_square.reference import (
    ORIENTATIONS_DEG,
    REFERENCE_LINES,
    ballbar_squareness,
    biaxial_squareness,
    diagonal_squareness,
)
from imu_square.simulate import read_machine
from imu_square.units import MM, SQUARENESS_UNIT, URAD

METHODS = ("ballbar", "diagonal", "L", "T", "+")


HELP = "squareness a ballbar, laser diagonal or L/T/+ test would give on a machine file"


def register(sub):
    """Add the ``reference`` subcommand."""
    p = sub.add_parser(
        "reference",
        help=HELP,
        description="Simulate the ISO 230 reference squareness tests on the geometric errors of "
        "a machine file, over the full travel (global tests). L and T are run in all four "
        "orientations.",
    )
    p.add_argument("--machine", required=True, help="machine TOML file")
    p.add_argument("--method", choices=METHODS, help="one method only (default: all)")
    p.add_argument(
        "--radius-mm",
        type=float,
        help="ballbar radius (default: half the shorter axis travel)",
    )
    p.add_argument(
        "--reference-line",
        choices=REFERENCE_LINES,
        default="least_squares",
        help="reference line of the L/T/+ straightness traces (ISO 230-1; default: "
        "%(default)s, as in Chapman's paper)",
    )
    p.add_argument("--json", action="store_true", help="print the results as JSON on stdout")
    p.set_defaults(func=run)


def _results(machine, methods, radius_m, reference_line):
    g = machine.geometry
    cx, cy = g.axis_centre_m
    x_range = (cx - g.length_x_m / 2, cx + g.length_x_m / 2)
    y_range = (cy - g.length_y_m / 2, cy + g.length_y_m / 2)
    out = {}
    for method in methods:
        if method == "ballbar":
            r = ballbar_squareness(
                g.deviation,
                (cx, cy),
                radius_m,
                backlash=(machine.backlash_x_m, machine.backlash_y_m),
            )
            value = r.machine_squareness_rad
            out[method] = {"machine_squareness_rad": value, "radius_m": radius_m}
        elif method == "diagonal":
            value = diagonal_squareness(g.deviation, x_range, y_range)
            out[method] = {"machine_squareness_rad": value}
        else:
            out[method] = {
                f"{o}deg": biaxial_squareness(
                    g.deviation, method, o, x_range, y_range, reference_line=reference_line
                ).machine_squareness_rad
                for o in ORIENTATIONS_DEG
            }
            continue
        out[method]["squareness_rad"] = value  # the old key, kept for one release
    return out


def run(args):
    """Print the squareness of each reference method."""
    machine = read_machine(args.machine)
    g = machine.geometry
    radius_m = (
        min(g.length_x_m, g.length_y_m) / 2 if args.radius_mm is None else args.radius_mm * MM
    )
    if not radius_m > 0:
        raise ConfigError(f"--radius-mm must be > 0, got {args.radius_mm!r}")
    methods = METHODS if args.method is None else (args.method,)
    results = _results(machine, methods, radius_m, args.reference_line)
    for method, r in results.items():
        if "machine_squareness_rad" in r:
            text = f"{r['machine_squareness_rad'] / URAD:9.3f}"
            if method == "ballbar":
                text += f"   (r = {radius_m / MM:g} mm, centre of travel)"
        else:
            text = "  ".join(f"{k:>6} {v / URAD:9.3f}" for k, v in r.items())
        print(f"{method:>8}  {text}  {SQUARENESS_UNIT}", file=result_stream(args))
    if args.json:
        doc = {"machine": args.machine, "reference_line": args.reference_line, "methods": results}
        json.dump(doc, sys.stdout, indent=2)
        sys.stdout.write("\n")
    return 0
