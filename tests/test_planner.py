"""The test planner: its noise model, its choices within the limits, its CLI, its prediction."""

import json
import math
import re
from dataclasses import replace

import numpy as np
import pytest
from scipy import stats

from imu_square.cli import main
from imu_square.errors import ImuSquareError
from imu_square.io.recording import SensorInfo
from imu_square.pipeline.squareness import AnalysisOptions, analyze
from imu_square.program import TestProgram, read_program
from imu_square.program.planner import (
    ESTIMATOR_EFFICIENCY,
    MIN_CYCLES,
    Goal,
    Limits,
    PlanError,
    PlanInputError,
    SensorSpec,
    plan_test,
    predict,
    servo_leak,
    sigma_run,
)
from imu_square.simulate import MachineModel, SensorModel, simulate_run
from imu_square.simulate.sensor_noise import sensor_noise
from imu_square.units import MM, MM_PER_MIN, UG, URAD, G

PAPER = TestProgram()  # r = 100 mm, 6000 mm/min, 15 cycles each way
D7 = 7.0 * UG


def test_white_noise_gives_the_cramer_rao_bound_over_the_efficiency():
    # docs/model.md: sqrt(2) d / (A sqrt(T)), T = 2 x 15 cycles of 2 pi s: about 70 urad
    sensor = SensorSpec(D7)
    bound = math.sqrt(2) * D7 / (0.1 * math.sqrt(30 * 2 * math.pi))
    assert sigma_run(PAPER, sensor, 1.0) == pytest.approx(bound, rel=1e-12)
    assert bound == pytest.approx(70e-6, rel=0.02)
    assert sigma_run(PAPER, sensor) == pytest.approx(bound / math.sqrt(ESTIMATOR_EFFICIENCY))


def test_flicker_noise_counts_at_the_circle_frequency():
    # the paper's circle turns at 1/(2 pi) = 0.159 Hz: under a 0.5 Hz corner the PSD
    # there is d^2 (1 + 0.5 / 0.159) = 4.14 d^2, the bound 2.03 x the white one
    white = sigma_run(PAPER, SensorSpec(D7), 1.0)
    pink = sigma_run(PAPER, SensorSpec(D7, flicker_corner_hz=0.5), 1.0)
    assert pink / white == pytest.approx(math.sqrt(1 + 0.5 * 2 * math.pi), rel=1e-12)
    # ADC steps of q add q^2 / (6 fs) to the PSD
    stepped = SensorSpec(D7, resolution_m_s2=100 * UG, sample_rate_hz=1000.0)
    assert stepped.psd(1.0) == pytest.approx(D7**2 + (100 * UG) ** 2 / 6000, rel=1e-12)


def test_two_feeds_propagate_each_feed_through_its_weight():
    program = TestProgram(radius_m=0.1, feeds_m_per_s=(0.1, 0.05), cycles_per_feed=(15, 8))
    sensor = SensorSpec(D7)
    s1 = sigma_run(program.at_feed(0), sensor)
    s2 = sigma_run(program.at_feed(1), sensor)
    # c = (A1, -A2) / (A1 - A2) = (4/3, -1/3)
    assert sigma_run(program, sensor) == pytest.approx(math.hypot(4 / 3 * s1, s2 / 3), rel=1e-12)


def test_servo_leak_is_the_issues_example():
    # lags 1.5 and 2.1 ms at omega = 16 rad/s, eps_c = 1.15 deg: "about 10 urad";
    # omega^2 (tau_y^2 - tau_x^2) / 2 sin(2 eps_c) = 11.1 urad
    program = TestProgram(radius_m=0.025, feed_m_per_s=0.4)  # omega = 16 rad/s
    limits = Limits(1.0, 10.0, 1.0, 600.0, (1.5e-3, 2.1e-3), math.radians(1.15))
    leak = servo_leak(program, SensorSpec(D7), limits)
    assert leak == pytest.approx(0.5 * 256 * (2.1e-3**2 - 1.5e-3**2) * math.sin(math.radians(2.3)))
    assert leak == pytest.approx(11.1 * URAD, abs=0.05 * URAD)


SENSOR25 = SensorSpec(25 * UG, 0.1, 2.048 * G, 1000.0, 3.9 * UG)
LIMITS = Limits(20000 * MM_PER_MIN, 5.0, 0.5, 300.0)


@pytest.mark.parametrize("separate", [False, True])
@pytest.mark.parametrize(
    "limits",
    [
        LIMITS,
        Limits(6000 * MM_PER_MIN, 0.1, 0.2, 600.0),
        Limits(15000 * MM_PER_MIN, 2.0, 0.08, 90.0),
    ],
)
def test_the_plan_keeps_within_the_limits(limits, separate):
    goal = Goal(10 * URAD, 0.95, 5, separate_gravity=separate)
    plan = plan_test(SENSOR25, limits, goal)
    p = plan.program
    assert p.n_feeds == (2 if separate else 1)
    for f in range(p.n_feeds):
        one = p.at_feed(f)
        assert one.feed_m_per_s <= limits.max_feed_m_s * (1 + 1e-12)
        assert one.centripetal_m_s2 <= limits.max_accel_m_s2 * (1 + 1e-12)
        assert one.cycles_per_direction >= MIN_CYCLES
        # the blocks rest longer than a tenth of the period, which the segmentation needs
        assert p.dwell_s >= 0.1 * one.period_s
    assert 2 * p.radius_m <= limits.travel_m
    assert plan.duration_s <= limits.time_s
    # a plan is a valid program file
    from imu_square.program import parse_program

    assert parse_program(plan.to_toml()) == p
    # the detectable change: z sigma_change + the leak, z = 1.96 at 95 %
    assert plan.z == pytest.approx(1.959964, rel=1e-6)
    assert plan.sigma_change_rad == pytest.approx(plan.sigma_run_rad * math.sqrt(1.2))
    assert plan.detectable_change_rad == pytest.approx(
        plan.z * plan.sigma_change_rad + plan.servo_leak_rad
    )


def test_more_time_resolves_more_and_the_leak_pushes_to_large_circles():
    short = plan_test(SENSOR25, replace(LIMITS, time_s=100.0), Goal(stable_servo=True))
    long = plan_test(SENSOR25, replace(LIMITS, time_s=400.0), Goal(stable_servo=True))
    # sigma ~ 1/sqrt(T), up to the overheads of a block (overshoots, ramps, dwells)
    assert long.sigma_run_rad / short.sigma_run_rad == pytest.approx(0.5, rel=0.1)
    counted = plan_test(SENSOR25, LIMITS, Goal())
    kept = plan_test(SENSOR25, LIMITS, Goal(stable_servo=True))
    # counting the leak (omega^2 = A / r) moves the plan to a larger, slower circle
    assert counted.program.radius_m > kept.program.radius_m
    assert counted.program.omega_rad_s < kept.program.omega_rad_s
    assert kept.detectable_change_rad == pytest.approx(kept.z * kept.sigma_change_rad)


def test_time_to_detect_scales_the_cycles():
    plan = plan_test(SENSOR25, LIMITS, Goal(3 * URAD, 0.95, 5, stable_servo=True))
    assert not plan.detects
    # (z sigma_change / target)^2 as many cycles: about (8.9 / 3)^2 = 9 x the time
    ratio = (plan.z * plan.sigma_change_rad / (3 * URAD)) ** 2
    assert plan.time_to_detect_s == pytest.approx(ratio * plan.duration_s, rel=0.02)


@pytest.mark.parametrize(
    ("sensor", "limits", "goal", "match"),
    [
        (SENSOR25, replace(LIMITS, time_s=2.0), Goal(), r"no circle test fits: at least 5 cycles"),
        (
            SENSOR25,
            replace(LIMITS, travel_m=0.005),
            Goal(),
            r"travel \[m\] must be in \[0\.01, 10\], got 0\.005",
        ),
        (replace(SENSOR25, noise_density_m_s2_rthz=-1.0), LIMITS, Goal(), r"noise density .*-1\.0"),
        (SENSOR25, LIMITS, Goal(confidence=1.5), r"confidence must be in \(0, 1\), got 1\.5"),
        (SENSOR25, LIMITS, Goal(confidence=1.0), r"confidence must be in \(0, 1\), got 1\.0"),
        (SENSOR25, LIMITS, Goal(baseline_runs=0), r"baseline runs must be in \(0, 1e\+06\]"),
        (SENSOR25, replace(LIMITS, max_accel_m_s2=0.0), Goal(), r"max centripetal .*got 0\.0"),
    ],
)
def test_refusals_name_the_parameter(sensor, limits, goal, match):
    with pytest.raises(PlanError, match=match):
        plan_test(sensor, limits, goal)
    assert issubclass(PlanError, ImuSquareError)


def test_cli_writes_a_program_the_other_commands_take(tmp_path, capsys):
    out = tmp_path / "plan.toml"
    argv = [
        "plan",
        "--noise-ug",
        "25",
        "--max-feed-mm-min",
        "20000",
        "--max-accel-m-s2",
        "5",
        "--travel-mm",
        "500",
        "--time-s",
        "300",
        "--detect-um-m",
        "10",
        "--baseline-runs",
        "5",
        "--stable-servo",
        "--json",
        "-o",
        str(out),
    ]
    assert main(argv) == 0
    captured = capsys.readouterr()
    doc = json.loads(captured.out)
    for key in ("sigma_run_urad", "sigma_change_urad", "detectable_change_urad", "duration_s"):
        assert doc[key] > 0
    assert doc["detects_target"] is True and doc["detectable_change_urad"] <= 10.0
    assert doc["duration_s"] <= 300.0
    program = read_program(out)
    assert program.radius_m == pytest.approx(doc["radius_mm"] * MM)
    assert doc["feeds_mm_per_min"] == [program.feed_m_per_s / MM_PER_MIN]
    assert "plan: r = " in captured.err and f"wrote {out}" in captured.err
    assert main(["program", str(out), "-o", str(tmp_path / "w.ngc")]) == 0
    capsys.readouterr()
    # the flags name their units; the old name of the noise flag is taken too
    argv[1] = "--noise-density-ug"
    assert main(argv[:-2]) == 0
    assert json.loads(capsys.readouterr().out)["sigma_run_urad"] == doc["sigma_run_urad"]


def test_cli_takes_the_sensor_file_and_says_when_the_target_is_missed(tmp_path, capsys):
    from imu_square.simulate import data_path

    argv = ["plan", "--sensor", str(data_path("sensor_paper.toml")), "--max-feed-mm-min", "6000"]
    argv += ["--max-accel-m-s2", "0.1", "--travel-mm", "200", "--time-s", "400"]
    assert main([*argv, "--detect-um-m", "10", "--json"]) == 1  # not detected: exit 1
    doc = json.loads(capsys.readouterr().out)
    assert doc["detects_target"] is False
    assert doc["noise_density_at_circle_ug_rthz"] == pytest.approx([7.0], rel=1e-3)
    assert doc["time_to_detect_s"] > 400
    assert main([*argv[:-1], "2"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "error:" in err[0]


@pytest.mark.slow
def test_predicted_sigma_matches_simulated_runs():
    """Monte Carlo subset of benchmarks/planner.py: one short plan, 30 runs.

    The ratio of the runs' standard deviation to the prediction lies within the
    chi-square interval of 29 degrees of freedom (two-sided 0.1 %), and their
    mean within 1 urad plus 3.5 standard errors of the truth (servo lags on).
    """
    sensor = SensorSpec(25 * UG, 0.5, 2.048 * G, 500.0, 0.0)
    plan = plan_test(sensor, Limits(12000 * MM_PER_MIN, 2.0, 0.1, 40.0), Goal(stable_servo=True))
    program = plan.program
    machine = MachineModel(tau_x_s=2e-3, tau_y_s=2.5e-3)
    quiet = SensorModel(sample_rate_hz=500.0, eps_c_rad=math.radians(2.1), beta_rad=20e-6)
    base, truth = simulate_run(program, machine, quiet, seed=0)
    options = AnalysisOptions(cutoff_hz=plan.cutoff_hz, bootstrap_n=0)
    n = 30
    errors = []
    for seed in range(n):
        rng = np.random.default_rng(500 + seed)
        noise = sensor_noise(base.n_samples, 500.0, sensor.noise_density_m_s2_rthz, 0.5, rng)
        rec = replace(
            base,
            accel=base.accel + noise,
            sensor=SensorInfo(noise_density_m_s2_rthz=sensor.noise_density_m_s2_rthz),
        )
        errors.append(analyze(rec, options).squareness_rad - truth["expected_squareness_rad"])
    sd = float(np.std(errors, ddof=1))
    lo = math.sqrt(stats.chi2.ppf(0.0005, n - 1) / (n - 1))
    hi = math.sqrt(stats.chi2.ppf(0.9995, n - 1) / (n - 1))
    assert lo < sd / plan.sigma_run_rad < hi
    assert abs(np.mean(errors)) < 1 * URAD + 3.5 * sd / math.sqrt(n)


def test_evaluate_says_what_a_given_program_resolves():
    # the paper's test (2 x 15 cycles) with the paper's sensor: 70 urad / sqrt(e) per run;
    # a 0.5 urad target is far out of reach: (z sigma_change / target)^2 times the cycles
    limits = Limits(0.1, 0.1, 0.2, 400.0, (2e-3, 2e-3))
    plan = predict(PAPER, SensorSpec(D7), limits, Goal(100 * URAD, 0.95, 4))
    assert plan.servo_leak_rad == 0.0  # equal lags: no ellipse
    assert plan.sigma_run_rad == pytest.approx(sigma_run(PAPER, SensorSpec(D7)), rel=1e-12)
    assert plan.sigma_change_rad == pytest.approx(plan.sigma_run_rad * math.sqrt(1.25))
    assert plan.detectable_change_rad == pytest.approx(1.959964 * plan.sigma_change_rad)
    assert plan.detects is False
    assert plan.analysed_s == pytest.approx(30 * 2 * math.pi, rel=1e-12)
    assert plan.cutoff_hz == 4.0


PLAN_ARGS = ["plan", "--max-feed-mm-min", "30000", "--max-accel-m-s2", "5", "--travel-mm", "500"]


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--noise-ug", "-3"], "noise_density_ug_rthz > 0, got -3 ug/sqrt(Hz)"),
        (["--noise-ug", "25", "-o", "{tmp}/nodir/plan.toml"], "nodir' does not exist"),
        (["--noise-ug", "25", "-o", "{tmp}"], "is a directory"),
        (["--noise-ug", "25", "--confidence", "1"], ": --confidence must be in (0, 1), got 1\n"),
        # each limit named by its flag, in the flag's unit
        (
            ["--noise-ug", "25", "--travel-mm", "5"],
            "--travel-mm must be in [10, 10000] mm, got 5 mm",
        ),
        (
            ["--noise-ug", "25", "--servo-lags-ms", "2", "2000"],
            "--servo-lags-ms must be in [0, 1000] ms, got 2000 ms",
        ),
        (
            ["--noise-ug", "25", "--eps-c-deg", "50"],
            ": --eps-c-deg must be in [0, 45] deg, got 50 deg",
        ),
        (["--noise-ug", "25", "--detect-um-m", "-3"], "--detect-um-m must be in (0, 1e+06] µm/m"),
    ],
)
def test_cli_refusals_are_one_line_before_any_plan(tmp_path, capsys, extra, message):
    argv = [*PLAN_ARGS, "--time-s", "300", *(a.format(tmp=tmp_path) for a in extra)]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and message in err, err  # no plan printed before the error


def test_a_refused_sensor_file_value_is_named_as_the_file_s(tmp_path, capsys):
    sensor = tmp_path / "s.toml"
    sensor.write_text("[sensor]\nnoise_density_ug_rthz = 25.0\nrange_g = 2.0\neps_c_deg = 50.0\n")
    argv = [*PLAN_ARGS, "--time-s", "300", "--sensor", str(sensor)]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1
    assert "--eps-c-deg (here the --sensor file's value) must be in [0, 45] deg, got 50 deg" in err
    # the flag overrides the file: then the flag is what was refused
    assert main([*argv, "--range-g", "-1"]) == 2
    err = capsys.readouterr().err
    assert ": --range-g must be in (0, 1019.72] g, got -1 g" in err, err


# Every input is checked by imu_square.validation, as every file's fields are.
@pytest.mark.parametrize(
    ("sensor", "limits", "match"),
    [
        # text was a TypeError from a comparison
        (SENSOR25, replace(LIMITS, time_s="300"), r"^time \[s\] must be a number in \(0, 1e\+06\]"),
        # a bool is not a number (True was taken as a 1 Hz corner)
        (
            replace(SENSOR25, flicker_corner_hz=True),
            LIMITS,
            r"^flicker corner \[Hz\] must be a number in \[0, 1000\], got True$",
        ),
    ],
)
def test_a_plan_input_of_the_wrong_type_is_refused_naming_it(sensor, limits, match):
    with pytest.raises(PlanInputError, match=match) as info:
        plan_test(sensor, limits, Goal())
    assert info.value.parameter in ("time_s", "flicker_corner_hz")


def test_a_numpy_integer_is_a_whole_number_to_the_planner():
    # a numpy integer was refused as "baseline runs must be a whole number"
    goal = Goal(baseline_runs=np.int64(5))
    assert plan_test(SENSOR25, LIMITS, goal) == plan_test(SENSOR25, LIMITS, Goal(baseline_runs=5))


@pytest.mark.slow
def test_plan_says_how_many_nights_the_monitors_charts_take(tmp_path, capsys):
    # One night's 95 % test "detects" 5 µm/m here (z sigma_change = 4.3), yet the
    # monitor, designed for one false alarm in 730 nights, needs more than a night.
    argv = ["plan", "--noise-density-ug", "25", "--max-feed-mm-min", "30000"]
    argv += ["--max-accel-m-s2", "10", "--travel-mm", "500", "--time-s", "300"]
    argv += ["--stable-servo", "--baseline-runs", "10", "--detect-um-m", "5", "--json"]
    assert main(argv) == 0
    out = capsys.readouterr()
    plan = json.loads(out.out)
    assert plan["detects_target"] is True and plan["detectable_change_urad"] < 5
    assert plan["monitor_false_alarm_nights"] == 730 and plan["monitor_step_urad"] == 5
    assert plan["monitor_nights_to_detect_median"] > 1
    assert plan["monitor_nights_to_detect_p90"] >= plan["monitor_nights_to_detect_median"]
    assert "one night alone, a two-sided test at 95%" in out.err
    assert re.search(r"the monitor \(.*730 nights\): a step of 5 µm/m alarms after", out.err)
    # The monitor's own design code gives the same nights for the same night law.
    from imu_square.monitor.stats.alarms import design_alarms

    design = design_alarms(
        730,
        plan["sigma_run_urad"] * URAD,
        step_rad=5 * URAD,
        nu=plan["cycles_per_direction"][0] - 1,
        baseline_sd_ratio=10**-0.5,
        mc_nights=400_000,
    )
    assert plan["monitor_nights_to_detect_median"] == design.check.step_median
    # A monitor file asking for more false alarms finds the step sooner.
    monitor = tmp_path / "monitor.toml"
    monitor.write_text(
        '[monitor]\nmachine_id = "m"\nhistory = "h.db"\n\n[alarms]\nfalse_alarm_nights = 50\n'
    )
    assert main([*argv, "--config", str(monitor)]) == 0
    eager = json.loads(capsys.readouterr().out)
    assert eager["monitor_false_alarm_nights"] == 50
    assert eager["monitor_nights_to_detect_p90"] < plan["monitor_nights_to_detect_p90"]
