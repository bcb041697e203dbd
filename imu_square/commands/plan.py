"""``imu-square plan``: the circle test that detects the smallest change in the time given."""

import json
import math
import sys
from dataclasses import replace
from pathlib import Path

from imu_square.commands._output import result_stream

HELP = "plan a circle test: radius, feed(s), cycles and dwell for a sensor and a machine"
# Nights simulated to check the monitor's design for a plan: the step's run lengths
# (2000 machines) do not depend on it, the false-alarm check's precision does (5 %).
_DESIGN_NIGHTS = 400_000


def register(sub):
    """Add the ``plan`` subcommand."""
    p = sub.add_parser(
        "plan",
        help=HELP,
        description="Choose the circle test that detects the smallest change of squareness in "
        "the time given, within the machine's and the sensor's limits; predict the standard "
        "deviation of one run and of the change against a baseline, the smallest change "
        "detected at the confidence asked, and the time on the machine. The prediction is the "
        "Cramér-Rao bound at the sensor's noise at the circle frequency (white, 1/f and ADC "
        "steps) over the estimator's measured efficiency, plus the servo amplitude leak as a "
        "bias bound. -o writes the program file.",
    )
    s = p.add_argument_group("sensor (or --sensor FILE; a flag overrides the file)")
    s.add_argument("--sensor", metavar="SENSOR.toml", help="sensor file, as simulate takes")
    s.add_argument(
        "--noise-density-ug",
        "--noise-ug",
        dest="noise_density_ug",
        type=float,
        help="white-noise density per axis [ug/sqrt(Hz)]",
    )
    s.add_argument("--flicker-corner-hz", type=float, help="1/f noise corner [Hz] (default 0)")
    s.add_argument("--range-g", type=float, help="full scale [g] (default 2.048)")
    s.add_argument("--sample-rate-hz", type=float, help="sample rate [Hz] (default 1000)")
    s.add_argument("--resolution-ug", type=float, help="ADC step [ug] (default 0)")
    m = p.add_argument_group(
        "machine (--max-feed-mm-min and --max-accel-m-s2, or --linuxcnc-ini, or both: the "
        "lower limits hold)"
    )
    m.add_argument("--max-feed-mm-min", type=float, help="fastest feed [mm/min]")
    m.add_argument(
        "--max-accel-m-s2",
        type=float,
        help="largest centripetal acceleration v^2/r for a stable circle [m/s^2]; a control may "
        "allow less on arcs than on its axes (LinuxCNC: sqrt(3)/2 of the axis limit)",
    )
    m.add_argument(
        "--linuxcnc-ini",
        metavar="FILE",
        help="the machine's LinuxCNC INI file: the fastest feed is the smaller X/Y MAX_VELOCITY "
        "(and [TRAJ] MAX_LINEAR_VELOCITY), the largest centripetal acceleration sqrt(3)/2 of the "
        "smaller X/Y MAX_ACCELERATION, which LinuxCNC keeps for an arc's normal acceleration",
    )
    m.add_argument(
        "--travel-mm",
        type=float,
        required=True,
        help="shortest of the X and Y travels free around the centre: the circle's diameter [mm]",
    )
    m.add_argument(
        "--servo-lags-ms",
        type=float,
        nargs=2,
        default=[2.0, 2.5],
        metavar=("TX", "TY"),
        help="axes' following lags, for the servo amplitude leak bound [ms] (default 2.0 2.5)",
    )
    m.add_argument(
        "--eps-c-deg",
        type=float,
        help="largest rotation of the sensor on the table [deg] (default: the sensor file's, "
        "else 2)",
    )
    m.add_argument(
        "--ramp-s", type=float, default=0.15, help="feed ramp at each block end [s] (0.15)"
    )
    g = p.add_argument_group("test")
    g.add_argument("--time-s", type=float, required=True, help="time available [s]")
    g.add_argument("--detect-um-m", type=float, help="change of squareness to detect [µm/m]")
    g.add_argument(
        "--confidence", type=float, default=0.95, help="confidence of the detection (0.95)"
    )
    g.add_argument(
        "--baseline-runs",
        type=int,
        default=1,
        metavar="N",
        help="runs averaged into the baseline the change is taken against (1)",
    )
    g.add_argument(
        "--stable-servo",
        action="store_true",
        help="the servo tuning and the sensor mount stay as for the baseline: the servo leak "
        "cancels in the change and is not added to the detectable change",
    )
    g.add_argument(
        "--separate-gravity",
        action="store_true",
        help="plan two feeds of one circle, for analyze --separate-gravity",
    )
    g.add_argument(
        "--config",
        metavar="MONITOR.toml",
        help="the machine's monitor file: its alarm design (false alarms, step) says how many "
        "nights the monitor takes to find the step",
    )
    g.add_argument(
        "--false-alarm-nights",
        type=float,
        metavar="N",
        help="the monitor's design: one false alarm in N valid nights (default: the monitor "
        "file's, else 730)",
    )
    p.add_argument("-o", "--output", metavar="PLAN.toml", help="write the program file")
    p.add_argument("--json", action="store_true", help="the plan as one JSON object on stdout")
    p.set_defaults(func=run)


def _sensor(args):
    from imu_square.errors import ConfigError
    from imu_square.program.planner import SensorSpec
    from imu_square.simulate import read_sensor
    from imu_square.units import UG, G

    eps = None
    if args.sensor:
        model = read_sensor(args.sensor)
        noise = model.noise_density_m_s2_rthz
        corner, full, rate = model.flicker_corner_hz, model.range_m_s2, model.sample_rate_hz
        step = model.resolution_m_s2
        eps = abs(model.eps_c_rad)
    else:
        noise, corner, full, rate, step = None, 0.0, 2.048 * G, 1000.0, 0.0
    if args.noise_density_ug is not None:
        noise = args.noise_density_ug * UG
    if noise is None or noise <= 0:
        raise ConfigError(
            "plan: the sensor's noise is needed: give --noise-density-ug (ug/sqrt(Hz)) or a "
            f"--sensor file with noise_density_ug_rthz > 0, got "
            f"{'none' if noise is None else f'{noise / UG:g} ug/sqrt(Hz)'}"
        )
    if args.flicker_corner_hz is not None:
        corner = args.flicker_corner_hz
    if args.range_g is not None:
        full = args.range_g * G
    if args.sample_rate_hz is not None:
        rate = args.sample_rate_hz
    if args.resolution_ug is not None:
        step = args.resolution_ug * UG
    return SensorSpec(noise, corner, full, rate, step), eps


def run(args):
    """Plan, print the plan, write the program file and the JSON."""
    from imu_square.errors import ProgramError
    from imu_square.program.planner import Goal, Limits, PlanInputError, plan_test
    from imu_square.units import MM, MS, URAD

    if args.output:  # refuse a bad path before planning, not after printing the plan
        from imu_square.io.output import check_output_path

        check_output_path(args.output, overwrite=True)
    sensor, sensor_eps = _sensor(args)
    eps_deg = args.eps_c_deg
    eps = math.radians(eps_deg) if eps_deg is not None else sensor_eps
    max_feed_m_s, max_accel_m_s2 = _machine_limits(args)
    limits = Limits(
        max_feed_m_s=max_feed_m_s,
        max_accel_m_s2=max_accel_m_s2,
        travel_m=args.travel_mm * MM,
        time_s=args.time_s,
        servo_lags_s=tuple(t * MS for t in args.servo_lags_ms),
        eps_c_rad=math.radians(2.0) if eps is None else eps,
        ramp_s=args.ramp_s,
    )
    goal = Goal(
        change_rad=None if args.detect_um_m is None else args.detect_um_m * URAD,
        confidence=args.confidence,
        baseline_runs=args.baseline_runs,
        separate_gravity=args.separate_gravity,
        stable_servo=args.stable_servo,
    )
    alarms = _alarm_settings(args)
    try:
        plan = plan_test(sensor, limits, goal)
    except PlanInputError as exc:
        raise _in_flag_units(exc, args) from None
    if plan.program.n_feeds == 1:
        plan = replace(plan, monitor=_monitor_detection(plan, alarms))
    print(plan.summary(), file=result_stream(args))
    if args.output:
        out = Path(args.output)
        try:
            out.write_text(plan.to_toml(), encoding="utf-8")
        except OSError as exc:
            raise ProgramError(f"{out}: cannot write the program file: {exc}") from None
        print(f"wrote {out}", file=sys.stderr)
    if args.json:
        print(json.dumps(plan.to_json_dict()), file=sys.stdout, flush=True)
    return 0 if plan.detects is not False else 1


def _alarm_settings(args):
    """The monitor's alarm settings: the monitor file's, a flag overriding its false alarms."""
    from imu_square.errors import ImuSquareError
    from imu_square.monitor.config import AlarmSettings, read_monitor

    settings = AlarmSettings() if args.config is None else read_monitor(args.config).alarms
    nights = args.false_alarm_nights
    if nights is not None:
        if not (math.isfinite(nights) and nights >= 10):
            raise ImuSquareError(f"--false-alarm-nights must be a number >= 10, got {nights!r}")
        settings = replace(settings, false_alarm_nights=nights)
    return settings


def _monitor_detection(plan, alarms):
    """Nights the monitor's charts, designed for this test, take to find the step."""
    from imu_square.monitor.stats.alarms import design_alarms
    from imu_square.program.planner import MonitorDetection

    step = plan.goal.change_rad or alarms.step_rad
    design = design_alarms(
        alarms.false_alarm_nights,
        plan.sigma_run_rad,
        step_rad=step,
        nu=plan.cycle_pairs - 1,
        baseline_sd_ratio=min(plan.goal.baseline_runs**-0.5, 2.0),
        mc_nights=_DESIGN_NIGHTS,
    )
    check = design.check
    return MonitorDetection(alarms.false_alarm_nights, step, check.step_median, check.step_p90)


def _machine_limits(args):
    """Fastest feed [m/s] and largest centripetal acceleration [m/s^2]: the flags', the
    LinuxCNC INI file's, or the lower of both."""
    from imu_square.errors import ConfigError
    from imu_square.units import MM_PER_MIN

    feed = None if args.max_feed_mm_min is None else args.max_feed_mm_min * MM_PER_MIN
    accel = args.max_accel_m_s2
    if args.linuxcnc_ini is None:
        missing = [
            f for f, v in (("--max-feed-mm-min", feed), ("--max-accel-m-s2", accel)) if v is None
        ]
        if missing:
            raise ConfigError(
                f"plan: the machine's limits are needed: give {' and '.join(missing)}, or the "
                "machine's LinuxCNC INI file with --linuxcnc-ini"
            )
        return feed, accel
    from imu_square.linuxcnc.ini import read_limits

    ini = read_limits(args.linuxcnc_ini)
    print(
        f"{args.linuxcnc_ini}: feed up to {ini.max_feed_m_s / MM_PER_MIN:g} mm/min; arcs at up "
        f"to {ini.arc_accel_m_s2:.4g} m/s² (sqrt(3)/2 of the axes' "
        f"{min(ini.max_accel_m_s2):g} m/s², as LinuxCNC plans an arc)",
        file=sys.stderr,
    )
    feed = ini.max_feed_m_s if feed is None else min(feed, ini.max_feed_m_s)
    accel = ini.arc_accel_m_s2 if accel is None else min(accel, ini.arc_accel_m_s2)
    return feed, accel


def _in_flag_units(exc, args):
    """The planner's refusal of a value, restated with the option and the unit it came in,
    or as the --sensor file's value when it came from there."""
    from imu_square.program.planner import PlanError
    from imu_square.units import MM, MM_PER_MIN, MS, UG, URAD, G
    from imu_square.validation import interval

    flag, unit, scale = {
        "noise_density_m_s2_rthz": ("--noise-density-ug", "ug/sqrt(Hz)", UG),
        "flicker_corner_hz": ("--flicker-corner-hz", "Hz", 1.0),
        "range_m_s2": ("--range-g", "g", G),
        "sample_rate_hz": ("--sample-rate-hz", "Hz", 1.0),
        "resolution_m_s2": ("--resolution-ug", "ug", UG),
        "max_feed_m_s": ("--max-feed-mm-min", "mm/min", MM_PER_MIN),
        "max_accel_m_s2": ("--max-accel-m-s2", "m/s^2", 1.0),
        "travel_m": ("--travel-mm", "mm", MM),
        "time_s": ("--time-s", "s", 1.0),
        "servo_lags_s": ("--servo-lags-ms", "ms", MS),
        "eps_c_rad": ("--eps-c-deg", "deg", math.radians(1.0)),
        "ramp_s": ("--ramp-s", "s", 1.0),
        "confidence": ("--confidence", "", 1.0),
        "change_rad": ("--detect-um-m", "µm/m", URAD),
        "baseline_runs": ("--baseline-runs", "", 1.0),
    }[exc.parameter]
    lo, hi = (b / scale for b in exc.bounds)
    lo_in, hi_in = exc.closed
    got = exc.value / scale
    # a sensor field the flag did not give came from the --sensor file
    dest = {"noise_density_m_s2_rthz": "noise_density_ug", "eps_c_rad": "eps_c_deg"}.get(
        exc.parameter, flag[2:].replace("-", "_")
    )
    file_fields = ("noise_density_m_s2_rthz", "flicker_corner_hz", "range_m_s2")
    file_fields += ("sample_rate_hz", "resolution_m_s2", "eps_c_rad")
    from_file = args.sensor and exc.parameter in file_fields and getattr(args, dest) is None
    where = " (here the --sensor file's value)" if from_file else ""
    unit = f" {unit}" if unit else ""
    return PlanError(
        f"{flag}{where} must be in {interval(lo, hi, not lo_in, not hi_in)}{unit}, "
        f"got {got:.6g}{unit}"
    )
