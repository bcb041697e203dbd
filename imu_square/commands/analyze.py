"""``imu-square analyze``: squareness of one or more recorded runs."""

import json
import sys

from imu_square.errors import ImuSquareError


def register(sub):
    """Add the ``analyze`` subcommand."""
    p = sub.add_parser(
        "analyze",
        help="squareness from recorded runs",
        description="Filter, segment, flip, average and fit each recording; print the "
        "squareness (theta_y - theta_x) with its uncertainty. Human summary on stderr; "
        "--json writes one JSON object per run to stdout.",
    )
    p.add_argument("recordings", nargs="+", metavar="RUN.mcap", help="recording(s) to analyse")
    p.add_argument("--json", action="store_true", help="one JSON object per run on stdout")
    p.add_argument("--plot", metavar="OUT.png", help="write the traces, fits and convergence")
    p.add_argument("--program", help="test program TOML, overriding the recording's")
    p.add_argument(
        "--cutoff-hz",
        type=float,
        default=None,
        help="low-pass cutoff (default: 8 pi x the circle frequency, the paper's 4 Hz at "
        "its 0.16 Hz circle)",
    )
    p.add_argument("--order", type=int, default=1, help="low-pass order (default: %(default)s)")
    p.add_argument(
        "--gain-tolerance",
        type=float,
        default=0.01,
        metavar="FRACTION",
        help="largest error of the sensor's mean x/y gain, which bounds the servos' "
        "amplitude share of the result (default: %(default)s)",
    )
    p.add_argument(
        "--bootstrap",
        type=int,
        default=200,
        metavar="N",
        help="bootstrap resamples over cycles, 0 to skip (default: %(default)s)",
    )
    p.set_defaults(func=run)


def run(args):
    """Analyse each recording; return 2 if any could not be analysed."""
    from imu_square.errors import AnalysisError
    from imu_square.io.mcap import read_mcap
    from imu_square.pipeline.convergence import convergence
    from imu_square.pipeline.squareness import AnalysisOptions, analyze
    from imu_square.program import read_program
    from imu_square.units import SQUARENESS_UNIT, URAD

    options = AnalysisOptions(
        cutoff_hz=args.cutoff_hz,
        order=args.order,
        bootstrap_n=args.bootstrap,
        gain_tolerance=args.gain_tolerance,
    )
    program = read_program(args.program) if args.program else None
    results = []
    status = 0
    for path in args.recordings:
        try:
            recording = read_mcap(path)  # its errors name the file
            result = analyze(recording, options, program=program)
        except AnalysisError as exc:  # the pipeline names no file: say which
            print(f"imu-square analyze: error: {path}: {exc}", file=sys.stderr)
            status = 2
            continue
        except ImuSquareError as exc:
            print(f"imu-square analyze: error: {exc}", file=sys.stderr)
            status = 2
            continue
        results.append(result)
        last_path = path
        conv = convergence([r.squareness_rad for r in results])
        print(f"{path}: {result.summary()}", file=sys.stderr)
        if len(results) > 1:
            print(
                f"  after {len(results)} runs: mean {conv.mean_rad[-1] / URAD:.1f} ± "
                f"{conv.u_mean_rad[-1] / URAD:.1f} {SQUARENESS_UNIT} (type A over runs)",
                file=sys.stderr,
            )
        if args.json:
            doc = {"recording": str(path), **result.to_json_dict()}
            doc["source"] = str(path)  # the old name of "recording", kept for one release
            doc["convergence"] = conv.to_json_dict()
            print(json.dumps(doc), file=sys.stdout, flush=True)
    if args.plot and results:
        from imu_square.pipeline.plot import plot_results

        title = str(last_path) if len(results) == 1 else f"{len(results)} runs"
        plot_results(results, args.plot, convergence([r.squareness_rad for r in results]), title)
        print(f"wrote {args.plot}", file=sys.stderr)
    return status
