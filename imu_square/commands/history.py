"""``imu-square history``: a machine's runs and verdicts, its trend chart, a back-up."""

import json
import math
import sys
from dataclasses import replace
from datetime import UTC, datetime

from imu_square.commands._monitor import add_config_argument, monitor_session
from imu_square.commands._output import result_stream
from imu_square.errors import ImuSquareError

HELP = "a machine's runs and verdicts, its trend chart, or a back-up of the history"


def register(sub):
    """Add the ``history`` subcommand."""
    p = sub.add_parser(
        "history",
        help=HELP,
        description="Print the machine's runs with the monitor's verdict on each (against the "
        "current baseline), then each night's diagnostics (value ± its uncertainty; ! past a "
        "diagnostic's alarm limit, ? past its warning limit), or write them as JSON, or draw "
        "the trend chart with the alarm limits, the baseline band, anchors, remounts and "
        "invalid runs marked, and beside it the diagnostics' chart (OUT-diagnostics.png). "
        "--backup copies the whole history safely while it is in use (SQLite's backup API; "
        "pg_dump for PostgreSQL).",
    )
    add_config_argument(p)
    p.add_argument("--json", action="store_true", help="one JSON object per run on stdout")
    p.add_argument("--plot", metavar="OUT.png", help="write the trend chart")
    p.add_argument("--since", metavar="YYYY-MM-DD", help="only runs recorded from this day (UTC)")
    p.add_argument("--backup", metavar="PATH", help="copy the whole history to PATH")
    p.add_argument(
        "--compare",
        nargs=2,
        metavar=("A", "B"),
        help="two histories (files or postgresql:// URLs) side by side, run by run (the same "
        "recording by its SHA-256), e.g. one replayed under other analysis settings",
    )
    p.set_defaults(func=run)


def _since(text):
    if text is None:
        return None
    try:
        return datetime.strptime(text, "%Y-%m-%d").replace(tzinfo=UTC)
    except ValueError:
        raise ImuSquareError(f"--since must be a date YYYY-MM-DD, got {text!r}") from None


def run(args):
    """Print the table (or JSON), draw the chart, back the history up, or compare two."""
    if args.compare:
        return _compare(args)
    import math

    from imu_square.monitor.history.encoding import ns_from_datetime
    from imu_square.monitor.night import judge_history, night_record
    from imu_square.monitor.verdict import iso, verdict
    from imu_square.units import URAD

    since = _since(args.since)
    if args.plot:
        from imu_square.io.output import check_plot_path

        check_plot_path(args.plot)
    if args.backup:
        from imu_square.io.output import check_output_path

        # Never make a missing folder: an unmounted share would be backed up to local disk.
        check_output_path(args.backup, overwrite=True)
    with monitor_session(args.config) as (config, history):
        if args.backup:
            path = history.backup(args.backup)
            print(f"backed up {history.location} to {path}", file=sys.stderr)
            return 0
        assessment = judge_history(config, history)
        start = None if since is None else ns_from_datetime(since)
        nights = [
            n
            for n in assessment.nights
            if start is None or (n.run.recorded_at_ns is not None and n.run.recorded_at_ns >= start)
        ]
        print(
            f"{'run':>5}  {'recorded':20}  {'state':14}  {'change µm/m':>16}  {'θy−θx µm/m':>11}  "
            f"{'eps_c °':>8}  {'machine µm/m':>16}  note",
            file=result_stream(args),
        )
        for n in nights:
            r = n.run
            change = ""
            if math.isfinite(n.change_rad):
                change = f"{n.change_rad / URAD:+7.1f} ± {n.u_change_rad / URAD:5.1f}"
            sq = "" if r.squareness_rad is None else f"{r.squareness_rad / URAD:+11.1f}"
            eps = "" if r.eps_c_rad is None else f"{math.degrees(r.eps_c_rad):8.3f}"
            print(
                f"{r.id:>5}  {iso(r.recorded_at_ns):20}  {n.state:14}  {change:>16}  {sq:>11}  "
                f"{eps:>8}  {_absolute(assessment, n):>16}  {n.reason}",
                file=result_stream(args),
            )
            if args.json:
                print(json.dumps(night_record(assessment, n, verdict(assessment, n))))
        from imu_square.monitor.diagnostics.text import note_lines, table_lines

        lines = table_lines(assessment.diagnostics, [n.run for n in nights])
        lines += note_lines(assessment.diagnostics, nights, config.motion)
        if lines:
            print("\ndiagnostics", file=result_stream(args))
        for line in lines:
            print(line, file=result_stream(args))
        if args.plot:
            _plot(assessment, nights, start, args.plot)
    return 0


def _plot(assessment, nights, start, path):
    """The trend chart, and the diagnostics' beside it (``OUT-diagnostics.png``)."""
    from pathlib import Path

    from imu_square.monitor.report.diagnostics_figure import plot_diagnostics
    from imu_square.monitor.report.figures import plot_trend

    shown = assessment
    if start is not None:
        runs = {n.run.id for n in nights}
        trends = tuple(
            replace(t, nights=tuple(n for n in t.nights if n.run.id in runs))
            for t in assessment.diagnostics
        )
        shown = replace(assessment, nights=tuple(nights), diagnostics=trends)
    plot_trend(shown, path)
    print(f"wrote {path}", file=sys.stderr)
    if shown.diagnostics:
        path = Path(path)
        beside = path.with_name(f"{path.stem}-diagnostics{path.suffix}")
        plot_diagnostics(shown, beside)
        print(f"wrote {beside}", file=sys.stderr)


def _compare(args):
    """Two histories of the machine side by side, by recording."""
    import math

    import numpy as np

    from imu_square.monitor.config import read_monitor
    from imu_square.monitor.history.store import open_history
    from imu_square.monitor.verdict import iso
    from imu_square.units import URAD

    machine = read_monitor(args.config).machine_id
    tables = []
    for location in args.compare:
        with open_history(location) as h:
            states = {e.run_id: e.state for e in h.evaluations(machine)}
            tables.append({r.recording_sha256: (r, states.get(r.id, "")) for r in h.runs(machine)})
    a, b = tables
    both = sorted(set(a) & set(b), key=lambda k: (a[k][0].recorded_at_ns or 0, k))
    print(
        f"{'recorded':20}  {'A θy−θx':>9}  {'B θy−θx':>9}  {'B − A':>7}  {'A state':14}  "
        f"{'B state':14}  (µm/m)",
        file=result_stream(args),
    )
    diffs = []
    for key in both:
        (ra, sa), (rb, sb) = a[key], b[key]
        va = math.nan if ra.squareness_rad is None else ra.squareness_rad / URAD
        vb = math.nan if rb.squareness_rad is None else rb.squareness_rad / URAD
        if math.isfinite(va) and math.isfinite(vb):
            diffs.append(vb - va)
        print(
            f"{iso(ra.recorded_at_ns):20}  {_cell(va, 9)}  {_cell(vb, 9)}  {_cell(vb - va, 7)}  "
            f"{sa:14}  {sb:14}",
            file=result_stream(args),
        )
        if args.json:
            print(
                json.dumps(
                    {
                        "recording_sha256": key,
                        "recorded_at": iso(ra.recorded_at_ns),
                        "a_squareness_urad": None if math.isnan(va) else va,
                        "b_squareness_urad": None if math.isnan(vb) else vb,
                        "a_u_squareness_urad": _urad(ra.u_squareness_rad),
                        "b_u_squareness_urad": _urad(rb.u_squareness_rad),
                        "a_state": sa,
                        "b_state": sb,
                        "a_valid": ra.valid,
                        "b_valid": rb.valid,
                    }
                )
            )
    d = np.array(diffs)
    only = (len(set(a) - set(b)), len(set(b) - set(a)))
    validity = sum(a[k][0].valid != b[k][0].valid for k in both)
    text = (
        f"{len(both)} recordings in both, {only[0]} only in A, {only[1]} only in B; "
        f"{validity} valid in one and not the other"
    )
    if d.size:
        sd = f", sd {np.std(d, ddof=1):.2f}" if d.size > 1 else ""
        text += f"; B − A: mean {np.mean(d):+.2f}{sd}, largest {np.max(np.abs(d)):.2f} µm/m"
    print(text, file=result_stream(args))
    return 0


def _absolute(assessment, night):
    """The machine's anchored squareness ± its u, for the table; blank without an anchor."""
    from imu_square.monitor.verdict import machine_squareness
    from imu_square.units import URAD

    anchored = machine_squareness(assessment, night)
    if anchored is None:
        return ""
    value, u = anchored
    return f"{value / URAD:+7.1f}" + ("" if u is None else f" ± {u / URAD:5.1f}")


def _cell(value, width):
    """A signed value to 2 decimals, or a dash for an invalid run's missing one."""
    return f"{value:+{width}.2f}" if math.isfinite(value) else f"{'–':>{width}}"


def _urad(x):
    from imu_square.units import URAD

    return None if x is None else x / URAD
