"""``imu-square reference``: what a ballbar, a laser or a square would read on a machine."""

import json
import sys

from imu_square.errors import ConfigError
from imu_square.reference import (
    ORIENTATIONS_DEG,
    ballbar_squareness,
    biaxial_squareness,
    diagonal_squareness,
)
from imu_square.simulate import read_machine

METHODS = ("ballbar", "diagonal", "L", "T", "+")


def register(sub):
    """Add the ``reference`` subcommand."""
    p = sub.add_parser(
        "reference",
        help="squareness a ballbar, laser diagonal or L/T/+ test would give on a machine file",
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
    p.add_argument("--json", action="store_true", help="print the results as JSON on stdout")
    p.set_defaults(func=run)


def _results(machine, methods, radius_m):
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
            out[method] = {"squareness_rad": r.squareness_rad, "radius_m": radius_m}
        elif method == "diagonal":
            out[method] = {"squareness_rad": diagonal_squareness(g.deviation, x_range, y_range)}
        else:
            out[method] = {
                f"{o}deg": biaxial_squareness(
                    g.deviation, method, o, x_range, y_range
                ).squareness_rad
                for o in ORIENTATIONS_DEG
            }
    return out


def run(args):
    """Print the squareness of each reference method."""
    machine = read_machine(args.machine)
    g = machine.geometry
    radius_m = (
        min(g.length_x_m, g.length_y_m) / 2 if args.radius_mm is None else args.radius_mm * 1e-3
    )
    if not radius_m > 0:
        raise ConfigError(f"--radius-mm must be > 0, got {args.radius_mm!r}")
    methods = METHODS if args.method is None else (args.method,)
    results = _results(machine, methods, radius_m)
    for method, r in results.items():
        if "squareness_rad" in r:
            text = f"{r['squareness_rad'] * 1e6:9.3f}"
            if method == "ballbar":
                text += f"   (r = {radius_m * 1e3:g} mm, centre of travel)"
        else:
            text = "  ".join(f"{k:>6} {v * 1e6:9.3f}" for k, v in r.items())
        print(f"{method:>8}  {text}  um/m", file=sys.stderr)
    if args.json:
        json.dump({"machine": args.machine, "methods": results}, sys.stdout, indent=2)
        sys.stdout.write("\n")
    return 0
