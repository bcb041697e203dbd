"""``imu-square replay``: rebuild a machine's history from recorded runs, locally or on Dask."""

import json
import sys
import time

from imu_square.commands._monitor import add_config_argument
from imu_square.commands._output import result_stream
from imu_square.errors import ImuSquareError

HELP = "replay recorded runs into a machine's history (local processes or Dask)"


def register(sub):
    """Add the ``replay`` subcommand."""
    p = sub.add_parser(
        "replay",
        help=HELP,
        description="Analyse recordings (files, folders searched recursively, globs, or fsspec "
        "URLs) into the machine's history, in parallel, then judge the whole history again in "
        "recording-time order and say when the alarms would have fired. A recording already "
        "stored under the same analysis settings (same SHA-256) is skipped, so an interrupted "
        "replay picks up where it stopped. A bad file never stops the batch: it is stored as "
        "an invalid run with its reason, or counted as failed when it cannot be read. With "
        "--settings and --into it rebuilds another history under other analysis settings, to "
        "compare with 'imu-square history --compare'. Exit codes: 0 done (whatever the "
        "verdicts); 2 a user's mistake.",
    )
    add_config_argument(p)
    p.add_argument("paths", nargs="+", metavar="PATH", help="recordings, folders or globs")
    p.add_argument("--jobs", type=int, help="local worker processes (default: one per core)")
    p.add_argument(
        "--settings", metavar="SETTINGS.toml", help="analysis settings ([analysis] table)"
    )
    p.add_argument("--into", metavar="HISTORY", help="another history (file or postgresql://)")
    engine = p.add_mutually_exclusive_group()
    engine.add_argument("--scheduler", metavar="tcp://HOST:PORT", help="a running Dask scheduler")
    engine.add_argument(
        "--cluster", choices=("local",), help="a Dask LocalCluster of --jobs worker processes"
    )
    p.add_argument("--dry-run", action="store_true", help="list what would be done, do nothing")
    p.add_argument("--json", action="store_true", help="a JSON log on stdout instead of the bar")
    p.set_defaults(func=run)


def _settings(path):
    """The [analysis] table of a settings file."""
    from imu_square.errors import MonitorConfigError
    from imu_square.monitor.config import AnalysisSettings
    from imu_square.textfile import read_toml
    from imu_square.validation import read_tables

    layout = {"analysis": ("cutoff_hz", "order", "bootstrap")}
    t = read_tables(read_toml(path, MonitorConfigError), layout, path, MonitorConfigError)
    return AnalysisSettings.from_table(t["analysis"])


class _Progress:
    """A one-line bar on a terminal (files, rate, ETA), a JSON line per file otherwise."""

    def __init__(self, total, as_json):
        self.total, self.done, self.start = total, 0, time.monotonic()
        self.bar = not as_json and sys.stderr.isatty()  # progress, on stderr
        self.json = as_json

    def update(self, outcome):
        self.done += 1
        elapsed = time.monotonic() - self.start
        rate = self.done / elapsed if elapsed > 0 else 0.0
        eta = (self.total - self.done) / rate if rate > 0 else float("nan")
        if self.bar:
            width = 30
            fill = round(width * self.done / self.total)
            print(
                f"\r[{'#' * fill}{'.' * (width - fill)}] {self.done}/{self.total} files, "
                f"{rate:.1f}/s, ETA {eta:.0f} s ",
                end="",
                file=sys.stderr,
                flush=True,
            )
        if self.json:
            line = {
                "event": "file",
                "path": outcome.path,
                "status": outcome.status,
                "reason": outcome.reason,
                "seconds": round(outcome.seconds, 4),
                "done": self.done,
                "total": self.total,
                "rate_per_s": round(rate, 3),
            }
            print(json.dumps(line), flush=True)

    def close(self):
        if self.bar:
            print(file=sys.stderr)


def run(args):
    """Replay the files, store them as they come, judge the history, summarise."""
    from dataclasses import replace

    from imu_square.monitor.config import read_monitor
    from imu_square.monitor.replay import (
        ReplayJob,
        ReplaySummary,
        expand_paths,
        run_dask,
        run_local,
        store_outcome,
        stored_hashes,
    )

    config = read_monitor(args.config)
    if args.jobs is not None and args.jobs < 1:
        raise ImuSquareError(f"--jobs must be a whole number >= 1, got {args.jobs}")
    if args.settings:
        config = replace(config, analysis=_settings(args.settings))
    if args.into:
        config = replace(config, history=args.into)
    paths = expand_paths(args.paths)
    program = config.test_program()
    job = ReplayJob(config.machine_id, config.analysis, program, config.diagnostics)
    if args.dry_run:
        print(
            f"would replay {len(paths)} recording(s) of machine {config.machine_id} into "
            f"{config.history_location()} under analysis {config.analysis}, then judge it",
            file=sys.stderr,
        )
        for p in paths:
            print(p)
        return 0
    summary = ReplaySummary(files=len(paths))
    start = time.monotonic()
    with config.open_history() as history:
        known = stored_hashes(history, config)
        if args.scheduler or args.cluster:
            outcomes = run_dask(paths, job, known, scheduler=args.scheduler, workers=args.jobs or 2)
        else:
            outcomes = run_local(paths, job, known, jobs=args.jobs)
        progress = _Progress(len(paths), args.json)
        try:
            for outcome in outcomes:
                if outcome.row is not None and not store_outcome(history, outcome)[1]:
                    # a copy of a recording already stored (in this batch or before)
                    outcome = replace(outcome, status="skipped")
                summary.counts[outcome.status] += 1
                if outcome.status == "invalid":
                    summary.invalid.append((outcome.path, outcome.reason))
                elif outcome.status == "failed":
                    summary.failed.append((outcome.path, outcome.reason))
                progress.update(outcome)
        finally:
            progress.close()
        _rebaseline(read_monitor(args.config), config, history)
        _judge_all(config, history, summary)
    summary.seconds = time.monotonic() - start
    _print_summary(summary, config, result_stream(args))
    if args.json:
        print(json.dumps({"event": "summary", **summary.to_json_dict()}))
    return 0


def _rebaseline(original, config, history):
    """Re-set the baseline from the same recordings when the replayed runs have none.

    After a replay under other settings, or into another history, the machine's
    baseline names runs analysed otherwise: the replayed runs get a baseline
    of their own, from the same recordings analysed the new way.
    """
    from imu_square.monitor.baseline_setup import set_baseline
    from imu_square.monitor.history.encoding import settings_hash
    from imu_square.monitor.history.store import open_history
    from imu_square.monitor.night import analysis_settings

    machine = config.machine_id
    settings = settings_hash(analysis_settings(config))
    current = history.current_baseline(machine)
    if current is not None and current.settings_hash == settings:
        return
    if current is not None:
        source, hashes = current, {history.run(i).recording_sha256 for i in current.run_ids}
    elif original.history_location() != config.history_location():
        with open_history(original.history_location()) as old:
            source = old.current_baseline(machine)
            if source is None:
                return
            hashes = {old.run(i).recording_sha256 for i in source.run_ids}
    else:
        return
    runs = [
        r
        for r in history.runs(machine, settings_hash=settings, valid_only=True)
        if r.recording_sha256 in hashes
    ]
    try:
        set_baseline(config, history, runs, note=f"replayed from baseline {source.id}")
        print(f"baseline set again from {len(runs)} replayed runs", file=sys.stderr)
    except ImuSquareError as exc:
        print(f"no baseline for the replayed runs: {exc}", file=sys.stderr)


def _judge_all(config, history, summary):
    """Judge every run in recording-time order and store the verdicts."""
    from imu_square.monitor.night import judge_history, store_verdict
    from imu_square.monitor.verdict import iso

    assessment = judge_history(config, history)
    base = assessment.baseline_row
    start = -1 if base is None else (base.first_run_at_ns or 0)
    with history.transaction():
        for night in assessment.nights:
            r = night.run
            recorded = r.recorded_at_ns
            if (
                base is not None
                and r.id not in base.run_ids
                and recorded is not None
                and (recorded < start)
            ):
                continue  # judged against the baseline of its time, kept as it was
            store_verdict(history, base, night)
    summary.alarm_nights = [
        iso(n.run.recorded_at_ns)
        for n in assessment.nights
        if n.chart is not None and n.chart.state == "alarm"
    ]
    summary.state = assessment.latest.state if assessment.latest else "no_baseline"


def _print_summary(summary, config, out):
    c = summary.counts
    print(
        f"replayed {summary.files} recording(s) of {config.machine_id} in {summary.seconds:.1f} s: "
        f"{c['analysed']} analysed, {c['skipped']} skipped (already stored), {c['invalid']} "
        f"invalid, {c['failed']} failed",
        file=out,
    )
    for path, reason in summary.invalid + summary.failed:
        print(f"  {path}: {reason}", file=out)
    if summary.alarm_nights:
        print(f"the alarms would have fired on: {', '.join(summary.alarm_nights)}", file=out)
    else:
        print("the alarms would not have fired", file=out)
