"""``imu-square nightly``: the nightly warm-up run, from the sensor to a verdict.

With ``--config MONITOR.toml`` it is the monitor's nightly job: record (or take
``--recording``), analyse, store in the history, judge against the machine's
baseline, send the alerts, write the metrics, the trend chart and the report,
and end with one line and the state's exit code. ``--demo DIR`` does the same
on a demonstration machine whose history it seeds from the simulator.

Without ``--config`` it records and analyses one run, as before the monitor:
with ``--port`` from a real board; without it, the simulator drives an
emulated board on a pseudo-terminal, the recorder streams it into MCAP through
the real serial path, and the run's truth is written beside it.
"""

import json
import math
import secrets
import sys
import threading
import time
from pathlib import Path

from imu_square.commands._output import result_stream
from imu_square.simulate.sources import MOTION_SOURCES

HELP = "record and analyse one nightly run (emulated sensor unless --port is given)"


def register(sub):
    """Add the ``nightly`` subcommand."""
    p = sub.add_parser(
        "nightly",
        help=HELP,
        description="Record one circle test and analyse it: writes RUN.mcap, RUN.result.json "
        "and RUN.png into --out. Without --port, an emulated board streams a simulated machine "
        "(built-in: the paper's test on a typical machine with the paper's sensor) through a "
        "pseudo-terminal, and RUN.truth.json holds what the simulator put in. Exit codes: 0 a "
        "complete run, analysed; 3 the recording is incomplete (see 'imu-square record'), "
        "analysed if it could be; 2 a bad option, nothing recorded, or the run cannot be "
        "analysed; 4 writing the recording failed part-way (disk full).",
    )
    p.add_argument("--port", help="serial port of a real board (default: an emulated board)")
    p.add_argument("--baud", type=int, default=921600, help="line speed (default 921600)")
    p.add_argument("--program", help="program TOML (default: the paper's test)")
    p.add_argument("--machine", help="emulated machine TOML (default: built-in typical machine)")
    p.add_argument("--sensor", help="emulated sensor TOML (default: the paper's sensor)")
    p.add_argument(
        "--speed",
        type=float,
        default=20.0,
        help="emulated board: times faster than real time (default: %(default)s)",
    )
    p.add_argument("--seed", type=int, help="emulated board: seed of the noise")
    p.add_argument(
        "--motion",
        choices=MOTION_SOURCES,
        help="the commanded motion, our own trajectory or LinuxCNC's planner running the "
        "program in real time (or its cached run): the emulated board runs it, and with "
        "--config or --demo the night's diagnostics fit takes it as its model (default: the "
        "monitor file's [program] motion, else trajectory)",
    )
    p.add_argument(
        "--trigger",
        choices=("immediate", "motion", "marker"),
        help="when recording starts (default: the board's first block marker when emulated, "
        "motion with --port)",
    )
    p.add_argument("--machine-id", default="", help="machine the test runs on")
    p.add_argument(
        "--out",
        help="output folder (default: imu-square-out; with --config the "
        "monitor file's data folder)",
    )
    p.add_argument(
        "--json",
        action="store_true",
        help="the result as JSON on stdout (with --config the night's record: state, "
        "change_urad, ...)",
    )
    monitor = p.add_argument_group(
        "the monitor",
        "exit codes with --config or --demo: 0 ok, 10 warning, 11 alarm, 12 invalid run, "
        "13 stale baseline (the sensor was remounted), 14 no baseline yet; 2 a user's mistake "
        "(nothing stored), 4 writing the recording failed part-way, 130 interrupted",
    )
    monitor.add_argument("--config", metavar="MONITOR.toml", help="the machine's monitor file")
    monitor.add_argument(
        "--recording", metavar="RUN.mcap", help="judge this recording instead of recording one"
    )
    monitor.add_argument(
        "--check", action="store_true", help="check the monitor file and the history, then stop"
    )
    monitor.add_argument(
        "--demo",
        metavar="DIR",
        help="a demonstration machine in DIR: its monitor file and a history seeded from the "
        "simulator (a baseline, weeks of nights, drift and one repaired degradation), then "
        "tonight through the emulated board",
    )
    p.set_defaults(func=run)


def _start_board(program, machine_file, sensor_file, seed, speed, link, uptime_s=0.0, motion=None):
    from acquisition.emulator import emulated_board
    from imu_square.simulate import data_path, read_machine, read_sensor

    machine = read_machine(machine_file or data_path("machine_typical.toml"))
    sensor = read_sensor(sensor_file or data_path("sensor_paper.toml"))
    seed = seed if seed is not None else secrets.randbits(31)
    board, truth = emulated_board(
        program,
        machine,
        sensor,
        seed=seed,
        link=str(link),
        speed=speed,
        uptime_s=uptime_s,
        motion=motion,
    )
    thread = threading.Thread(target=board.run, name="emulated-board", daemon=True)
    thread.start()
    if not board.ready.wait(10.0):
        board.stop()
        from imu_square.errors import AcquisitionError

        raise AcquisitionError(f"the emulated board did not create its link {link} in 10 s")
    return board, thread, truth


def _record(
    stem,
    program,
    *,
    port,
    emulated,
    baud,
    trigger,
    machine_id,
    quiet,
    header_timeout_s=5.0,
    motion=None,
):
    """Record one run into ``stem.mcap``; an emulated board when ``port`` is None.

    ``emulated`` is ``(machine_file, sensor_file, seed, speed[, uptime_s])``, and
    ``motion`` the emulated machine's commanded motion (None: our own trajectory). Returns the
    recording's path, the recorder's status, its exit code and the emulated
    run's truth (None for a real board).
    """
    from acquisition.commands._session import report, run_recorder
    from acquisition.recorder import Recorder

    mcap_path = stem.with_suffix(".mcap")
    board = thread = truth = None
    if port is None:
        port = str(stem.with_suffix(".tty"))
        board, thread, truth = _start_board(
            program, *emulated[:4], port, *emulated[4:], motion=motion
        )
        print(
            f"emulated board on {port}: the circle test at x{emulated[3]:g} speed "
            f"({program.duration_s / emulated[3]:.0f} s)",
            file=sys.stderr,
        )
    recorder = Recorder(
        mcap_path,
        port,
        baudrate=baud,
        program=program,
        trigger=trigger or ("marker" if board is not None else "motion"),
        until_done=True,
        machine_id=machine_id or ("emulated" if board is not None else ""),
        header_timeout_s=header_timeout_s,
    )
    try:
        status = run_recorder(recorder, quiet=quiet)
    finally:
        if board is not None:
            board.stop()
            thread.join(timeout=15.0)
    return mcap_path, status, report(mcap_path, status), truth


def run(args):
    """The monitor's night with --config or --demo; otherwise record and analyse one run."""
    if args.demo:
        return run_demo(args)
    if args.config:
        return run_monitor(args)
    for flag in ("recording", "check"):
        if getattr(args, flag):
            from imu_square.errors import ImuSquareError

            raise ImuSquareError(f"--{flag} goes with --config (the monitor's nightly job)")
    return run_single(args)


def run_single(args):
    """Record, analyse, write the result and the plot; compare with the truth when emulated."""
    from imu_square.errors import AnalysisError, ImuSquareError
    from imu_square.io.mcap import read_mcap
    from imu_square.pipeline.run_figure import plot_results
    from imu_square.pipeline.squareness import analyze
    from imu_square.program import read_program
    from imu_square.simulate import data_path
    from imu_square.units import SQUARENESS_UNIT, URAD

    program = read_program(args.program or data_path("program_paper.toml"))
    if args.motion not in (None, "trajectory") and args.port is not None:
        raise ImuSquareError(
            f"--motion {args.motion} drives the emulated board: it cannot go with a real board "
            "(--port) but with a monitor file, whose nightly diagnostics it models"
        )
    motion = _motion(args.motion or "trajectory", program)
    out = Path(args.out or "imu-square-out")
    out.mkdir(parents=True, exist_ok=True)
    stem = out / f"nightly-{time.strftime('%Y%m%d-%H%M%S')}"
    mcap_path, status, code, truth = _record(
        stem,
        program,
        port=args.port,
        emulated=(args.machine, args.sensor, args.seed, args.speed),
        baud=args.baud,
        trigger=args.trigger,
        machine_id=args.machine_id,
        quiet=args.quiet,
        motion=motion,
    )
    recording = read_mcap(mcap_path)
    if program.n_feeds > 1:
        # several feeds of one circle: the squareness freed of gravity coupling
        from imu_square.pipeline.gravity import analyze_feeds, separate_gravity

        feeds = analyze_feeds([(str(mcap_path), recording)])  # its errors name the file
        result = separate_gravity(feeds)
        results = [f.result for f in feeds]
        expected_key = "expected_squareness_gravity_free_rad"
    else:
        try:
            result = analyze(recording)
        except AnalysisError as exc:  # the pipeline names no file: say which
            raise AnalysisError(f"{mcap_path}: {exc}") from None
        results = [result]
        expected_key = "expected_squareness_rad"
    doc = result.to_json_dict()
    doc["recording"] = str(mcap_path)
    doc["recording_complete"] = status.complete
    if truth is not None:
        stem.with_suffix(".truth.json").write_text(json.dumps(truth, indent=1) + "\n")
        # What theta_y - theta_x should read on this circle: local squareness,
        # sensor non-orthogonality and any gravity-coupling phase (none when the
        # feeds separate it), seen through the sensor's rotation (simulate prints
        # the same key).
        expected = truth[expected_key]
        error = result.squareness_rad - expected
        doc["expected_squareness_urad"] = expected / URAD
        doc["truth_expected_urad"] = expected / URAD  # old name, kept for one release
        doc["error_urad"] = error / URAD
    stem.with_suffix(".result.json").write_text(json.dumps(doc, indent=1) + "\n")
    plot_results(results, stem.with_suffix(".png"), title=mcap_path.name)

    shown = result_stream(args)
    print(f"{mcap_path}: {result.summary()}", file=shown)
    if truth is not None:
        u = result.u_squareness_rad
        print(
            f"  truth (simulator): {expected / URAD:.1f} {SQUARENESS_UNIT}; error "
            f"{error / URAD:+.1f} {SQUARENESS_UNIT} = {error / u:+.1f} u"
            + ("" if math.isfinite(u) and abs(error) <= 3 * u else "  <-- outside 3u"),
            file=shown,
        )
    print(f"wrote {stem}.result.json and {stem}.png", file=sys.stderr)
    if args.json:
        print(json.dumps(doc))
    return code


_SINGLE_RUN_FLAGS = ("port", "program", "machine", "sensor", "seed", "trigger", "machine_id")


def run_monitor(args, config=None):
    """The monitor's night: record (or take a recording), judge, report, exit with the state."""
    from imu_square.errors import HistoryError, ImuSquareError
    from imu_square.monitor.config import read_monitor
    from imu_square.monitor.night import judge_recording, store_kept_nights
    from imu_square.monitor.publish import write_night_outputs
    from imu_square.monitor.schedule import EXIT_CODES

    given = [f"--{f.replace('_', '-')}" for f in _SINGLE_RUN_FLAGS if getattr(args, f)]
    if given:
        raise ImuSquareError(
            f"{', '.join(given)} cannot go with --config: the monitor file says where the "
            f"sensor is and which program runs"
        )
    config = config or read_monitor(args.config)
    if args.motion:
        config = config.with_motion(args.motion)
    program = config.test_program()
    out = Path(args.out) if args.out else config.output_dir()
    # Before the machine runs or anything is stored; a check makes nothing.
    _check_night(config, out, not args.recording, make=not args.check)
    if args.recording and not Path(args.recording).is_file():
        raise ImuSquareError(f"{args.recording}: no such recording")
    # a real board's or a recording's motion is the diagnostics fit's alone
    emulated = config.sensor.emulated and not args.recording and not args.check
    motion = _motion(config.motion, program) if emulated else None
    if args.check and _not_made_yet(config.history_location()):
        print(
            f"{config.path}: machine {config.machine_id}, history "
            f"{config.history_location()} (not made yet: the first night makes it), program "
            f"{config.program or 'the paper test'}, sensor {config.sensor.port}, outputs in "
            f"{out}: ok",
            file=sys.stderr,
        )
        return 0
    if args.check:
        with config.open_history() as history:
            print(
                f"{config.path}: machine {config.machine_id}, history {history.location} "
                f"({len(history.runs(config.machine_id))} runs), program "
                f"{config.program or 'the paper test'}, sensor {config.sensor.port}, outputs "
                f"in {out}: ok",
                file=sys.stderr,
            )
        return 0
    code = 0
    if args.recording:
        path = Path(args.recording).resolve()
    else:  # recorded first: a history that is busy or down then loses nothing
        stem = out / f"{config.machine_id}-{time.strftime('%Y%m%d-%H%M%S')}"
        emu = config.emulated
        path, _, code, _ = _record(
            stem,
            program,
            port=None if config.sensor.emulated else config.sensor.port,
            emulated=(emu.machine, emu.sensor, None, emu.speed, emu.uptime_s),
            baud=config.sensor.baud,
            trigger=config.sensor.trigger,
            machine_id=config.machine_id,
            quiet=args.quiet,
            header_timeout_s=config.sensor.header_timeout_s,
            motion=motion,
        )
    try:
        with config.open_history() as history:
            for late in store_kept_nights(config, history, out, program):
                print(
                    f"{late.record['recording']}: stored late: {late.verdict}",
                    file=result_stream(args),
                )
            outcome = judge_recording(config, history, path, program, alert=True)
            files = write_night_outputs(config, history, outcome, out)
    except HistoryError as exc:
        return _kept_for_later(config, args, out, path, exc)
    for name, value in (
        ("trend chart", files.trend_png),
        ("diagnostics chart", files.diagnostics_png),
        ("report", files.report_html),
    ):
        if value is not None:
            print(f"wrote the {name} {value}", file=sys.stderr)
    if files.alerts is not None:
        for o in files.alerts.outcomes:
            if o.status not in ("sent", "skipped"):
                print(f"alert to {o.sink}: {o.status} ({o.error})", file=sys.stderr)
    if not outcome.inserted:
        print(
            f"{path}: already in the history (run {outcome.run_id}), judged again", file=sys.stderr
        )
    print(f"{config.machine_id}: {outcome.verdict}", file=result_stream(args))
    if args.json:
        print(json.dumps(outcome.record))
    # a failed write outranks the verdict: the night must be looked at
    return code if code == 4 else EXIT_CODES[outcome.record["machine_state"]]


def _kept_for_later(config, args, out, path, exc):
    """The history could not take tonight: keep the recording for the next run, say how to
    store it now, and tell the sinks directly (there is no outbox to keep the alert in)."""
    from imu_square.cli import EXIT_USER_ERROR
    from imu_square.monitor.alerts.send import send_without_history
    from imu_square.monitor.history.encoding import first_line
    from imu_square.monitor.night import keep_for_later

    keep_for_later(out, path)
    line = (
        f"the night could not be stored yet ({first_line(exc)}): its recording {path} is kept; "
        f"the next night stores it first, or now: imu-square nightly --config {config.path} "
        f"--recording {path}"
    )
    record = {"machine_id": config.machine_id, "state": "invalid", "recording": str(path)}
    report = send_without_history(
        config.alerts,
        {**record, "verdict": line},
        machine_id=config.machine_id,
        state="invalid",
        verdict=line,
    )
    for o in report.outcomes:
        if o.status != "sent":
            print(f"alert to {o.sink}: {o.status} ({o.error})", file=sys.stderr)
    print(f"{config.machine_id}: {line}", file=result_stream(args))
    if args.json:
        print(json.dumps({**record, "machine_state": "invalid", "verdict": line}))
    return EXIT_USER_ERROR


def _not_made_yet(location):
    """Whether a SQLite history does not exist yet; its folder must take it (checked, not made)."""
    from imu_square.io.output import check_output_path
    from imu_square.monitor.history.store import is_postgres_url

    if is_postgres_url(location) or Path(location).exists():
        return False
    check_output_path(location)
    return True


def _motion(source, program):
    """The emulated machine's commanded motion (None: our own trajectory)."""
    from imu_square.simulate.sources import commanded_motion

    return commanded_motion(program, source, lambda text: print(text, file=sys.stderr))


def _check_night(config, out, recording, make=True):
    """Everything the night will need, checked before it starts: one line if not."""
    from imu_square.errors import ConfigError
    from imu_square.monitor.publish import ensure_folder
    from imu_square.simulate import read_machine, read_sensor

    ensure_folder(out, "data", make)
    if config.metrics is not None and config.metrics.textfile is not None:
        ensure_folder(Path(config.metrics.textfile).parent, "metrics", make)
    for sink in config.alerts.sinks:
        path = getattr(sink, "path", None)
        if path is not None:
            ensure_folder(Path(path).parent, f"{sink.name} alert", make)
    if config.sensor.emulated:
        for field, path, read in (
            ("machine", config.emulated.machine, read_machine),
            ("sensor", config.emulated.sensor, read_sensor),
        ):
            if path is not None:
                try:
                    read(path)
                except ConfigError as exc:
                    raise ConfigError(f"{config.path}: [emulated] {field}: {exc}") from None
    elif recording and "://" not in config.sensor.port and not Path(config.sensor.port).exists():
        raise ConfigError(
            f"{config.path}: [sensor] port {config.sensor.port!r} does not exist (is the board "
            f"plugged in? a stable name is under /dev/serial/by-id/)"
        )


def run_demo(args):
    """Seed a demonstration machine's history from the simulator, then run its night."""
    from imu_square.errors import ImuSquareError
    from imu_square.monitor.demo import prepare_demo

    if args.config or args.recording:
        raise ImuSquareError("--demo makes its own monitor file and recording")
    config = prepare_demo(
        Path(args.demo), progress=lambda text: print(text, file=sys.stderr), motion=args.motion
    )
    return run_monitor(args, config)
