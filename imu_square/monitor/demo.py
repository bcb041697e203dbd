"""A demonstration machine: a monitor file and six weeks of nights from the simulator.

``imu-square nightly --demo DIR`` (the README's first command) shows the
monitor at work on a machine nobody has to own. :func:`prepare_demo` writes
into DIR a monitor file on the emulated board, the program (r = 25 mm at
9000 mm/min: 0.9 m/s², about 17 µm/m a night with the paper's sensor), the
emulated machine and a sensor with the paper's noise, a temperature channel
and a thermal drift; then, if the history is empty, it simulates and judges
the machine's past nights, generated afresh (never committed):

- eight warm nights, from which the baseline is set;
- normal nights, some just after the sensor was switched on: its
  non-orthogonality still drifts by hundreds of µm/m as it warms, so such a
  night is not judged (at this noise a few cold nights cannot teach the
  drift's slope with the temperature well enough to correct it);
- a crash that moves the squareness by +45 µm/m: the alarm fires and stands;
- a repair five nights later that brings it back within 2 µm/m, after which
  the maintenance team sets a new baseline from five nights;
- one night whose recording was cut short, stored as invalid with its reason;
- all along, the X axis's backlash wears from 3 µm by 1 µm a week: every
  night's diagnostics (:mod:`imu_square.monitor.diagnostics`) trend it, and
  its own alarm (2 µm, in the monitor file's ``[diagnostics.alarms]``) fires
  while the squareness is ``ok``.

Tonight is then recorded through the emulated board like any night.
"""

import os
import shutil
import tomllib
from datetime import UTC, datetime, timedelta
from pathlib import Path

import numpy as np

from imu_square.errors import ImuSquareError
from imu_square.monitor.config import read_monitor

MACHINE_ID = "demo-mill"
ALPHA_UM_PER_M = 30.0
CRASH_UM_PER_M = 45.0
REPAIRED_UM_PER_M = 31.5
NIGHTS = 42
BASELINE_NIGHTS = 8
CRASH_NIGHT = 23
REPAIR_NIGHT = 28
NEW_BASELINE_NIGHTS = range(29, 34)
CUT_NIGHT = 36
COLD_NIGHTS = (11, 15, 19, 35, 38, 40)
WARM_UPTIME_S = 5 * 3600.0
COLD_UPTIME_S = 30.0
BACKLASH_X_UM = 3.0
BACKLASH_WEAR_UM_PER_WEEK = 1.0

_PROGRAM = """\
# The demo's warm-up cycle: r = 25 mm at 9000 mm/min (omega = 6 rad/s, 0.9 m/s^2).
[program]
plane = "XY"
radius_mm = 25.0
feed_mm_per_min = 9000.0
cycles_per_direction = 20
overshoot_deg = 180.0
start_angle_deg = 0.0
order = ["ccw", "cw"]
dwell_s = 2.0
runs = 1
"""

_SENSOR = """\
# The paper's sensor (7 ug/sqrt(Hz), turned 2.1 deg), with a temperature channel and a
# warm-up drift of its non-orthogonality: 600 urad at power-on, gone in about 15 min.
[sensor]
model = "demo"
sample_rate_hz = 1000.0
noise_density_ug_rthz = 7.0
range_g = 2.048
resolution_ug = 3.9
eps_c_deg = 2.1
beta_urad = 40.0
temperature_c = 22.0

[sensor_thermal_drift]
beta_0_urad = 640.0
tau_warm_s = 300.0
temperature_rise_c = 8.0
"""

_MONITOR = """\
# The demonstration machine of 'imu-square nightly --demo': an emulated board.
[monitor]
machine_id = "{machine_id}"
history = "history.db"
data_dir = "data"

[sensor]
port = "emulated"
trigger = "marker"

[emulated]
machine = "machine.toml"
sensor = "sensor.toml"
speed = 20.0

[program]
file = "program.toml"
motion = "{motion}"

[alarms]
false_alarm_nights = 730
step_um_per_m = 30.0

[diagnostics.alarms]
backlash_x_um = 2.0

[alerts.json_file]
path = "data/latest-alert.json"
mode = "latest"
states = ["ok", "warning", "alarm", "invalid", "stale_baseline", "no_baseline"]

[metrics]
textfile = "data/{machine_id}.prom"
"""


def _machine_text(alpha_um_per_m, night):
    from imu_square.simulate import data_path

    text = Path(data_path("machine_typical.toml")).read_text(encoding="utf-8")
    text = text.replace('name = "typical"', f'name = "{MACHINE_ID}"')
    backlash = BACKLASH_X_UM + BACKLASH_WEAR_UM_PER_WEEK * night / 7
    text = text.replace("[backlash]\nx_um = 3.0", f"[backlash]\nx_um = {backlash:.3f}")
    return text.replace(
        "machine_squareness_um_per_m = 15.0", f"machine_squareness_um_per_m = {alpha_um_per_m}"
    )


def _alpha(night):
    if night < CRASH_NIGHT:
        return ALPHA_UM_PER_M
    if night < REPAIR_NIGHT:
        return ALPHA_UM_PER_M + CRASH_UM_PER_M
    return REPAIRED_UM_PER_M


def write_demo_files(folder, motion="trajectory"):
    """Write the demo's monitor, program, machine and sensor files (kept if present).

    Parameters
    ----------
    folder : Path
        The demo's folder.
    motion : str
        The program's commanded motion the monitor file names
        (:data:`~imu_square.simulate.sources.MOTION_SOURCES`).

    Returns
    -------
    Path
        The monitor file.
    """
    folder.mkdir(parents=True, exist_ok=True)
    files = {
        "monitor.toml": _MONITOR.format(machine_id=MACHINE_ID, motion=motion),
        "program.toml": _PROGRAM,
        "sensor.toml": _SENSOR,
        "machine.toml": _machine_text(REPAIRED_UM_PER_M, NIGHTS),
    }
    for name, text in files.items():
        if not (folder / name).exists():
            (folder / name).write_text(text, encoding="utf-8")
    return folder / "monitor.toml"


def seed_history(config, history, now=None, progress=None):
    """Simulate and judge the demo machine's past nights into its history.

    Every night runs the monitor file's commanded motion (``[program] motion``),
    which its diagnostics fit takes as its model too.

    Parameters
    ----------
    config : MonitorConfig
        The demo's monitor file.
    history : History
        Its open history, empty for this machine.
    now : datetime, optional
        Tonight (UTC); the past nights end yesterday at 02:30.
    progress : callable, optional
        Called with a line of text now and then.
    """
    from imu_square.io.mcap import write_mcap
    from imu_square.monitor.baseline_setup import set_baseline
    from imu_square.monitor.night import judge_recording, store_run
    from imu_square.monitor.replay import ReplayJob, run_local
    from imu_square.simulate import read_sensor, simulate_run
    from imu_square.simulate.machine import machine_from_mapping
    from imu_square.simulate.sources import commanded_motion

    say = progress or (lambda text: None)
    program = config.test_program()
    motion = commanded_motion(program, config.motion, say)
    sensor = read_sensor(config.emulated.sensor)
    folder = config.output_dir() / "seed"
    folder.mkdir(parents=True, exist_ok=True)
    now = now or datetime.now(UTC)
    first = (now - timedelta(days=NIGHTS)).replace(hour=2, minute=30, second=0, microsecond=0)
    rng = np.random.default_rng(20261124)
    say(f"seeding {NIGHTS} past nights of {MACHINE_ID} from the simulator into {history.location}")
    paths, whens = [], []
    for night in range(NIGHTS):
        machine = machine_from_mapping(tomllib.loads(_machine_text(_alpha(night), night)), "demo")
        when = first + timedelta(days=night, minutes=float(rng.uniform(0, 20)))
        uptime = COLD_UPTIME_S if night in COLD_NIGHTS else WARM_UPTIME_S
        recording, _ = simulate_run(
            program,
            machine,
            sensor,
            seed=int(rng.integers(2**31)),
            t0_ns=int(when.timestamp() * 1e9),
            uptime_s=uptime,
            motion=motion,
        )
        if night == CUT_NIGHT:  # the recording ends in the first block
            keep = recording.n_samples // 4
            recording.accel, recording.time_ns = recording.accel[:keep], recording.time_ns[:keep]
            recording.seq = recording.seq[:keep]
            if recording.temperature_c is not None:
                recording.temperature_c = recording.temperature_c[:keep]
            recording.events = [e for e in recording.events if e.time_ns <= recording.time_ns[-1]]
        path = folder / f"{MACHINE_ID}-{when:%Y%m%d-%H%M}.mcap"
        write_mcap(recording, path)
        paths.append(str(path))
        whens.append(when)
    # every night's analysis and diagnostic fit over the cores (a replay's per-file work),
    # then the nights judged in order as each came
    say(f"analysing them and fitting their diagnostics on {os.cpu_count() or 1} core(s)")
    job = ReplayJob(config.machine_id, config.analysis, program, config.diagnostics)
    made = {}
    for outcome in run_local(paths, job):
        if outcome.row is None:
            raise ImuSquareError(f"{outcome.path}: {outcome.reason}")
        made[outcome.path] = (outcome.row, None, outcome.diagnostics)
    baseline_runs, repaired = [], []
    for night, path in enumerate(paths):
        if night < BASELINE_NIGHTS:
            run_id, _ = store_run(history, made[path][0], made[path][2])
            baseline_runs.append(history.run(run_id))
            if night == BASELINE_NIGHTS - 1:
                say("setting the baseline from the first 8 nights and designing its alarms")
                set_baseline(config, history, baseline_runs, note="demo: eight warm nights")
            continue
        outcome = judge_recording(config, history, path, program, made=made[path])
        if outcome.state != "ok":
            say(f"  {whens[night]:%Y-%m-%d}: {outcome.verdict}")
        if night in NEW_BASELINE_NIGHTS:
            repaired.append(history.run(outcome.run_id))
            if night == NEW_BASELINE_NIGHTS[-1]:
                say("after the repair: a new baseline from five nights")
                set_baseline(config, history, repaired, note="demo: after the repair")


def prepare_demo(folder, progress=None, now=None, motion=None):
    """The demo's monitor file, with its history seeded when empty.

    Parameters
    ----------
    folder : str or Path
        Where the demo lives.
    progress : callable, optional
        Called with a line of text now and then.
    now : datetime, optional
        Tonight (UTC).
    motion : str, optional
        The commanded motion (:data:`~imu_square.simulate.sources.MOTION_SOURCES`)
        the past nights ran, tonight's too, and the diagnostics' model; None for
        the monitor file's (our own trajectory in a new one). A shop's history
        comes from one controller, and the sensor's ``eps_c`` reads differently
        on another one's ramps (by 0.05 deg on LinuxCNC's), which the monitor
        takes for a remounted sensor.

    Returns
    -------
    MonitorConfig
    """

    folder = Path(folder)
    config = read_monitor(write_demo_files(folder, motion or "trajectory"))
    if motion is not None:
        config = config.with_motion(motion)
    with config.open_history() as history:
        if not history.runs(config.machine_id):
            shutil.rmtree(config.output_dir() / "seed", ignore_errors=True)
            seed_history(config, history, now=now, progress=progress)
    return config
