"""``imu-square analyze``: squareness of one or more recorded runs."""

import json
import math
import sys
from dataclasses import replace

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
        "--cutoff-hz", type=float, default=4.0, help="low-pass cutoff (default: %(default)s)"
    )
    p.add_argument("--order", type=int, default=1, help="low-pass order (default: %(default)s)")
    p.add_argument(
        "--bootstrap",
        type=int,
        default=200,
        metavar="N",
        help="bootstrap resamples over cycles, 0 to skip (default: %(default)s)",
    )
    p.set_defaults(func=run)


def format_summary(path, r):
    """One human-readable paragraph about the result ``r`` of the recording at ``path``."""
    q = r.quality
    lines = [
        f"{path}: squareness {r.squareness_rad * 1e6:.1f} ± {r.u_squareness_rad * 1e6:.1f} µm/m "
        f"(type A, k=1; bootstrap {r.u_squareness_bootstrap_rad * 1e6:.1f}, "
        f"noise floor {r.crb_rad * 1e6:.1f})",
        f"  eps_c {math.degrees(r.eps_c_rad):.3f} ± {math.degrees(r.u_eps_c_rad):.3f}°, "
        f"servo mismatch {r.servo_mismatch_rad * 1e6:.1f} ± "
        f"{r.u_servo_mismatch_rad * 1e6:.1f} µrad, cycles {r.cycles_used['ccw']} CCW + "
        f"{r.cycles_used['cw']} CW, amplitude {q['amplitude_ratio']:.3f} x v²/r, "
        f"period {q['period_disagreement']:+.3%}",
    ]
    lines += [f"  warning: {w}" for w in q["warnings"]]
    return "\n".join(lines)


def run(args):
    """Analyse each recording; return 2 if any could not be analysed."""
    from imu_square.io.mcap import read_mcap
    from imu_square.pipeline.convergence import convergence
    from imu_square.pipeline.squareness import AnalysisOptions, analyze
    from imu_square.program import read_program

    options = AnalysisOptions(
        cutoff_hz=args.cutoff_hz, order=args.order, bootstrap_n=args.bootstrap
    )
    program = read_program(args.program) if args.program else None
    results = []
    status = 0
    for path in args.recordings:
        try:
            result = analyze(read_mcap(path), options, program=program)
        except ImuSquareError as exc:
            print(f"imu-square analyze: error: {path}: {exc}", file=sys.stderr)
            status = 2
            continue
        result = replace(result, source=str(path))
        results.append(result)
        conv = convergence([r.squareness_rad for r in results])
        print(format_summary(path, result), file=sys.stderr)
        if len(results) > 1:
            print(
                f"  after {len(results)} runs: mean {conv.mean_rad[-1] * 1e6:.1f} ± "
                f"{conv.u_mean_rad[-1] * 1e6:.1f} µm/m (type A over runs)",
                file=sys.stderr,
            )
        if args.json:
            doc = result.to_json_dict()
            doc["convergence"] = conv.to_json_dict()
            print(json.dumps(doc), file=sys.stdout, flush=True)
    if args.plot and results:
        from imu_square.pipeline.plot import plot_results

        plot_results(results, args.plot, convergence([r.squareness_rad for r in results]))
        print(f"wrote {args.plot}", file=sys.stderr)
    return status
