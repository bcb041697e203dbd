"""``imu-square nightly``: the nightly warm-up run, from the sensor to a result and a plot.

With ``--port`` it records a real board. Without it, it runs the whole chain
on built-in defaults: the simulator drives an emulated board on a
pseudo-terminal, the recorder streams it into MCAP through the real serial
path, and the pipeline analyses the file. The emulated run also writes the
simulator's truth, so the result can be checked against it.
"""

import json
import math
import secrets
import signal
import sys
import threading
import time
from pathlib import Path

EXIT_INCOMPLETE = 3


def register(sub):
    """Add the ``nightly`` subcommand."""
    p = sub.add_parser(
        "nightly",
        help="record and analyse one nightly run (emulated sensor unless --port is given)",
        description="Record one circle test and analyse it: writes RUN.mcap, RUN.result.json "
        "and RUN.png into --out. Without --port, an emulated board streams a simulated machine "
        "(built-in: the paper's test on a typical machine with the paper's sensor) through a "
        "pseudo-terminal, and RUN.truth.json holds what the simulator put in.",
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
        "--trigger",
        choices=("immediate", "motion", "marker"),
        help="when recording starts (default: the board's first block marker when emulated, "
        "motion with --port)",
    )
    p.add_argument("--machine-id", default="", help="machine the test runs on")
    p.add_argument("--out", default="imu-square-out", help="output folder (default: %(default)s)")
    p.set_defaults(func=run)


def _start_board(args, program, link):
    from acquisition.emulator import emulated_board
    from imu_square.simulate import data_path, read_machine, read_sensor

    machine = read_machine(args.machine or data_path("machine_typical.toml"))
    sensor = read_sensor(args.sensor or data_path("sensor_paper.toml"))
    seed = args.seed if args.seed is not None else secrets.randbits(31)
    board, truth = emulated_board(
        program, machine, sensor, seed=seed, link=str(link), speed=args.speed
    )
    thread = threading.Thread(target=board.run, name="emulated-board", daemon=True)
    thread.start()
    if not board.ready.wait(10.0):
        board.stop()
        from imu_square.errors import AcquisitionError

        raise AcquisitionError(f"the emulated board did not create its link {link} in 10 s")
    return board, thread, truth


def run(args):
    """Record, analyse, write the result and the plot; compare with the truth when emulated."""
    from acquisition.progress import ProgressPrinter, describe
    from acquisition.recorder import Recorder
    from imu_square.errors import AnalysisError
    from imu_square.io.mcap import read_mcap
    from imu_square.pipeline.plot import plot_results
    from imu_square.pipeline.squareness import analyze
    from imu_square.program import read_program
    from imu_square.simulate import data_path
    from imu_square.units import SQUARENESS_UNIT, URAD

    program = read_program(args.program or data_path("program_paper.toml"))
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    stem = out / f"nightly-{time.strftime('%Y%m%d-%H%M%S')}"
    mcap_path = stem.with_suffix(".mcap")

    board = thread = truth = None
    port = args.port
    if port is None:
        port = str(stem.with_suffix(".tty"))
        board, thread, truth = _start_board(args, program, port)
        print(
            f"emulated board on {port}: the circle test at x{args.speed:g} speed "
            f"({program.duration_s / args.speed:.0f} s)",
            file=sys.stderr,
        )
    trigger = args.trigger or ("marker" if board is not None else "motion")
    printer = ProgressPrinter(sys.stderr)
    recorder = Recorder(
        mcap_path,
        port,
        baudrate=args.baud,
        program=program,
        trigger=trigger,
        until_done=True,
        machine_id=args.machine_id or ("emulated" if board is not None else ""),
        progress=printer,
    )
    previous = {s: signal.signal(s, lambda *_: recorder.stop()) for s in _STOP_SIGNALS}
    try:
        status = recorder.run()
    finally:
        printer.close()
        for s, handler in previous.items():
            signal.signal(s, handler)
        if board is not None:
            board.stop()
            thread.join(timeout=15.0)
    print(f"{mcap_path}: {describe(status)}", file=sys.stderr)

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
    plot_results(results, stem.with_suffix(".png"), title=str(mcap_path))

    print(f"{mcap_path}: {result.summary()}", file=sys.stderr)
    if truth is not None:
        u = result.u_squareness_rad
        print(
            f"  truth (simulator): {expected / URAD:.1f} {SQUARENESS_UNIT}; error "
            f"{error / URAD:+.1f} {SQUARENESS_UNIT} = {error / u:+.1f} u"
            + ("" if math.isfinite(u) and abs(error) <= 3 * u else "  <-- outside 3u"),
            file=sys.stderr,
        )
    print(f"wrote {stem}.result.json and {stem}.png", file=sys.stderr)
    print(json.dumps(doc))
    return 0 if status.complete else EXIT_INCOMPLETE


_STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)
