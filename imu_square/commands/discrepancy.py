"""``imu-square discrepancy``: name the effects the simulator is missing for a recording."""

import json
import sys

from imu_square.commands._output import result_stream
from imu_square.simulate.sources import MOTION_SOURCES

HELP = "fit the simulator to a recording, name the missing effects, show the gap shrink"


def register(sub):
    """Add the ``discrepancy`` subcommand."""
    p = sub.add_parser(
        "discrepancy",
        help=HELP,
        description="Fit the simulator (the paper's model: squareness, sensor rotation and "
        "offsets) to a recording, show where they disagree in views normalised by the noise "
        "floor, add the effect of the simulator's vocabulary that best explains the gap, "
        "refit, and repeat while an effect is significant. The first line says whether a "
        "view's gap is left above the noise after the last step, and the lines 'gap left "
        "in' say where. Exit 0 when no effect was named, 1 when effects were named, 2 on a "
        "user error.",
    )
    p.add_argument("recording", metavar="RUN.mcap", help="the recording")
    p.add_argument("--json", action="store_true", help="the result as JSON on stdout")
    p.add_argument("--plot", metavar="OUT.png", help="each view's gap, step by step")
    p.add_argument(
        "--effects-allowed",
        metavar="NAME,...",
        help="comma-separated candidates (default: the whole vocabulary)",
    )
    p.add_argument(
        "--model-out",
        metavar="DIR",
        help="write the fitted model as program.toml, machine.toml, sensor.toml "
        "for imu-square simulate",
    )
    p.add_argument("--program", help="test program TOML, overriding the recording's")
    p.add_argument(
        "--motion",
        choices=MOTION_SOURCES,
        default="trajectory",
        help="the model's commanded motion: our own trajectory (default), or LinuxCNC's planner "
        "running the program (in real time, or from its cache), for a test a LinuxCNC "
        "machine ran",
    )
    p.add_argument(
        "--significance",
        type=float,
        default=0.01,
        help="family-wise significance level of each step (default: %(default)s)",
    )
    p.add_argument(
        "--no-suggest",
        action="store_true",
        help="skip simulating extra tests for effects this test cannot tell apart",
    )
    p.set_defaults(func=run)


def run(args):
    """Run the workflow and report; the exit code says whether effects were named."""
    from imu_square.discrepancy import DiscrepancyOptions, find_discrepancy
    from imu_square.errors import AnalysisError, ImuSquareError, OutputWriteError
    from imu_square.io.mcap import read_mcap
    from imu_square.program import read_program
    from imu_square.simulate.writer import write_model_files
    from imu_square.units import MM_PER_MIN

    program = read_program(args.program) if args.program else None
    options = DiscrepancyOptions(
        significance=args.significance,
        effects=args.effects_allowed if args.effects_allowed is not None else None,
        suggest=not args.no_suggest,
    )
    options.candidates()  # refuse an unknown effect before reading the file
    if args.plot:  # refuse a bad output before the work, not after it
        from imu_square.io.output import check_plot_path

        check_plot_path(args.plot)
    if args.model_out:  # checked now, made only when the fit has something to write
        from imu_square.io.output import check_folder_path

        check_folder_path(args.model_out, "model")
    recording = read_mcap(args.recording)
    prog = program or recording.program
    if prog is not None and prog.n_feeds > 1:  # else a message about a Python property
        feeds = ", ".join(f"{v / MM_PER_MIN:g}" for v in prog.feeds)
        raise ImuSquareError(
            f"{args.recording}: the program runs {prog.n_feeds} feeds ({feeds} mm/min); "
            "discrepancy fits a one-feed test: record each feed on its own, or use "
            "analyze --separate-gravity for the squareness"
        )
    motion = None
    if args.motion != "trajectory" and prog is not None:  # no program: analyze says so
        from imu_square.simulate.sources import commanded_motion

        motion = commanded_motion(prog, args.motion, lambda text: print(text, file=sys.stderr))
    try:
        result = find_discrepancy(recording, options, program=program, motion=motion)
    except AnalysisError as exc:  # the pipeline names no file: say which
        raise ImuSquareError(f"{args.recording}: {exc}") from None
    print(f"{args.recording}:", file=result_stream(args))
    print(result.summary(), file=result_stream(args))
    if args.model_out:
        header = (
            f"Fitted by imu-square discrepancy to {args.recording}\n"
            f"effects: {', '.join(s.effect for s in result.steps) or 'none'}"
        )
        try:
            paths = write_model_files(
                args.model_out, result.program, result.machine, result.sensor, header
            )
        except OSError as exc:  # disk full, permissions changed during the fit
            raise OutputWriteError(
                f"{args.model_out}: writing the model files failed: {exc.strerror or exc}"
            ) from None
        print(f"wrote {', '.join(str(p) for p in paths.values())}", file=sys.stderr)
    if args.plot:
        from imu_square.discrepancy.gap_figure import plot_gaps

        plot_gaps(result, args.plot, title=str(args.recording))
        print(f"wrote {args.plot}", file=sys.stderr)
    if args.json:
        doc = {"recording": str(args.recording), **result.to_json_dict()}
        print(json.dumps(doc, allow_nan=False), file=sys.stdout)
    return result.exit_code
