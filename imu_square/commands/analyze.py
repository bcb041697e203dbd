"""``imu-square analyze``: squareness of one or more recorded runs."""

import json
import sys
from pathlib import Path

from imu_square.commands._output import result_stream
from imu_square.errors import ImuSquareError

HELP = "squareness from recorded runs"


def register(sub):
    """Add the ``analyze`` subcommand."""
    p = sub.add_parser(
        "analyze",
        help=HELP,
        description="Filter, segment, flip, average and fit each recording; print the "
        "squareness (theta_y - theta_x) with its uncertainty: a summary on stdout, or with "
        "--json one JSON object per run on stdout (the summary then on stderr).",
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
        "--separate-gravity",
        action="store_true",
        help="fit the same circle at two feeds or more jointly (a recording of a program with "
        "feeds_mm_per_min, or one recording per feed) and report the squareness freed of "
        "gravity coupling, the coupling, and each feed's plain result; --json writes one object",
    )
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
    if args.plot:  # refuse a bad output before the work, not after it
        from imu_square.io.output import check_plot_path

        check_plot_path(args.plot)
    if args.separate_gravity:
        return _run_separated(args, options, program)
    results = []
    status = 0
    seen = {}
    for path in args.recordings:
        try:
            recording = read_mcap(path)  # its errors name the file
            _check_new(seen, path, recording)
            _check_one_feed(program or recording.program)
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
        print(f"{path}: {result.summary()}", file=result_stream(args))
        if len(results) > 1:
            print(
                f"  after {len(results)} runs: mean {conv.mean_rad[-1] / URAD:.1f} ± "
                f"{conv.u_mean_rad[-1] / URAD:.1f} {SQUARENESS_UNIT} (type A over runs)",
                file=result_stream(args),
            )
        if args.json:
            doc = {"recording": str(path), **result.to_json_dict()}
            doc["source"] = str(path)  # the old name of "recording", kept for one release
            doc["convergence"] = conv.to_json_dict()
            print(json.dumps(doc), file=sys.stdout, flush=True)
    if args.plot and results:
        from imu_square.pipeline.run_figure import plot_results

        title = Path(last_path).name if len(results) == 1 else f"{len(results)} runs"
        plot_results(results, args.plot, convergence([r.squareness_rad for r in results]), title)
        print(f"wrote {args.plot}", file=sys.stderr)
    return status


def _check_one_feed(program):
    """Refuse a multi-feed program without --separate-gravity, saying what to do."""
    from imu_square.errors import AnalysisError

    if program is not None and program.n_feeds > 1:
        feeds = ", ".join(f"{v * 6e4:g}" for v in program.feeds)
        raise AnalysisError(
            f"the program runs {program.n_feeds} feeds ({feeds} mm/min): analyse it with "
            "--separate-gravity, which also reports each feed's plain result"
        )


def _run_separated(args, options, program):
    """Fit every feed of every recording jointly; one JSON object for all."""
    from imu_square.io.mcap import read_mcap
    from imu_square.pipeline.gravity import analyze_feeds, separate_gravity

    # the messages of reading and of the pipeline name the file (and the feed)
    sources = [(path, read_mcap(path)) for path in args.recordings]
    _check_distinct(sources)
    feeds = analyze_feeds(sources, options, program)
    for f in feeds:
        label = f"{f.source} at {f.feed_mm_per_min:g} mm/min"
        print(f"{label}: {f.result.summary()}", file=result_stream(args))
    separation = separate_gravity(feeds)
    print(f"{len(feeds)} feeds: {separation.summary()}", file=result_stream(args))
    if args.json:
        doc = {"recordings": list(args.recordings), **separation.to_json_dict()}
        print(json.dumps(doc), file=sys.stdout, flush=True)
    if args.plot:
        from imu_square.pipeline.run_figure import plot_results

        last = feeds[-1]
        title = (
            f"{Path(last.source).name} at {last.feed_mm_per_min:g} mm/min "
            f"(the last of {len(feeds)} feeds)"
        )
        plot_results([f.result for f in feeds], args.plot, title=title)
        print(f"wrote {args.plot}", file=sys.stderr)
    return 0


def _check_distinct(sources):
    """Refuse one run given twice: its feeds would count twice and shrink the uncertainty."""
    seen = {}
    for path, recording in sources:
        _check_new(seen, path, recording)


def _check_new(seen, path, recording):
    """Refuse a recording whose samples ``seen`` (digest to path) holds already; add it."""
    import hashlib

    digest = hashlib.sha256(recording.accel.tobytes()).hexdigest()
    if digest in seen:
        raise ImuSquareError(
            f"recordings: {seen[digest]} and {path} hold the same samples: give each run "
            "once (a run counted twice would halve its variance)"
        )
    seen[digest] = path
