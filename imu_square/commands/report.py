"""``imu-square report``: one self-contained HTML page about a machine's squareness."""

import sys

from imu_square.commands._monitor import add_config_argument, monitor_session

HELP = "write a self-contained HTML report of a machine's squareness"


def register(sub):
    """Add the ``report`` subcommand."""
    p = sub.add_parser(
        "report",
        help=HELP,
        description="One HTML file with everything inline: the verdict, the trend chart, the "
        "last valid run in the paper's Fig. 5 style, eps_c and the sensor temperature over "
        "time, the baseline with its anchors, the alarm design, and the latest nights.",
    )
    add_config_argument(p)
    p.add_argument("-o", "--output", required=True, metavar="REPORT.html", help="file to write")
    p.set_defaults(func=run)


def run(args):
    """Judge the history and write the page."""
    from imu_square.io.output import check_output_path
    from imu_square.monitor.night import judge_history
    from imu_square.monitor.publish import last_valid_result
    from imu_square.monitor.report.html import render_report, write_report

    check_output_path(args.output, overwrite=True)
    with monitor_session(args.config) as (config, history):
        assessment = judge_history(config, history)
        last, title = last_valid_result(assessment, config.analysis.options())
        write_report(args.output, render_report(assessment, last, title))
    print(f"wrote {args.output}", file=sys.stderr)
    return 0
