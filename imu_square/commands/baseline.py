"""``imu-square baseline``: set, show and anchor a machine's baseline."""

import json
import math
import sys

from imu_square.commands._monitor import add_config_argument, monitor_session
from imu_square.commands._output import result_stream
from imu_square.errors import ImuSquareError

HELP = "set, show or anchor a machine's baseline (its squareness when monitoring began)"


def register(sub):
    """Add the ``baseline`` subcommand."""
    p = sub.add_parser(
        "baseline",
        help=HELP,
        description="The baseline is the machine's own theta_y - theta_x when the monitor was "
        "set up, the mean of at least 3 valid runs; every night's change is measured against "
        "it. An anchor by a reference method (a ballbar's value, or ISO 230-6 laser diagonals) "
        "turns the change into an absolute machine squareness.",
    )
    actions = p.add_subparsers(dest="action", metavar="ACTION", required=True)
    s = actions.add_parser("set", help="set a new baseline from runs")
    add_config_argument(s)
    s.add_argument(
        "runs",
        nargs="*",
        metavar="RUN",
        help="recordings (.mcap, analysed and stored if new) or run ids of the history",
    )
    s.add_argument("--last", type=int, metavar="N", help="the last N valid runs of the history")
    s.add_argument("--note", default="", help="free text kept with the baseline")
    s.add_argument("--json", action="store_true", help="the baseline as JSON on stdout")
    s.set_defaults(func=run_set)
    show = actions.add_parser("show", help="print the current baseline and its alarm design")
    add_config_argument(show)
    show.add_argument("--json", action="store_true", help="as JSON on stdout")
    show.set_defaults(func=run_show)
    a = actions.add_parser("anchor", help="anchor the baseline by a reference method")
    add_config_argument(a)
    how = a.add_mutually_exclusive_group(required=True)
    how.add_argument("--ballbar", type=float, metavar="UM_PER_M", help="a ballbar's squareness")
    how.add_argument(
        "--diagonals",
        type=float,
        nargs=2,
        metavar=("D1_MM", "D2_MM"),
        help="measured lengths of the face diagonals (ISO 230-6), D1 from (x max, y min) to "
        "(x min, y max); needs --travel-mm",
    )
    a.add_argument("--u", type=float, metavar="UM_PER_M", help="the ballbar's uncertainty (k=1)")
    a.add_argument(
        "--travel-mm", type=float, nargs=2, metavar=("X", "Y"), help="the diagonals' rectangle"
    )
    a.add_argument("--note", default="", help="free text kept with the anchor")
    a.set_defaults(func=run_anchor)


def _describe(row, design):
    from imu_square.monitor.verdict import iso
    from imu_square.units import URAD

    lines = [
        f"baseline {row.id} of machine {row.machine_id}: theta_y - theta_x "
        f"{row.squareness_mean_rad / URAD:+.2f} ± {row.u_squareness_mean_rad / URAD:.2f} µm/m "
        f"(k=1; {len(row.run_ids)} runs, spread {(row.squareness_sd_rad or 0) / URAD:.2f} µm/m), "
        f"eps_c {math.degrees(row.eps_c_rad):.3f} ± {math.degrees(row.u_eps_c_rad):.3f}°",
        f"  runs {iso(row.first_run_at_ns)} to {iso(row.last_run_at_ns)}, "
        f"set {iso(row.created_at_ns)}" + (f"; STALE: {row.stale_reason}" if row.stale else ""),
    ]
    if design is not None:
        lines.append(f"  alarms: {design.describe()}")
    return "\n".join(lines)


def _json(row, design, anchors=()):
    from imu_square.monitor.verdict import iso
    from imu_square.units import URAD

    return {
        "id": row.id,
        "machine_id": row.machine_id,
        "squareness_urad": row.squareness_mean_rad / URAD,
        "u_squareness_urad": row.u_squareness_mean_rad / URAD,
        "sd_urad": None if row.squareness_sd_rad is None else row.squareness_sd_rad / URAD,
        "eps_c_deg": math.degrees(row.eps_c_rad),
        "u_eps_c_deg": math.degrees(row.u_eps_c_rad),
        "run_ids": list(row.run_ids),
        "first_run_at": iso(row.first_run_at_ns),
        "last_run_at": iso(row.last_run_at_ns),
        "created_at": iso(row.created_at_ns),
        "stale": row.stale,
        "stale_reason": row.stale_reason,
        "note": row.note,
        "alarm_design": None if design is None else design.to_json_dict(),
        "anchors": [
            {
                "method": a.method,
                "machine_squareness_urad": a.value_rad / URAD,
                "u_machine_squareness_urad": None
                if a.u_value_rad is None
                else a.u_value_rad / URAD,
                "input": a.input,
                "created_at": iso(a.created_at_ns),
            }
            for a in anchors
        ],
    }


def run_set(args):
    """Set a baseline from the runs given, design its alarms, print it."""
    from imu_square.monitor.baseline_setup import runs_for_baseline, set_baseline
    from imu_square.monitor.night import stored_design

    if bool(args.runs) == (args.last is not None):
        raise ImuSquareError("give the baseline's runs (RUN...) or --last N, one of the two")
    with monitor_session(args.config) as (config, history):
        program = config.test_program()
        diagnostics = {}
        if args.last is not None:
            valid = history.runs(config.machine_id, valid_only=True)
            if args.last < 1 or args.last > len(valid):
                raise ImuSquareError(
                    f"--last must be in [1, {len(valid)}] (the valid runs in the history), "
                    f"got {args.last}"
                )
            runs = valid[-args.last :]
        else:
            runs, diagnostics = runs_for_baseline(config, history, args.runs, program)
        print("setting the baseline and designing its alarm charts ...", file=sys.stderr)
        row = set_baseline(config, history, runs, note=args.note, diagnostics=diagnostics)
        design = stored_design(history, row, config.alarms)
        print(_describe(row, design), file=result_stream(args))
        if args.json:
            print(json.dumps(_json(row, design)))
    return 0


def run_show(args):
    """Print the current baseline."""
    from imu_square.monitor.night import stored_design
    from imu_square.units import URAD

    with monitor_session(args.config) as (config, history):
        row = history.current_baseline(config.machine_id)
        if row is None:
            raise ImuSquareError(
                f"machine {config.machine_id!r} has no baseline in {history.location}: set one "
                f"with 'imu-square baseline set --config {args.config} RUN...'"
            )
        design = stored_design(history, row, config.alarms)
        anchors = history.anchors(row.id)
        print(_describe(row, design), file=result_stream(args))
        for a in anchors:
            print(
                f"  anchor by {a.method}: {a.value_rad / URAD:+.2f} µm/m", file=result_stream(args)
            )
        if args.json:
            print(json.dumps(_json(row, design, anchors)))
    return 0


def run_anchor(args):
    """Anchor the current baseline by a ballbar value or laser diagonals."""
    from imu_square.monitor.baseline_setup import anchor_by_ballbar, anchor_by_diagonals
    from imu_square.units import URAD

    with monitor_session(args.config) as (config, history):
        row = history.current_baseline(config.machine_id)
        if row is None:
            raise ImuSquareError(f"machine {config.machine_id!r} has no baseline to anchor")
        if args.ballbar is not None:
            if args.travel_mm is not None:
                raise ImuSquareError("--travel-mm goes with --diagonals, not --ballbar")
            anchor = anchor_by_ballbar(history, row, args.ballbar, args.u, args.note)
        else:
            if args.travel_mm is None:
                raise ImuSquareError("--diagonals needs --travel-mm X Y (the diagonals' rectangle)")
            if args.u is not None:
                raise ImuSquareError("--u goes with --ballbar")
            anchor = anchor_by_diagonals(history, row, args.diagonals, args.travel_mm, args.note)
        print(
            f"baseline {row.id} anchored by {anchor.method}: machine squareness "
            f"{anchor.value_rad / URAD:+.2f} µm/m at the baseline; every night now also reports "
            f"it plus the change",
            file=result_stream(args),
        )
    return 0
