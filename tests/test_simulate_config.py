"""Machine and sensor files, the shipped examples, and the named effects."""

import math

import pytest
from numpy.testing import assert_allclose

from imu_square.cli import main
from imu_square.errors import ConfigError
from imu_square.program import TestProgram, read_program
from imu_square.simulate import (
    EFFECTS,
    MachineModel,
    SensorModel,
    data_path,
    read_machine,
    read_sensor,
    simulate_run,
    with_effects,
)

PROGRAM = TestProgram(radius_m=0.05, feed_m_per_s=0.05, cycles_per_direction=2, dwell_s=0.3)


def test_shipped_files_read():
    program = read_program(data_path("program_paper.toml"))
    assert (program.radius_m, program.feed_m_per_s, program.cycles_per_direction) == (
        0.1,
        0.1,
        15,
    )
    assert program.dwell_s == 2.0 and program.overshoot_rad == math.pi
    assert read_machine(data_path("machine_ideal")) == MachineModel(name="ideal")
    assert read_sensor(data_path("sensor_ideal.toml")) == SensorModel(model="ideal")
    paper = read_sensor(data_path("sensor_paper.toml"))
    assert_allclose(paper.noise_density_m_s2_rthz, 7e-6 * 9.80665, rtol=1e-12)
    assert_allclose(paper.eps_c_rad, math.radians(2.1), rtol=1e-12)
    assert paper.sample_rate_hz == 1000.0
    typical = read_machine(data_path("machine_typical.toml"))
    assert set(typical.effects()) == {
        "servo_mismatch",
        "backlash",
        "reversal_spikes",
        "scale_mismatch",
        "straightness_yaw",
        "structural_vibration",
    }
    assert_allclose(typical.geometry.machine_squareness_rad, 15e-6, rtol=1e-12)


def test_unknown_data_file():
    with pytest.raises(ConfigError, match=r"data file 'nope.toml' is not shipped; available"):
        data_path("nope")


@pytest.mark.parametrize(
    "in_phase, quadrature, damping, refused",
    [(0.01, 0.0, 0.26, False), (0.0, 0.02, 0.27, True), (0.0, 0.0, 0.9, False)],
)
def test_a_ramp_ringing_that_dies_before_it_is_sized_is_refused(
    tmp_path, in_phase, quadrature, damping, refused
):
    # sized 30 ms after the corner: at 1 kHz a damping of 0.265 decays e^50 by then, and
    # the ringing would start e^50 larger (inf beyond e^709); without it, any damping reads
    path = tmp_path / "m.toml"
    path.write_text(
        f"[structural_vibration]\nstart_stop_m_s2 = {in_phase}\n"
        f"start_stop_quadrature_m_s2 = {quadrature}\n"
        f"frequency_hz = 1000.0\ndamping_ratio = {damping}\n"
    )
    if refused:
        with pytest.raises(ConfigError, match=r"damping_ratio must be below 0.265 with the feed"):
            read_machine(path)
    else:
        assert read_machine(path).vibration_damping == damping


def test_machine_file_units(tmp_path):
    path = tmp_path / "m.toml"
    path.write_text(
        "[machine]\nname = 'm1'\nramp_s = 0.2\nramp_profile = 's_curve'\n"
        "[geometry]\nmachine_squareness_um_per_m = -12.5\naxis_centre_mm = [100, -50]\n"
        "[squareness_drift]\nrate_um_per_m_per_h = 3.6\n"
        "[servo_mismatch]\ntau_x_ms = 1.5\nmodel = 'first_order'\n"
        "[straightness_yaw]\nx_um = 4\nyaw_x = true\n"
        "[gravity_coupling]\nx_per_y_urad_per_m = 100\n"
        "[structural_vibration]\nstart_stop_m_s2 = -0.03\n"
        "[reversal_spikes]\npeak_x_m_s2 = -0.01\nonset_tau = -2\nsymmetric = true\n"
    )
    m = read_machine(path)
    assert m.vibration_start_stop_m_s2 == -0.03
    assert m.spike_symmetric and m.spike_onset == -2.0 and m.spike_x_m_s2 == -0.01
    assert m.effects()["reversal_spikes"]["symmetric"] is True
    # the skewed form's default: its truth is what it was before the symmetric one
    assert (
        "symmetric"
        not in read_machine(data_path("machine_typical.toml")).effects()["reversal_spikes"]
    )
    assert m.name == "m1" and m.ramp_s == 0.2 and m.ramp_profile == "s_curve"
    assert_allclose(m.geometry.machine_squareness_rad, -12.5e-6, rtol=1e-12)
    assert_allclose(m.geometry.machine_squareness_rate_rad_s, 1e-9, rtol=1e-12)
    assert_allclose(m.geometry.axis_centre_m, (0.1, -0.05), rtol=1e-12)
    assert_allclose(m.tau_x_s, 1.5e-3, rtol=1e-12)
    assert m.servo_model == "first_order"
    assert m.geometry.yaw_x and not m.geometry.yaw_y
    assert_allclose(m.tilt_per_m, (0.0, 1e-4, 0.0, 0.0), rtol=1e-12)


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("[machin]\nname = 'x'\n", r"m.toml: unknown section \[machin\]; allowed: \["),
        ("[backlash]\nx_mm = 5\n", r"\[backlash\] has unknown field 'x_mm'; allowed: \["),
        (
            "[backlash]\nx_um = -5000\n",
            r"\[backlash\] x_um must be in \[-1000, 1000\], got -5000.0",
        ),
        ("[servo_mismatch]\ntau_x_ms = 'fast'\n", r"tau_x_ms must be a number, got 'fast'"),
        (
            "[servo_mismatch]\nmodel = 'pid'\n",
            r"\[servo_mismatch\] model must be one of \('pure_lag', 'first_order'\), got 'pid'",
        ),
        ("[machine]\nramp_profile = 'sine'\n", r"ramp_profile must be one of \('trapezoid', "),
        ("[machine]\nramp_s = 0\n", r"\[machine\] ramp_s must be in \(0, 5\], got 0.0"),
        ("[straightness_yaw]\nyaw_x = 1\n", r"yaw_x must be true or false, got 1"),
        ("[geometry]\naxis_length_mm = [800]\n", r"axis_length_mm must be two finite numbers"),
        ("[geometry]\naxis_length_mm = [0, 800]\n", r"axis_length_mm must be positive, got \[0"),
        (
            "[structural_vibration]\ndamping_ratio = 1.0\n",
            r"damping_ratio must be in \(0, 1\), got 1.0",
        ),
        ("backlash = 5\n", r"\[backlash\] must be a table, got 5"),
        ("[machine\n", r"m.toml: not valid TOML"),
    ],
)
def test_machine_file_errors(tmp_path, text, match):
    path = tmp_path / "m.toml"
    path.write_text(text)
    with pytest.raises(ConfigError, match=match):
        read_machine(path)


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("[sensor]\nsample_rate_hz = 0\n", r"\[sensor\] sample_rate_hz must be in \(0, "),
        ("[sensor]\nnoise_density = 7\n", r"unknown field 'noise_density'"),
        ("[sensor]\nrange_g = nan\n", r"range_g must be in \(0, inf\], got nan"),
        ("[sensor_gain_mismatch]\ngain_percent = [1, 2]\n", r"three numbers \[x, y, z\]"),
        ("[sample_clock_error]\nppm = true\n", r"ppm must be a number, got True"),
        # a drift section without its start value would invent a warm-up from 0
        (
            "[sensor]\nbeta_urad = 30\n[sensor_thermal_drift]\ntau_warm_s = 100\n",
            r"\[sensor_thermal_drift\] needs beta_0_urad .*got only \['tau_warm_s'\]",
        ),
    ],
)
def test_sensor_file_errors(tmp_path, text, match):
    path = tmp_path / "s.toml"
    path.write_text(text)
    with pytest.raises(ConfigError, match=match):
        read_sensor(path)


def test_missing_file(tmp_path):
    with pytest.raises(ConfigError, match=r"missing.toml: file not found"):
        read_sensor(tmp_path / "missing.toml")


def test_sensor_file_units(tmp_path):
    path = tmp_path / "s.toml"
    path.write_text(
        "[sensor]\nrange_g = 2\nresolution_ug = 3.9\ntilt_x_urad = 100\nbeta_urad = 20\n"
        "temperature_c = 21.5\n"
        "[sensor_thermal_drift]\nbeta_0_urad = 120\ntau_warm_s = 100\ntemperature_rise_c = 6\n"
        "[sensor_gain_mismatch]\ngain_percent = [0.1, -0.2, 0]\nbias_mg = [1, 0, 0]\n"
        "[sample_clock_error]\nppm = -20\n"
    )
    s = read_sensor(path)
    assert_allclose(s.range_m_s2, 2 * 9.80665, rtol=1e-12)
    assert_allclose(s.resolution_m_s2, 3.9e-6 * 9.80665, rtol=1e-12)
    assert_allclose(s.tilt_rad, (1e-4, 0.0), rtol=1e-12)
    assert_allclose((s.beta_rad, s.beta_0_rad, s.tau_warm_s), (20e-6, 120e-6, 100.0))
    assert (s.temperature_c, s.temperature_rise_c) == (21.5, 6.0)
    assert_allclose(s.gain, (1e-3, -2e-3, 0.0), rtol=1e-12)
    assert_allclose(s.bias_m_s2, (9.80665e-3, 0, 0), rtol=1e-12)
    assert s.clock_ppm == -20.0
    assert set(s.effects()) == {
        "sensor_thermal_drift",
        "sensor_gain_mismatch",
        "sample_clock_error",
    }


@pytest.mark.parametrize("name", EFFECTS)
def test_each_effect_switches_on_exactly_itself(name):
    machine, sensor = with_effects([name], None, SensorModel(sample_rate_hz=100.0))
    _, truth = simulate_run(PROGRAM, machine, sensor, seed=0, lead_in_s=0.5, lead_out_s=0.5)
    assert set(truth["effects"]) == {name}


def test_effect_magnitudes_at_the_paper_test():
    machine, sensor = with_effects("servo_mismatch, gravity_coupling, squareness_drift")
    paper = TestProgram()
    assert_allclose(paper.omega_rad_s * (machine.tau_y_s - machine.tau_x_s), 1000e-6, rtol=1e-9)
    assert_allclose(machine.tilt_per_m[1] * 0.1, 10e-6, rtol=1e-12)  # 10 urad per 100 mm
    assert_allclose(machine.geometry.machine_squareness_rate_rad_s * 3600, 36e-6, rtol=1e-12)
    assert sensor == SensorModel()


def test_unknown_effect_is_named():
    with pytest.raises(ConfigError, match=r"unknown effect 'servo'; allowed: \['servo_mismatch'"):
        with_effects(["servo"])


def test_lead_in_is_checked():
    with pytest.raises(ConfigError, match=r"lead_in_s must be a finite number >= 0, got -1.0"):
        simulate_run(PROGRAM, lead_in_s=-1.0)


def test_events_at_true_motion_start_and_end():
    rec, truth = simulate_run(PROGRAM, seed=0, lead_in_s=0.5)
    assert [(e.kind, e.direction, e.block) for e in rec.events] == [
        ("block_start", "ccw", 0),
        ("block_end", "ccw", 0),
        ("block_start", "cw", 1),
        ("block_end", "cw", 1),
    ]
    times = [e.time_ns for e in rec.events]
    assert times == [v for b in truth["blocks"] for v in (b["start_ns"], b["end_ns"])]
    assert_allclose(truth["blocks"][0]["start_s"], 0.5, rtol=1e-15)
    # nothing moves before the first start (ideal machine, noiseless sensor)
    before = rec.time_ns < times[0]
    assert (rec.accel[before, :2] == 0).all() and (rec.accel[~before, :2][:1] != 0).any()
    rec2, _ = simulate_run(PROGRAM, seed=0, lead_in_s=0.5, events=False)
    assert rec2.events == []


# The machine and sensor files are now checked like every file (imu_square.validation);
# each of these they said differently, or let through.
@pytest.mark.parametrize(
    ("flag", "text", "line"),
    [
        # a name is one line of text, as in the monitor file (was taken as it came)
        (
            "--machine",
            '[machine]\nname = "a\\nb"\n',
            "[machine] name must be a non-empty string on one line (no control characters), "
            "got 'a\\nb'",
        ),
        # an infinity is told "finite", as by the program file (was "in [-100000, 100000]")
        ("--sensor", "[sensor]\nbeta_urad = inf\n", "[sensor] beta_urad must be finite, got inf"),
        # each number of a list is checked as a number, as in the program file's centre_mm
        (
            "--sensor",
            "[sensor_gain_mismatch]\ngain_percent = [60, 0, 0]\n",
            "[sensor_gain_mismatch] gain_percent must be in [-50, 50], got 60.0",
        ),
        (
            "--machine",
            '[geometry]\naxis_centre_mm = [0, "x"]\n',
            "[geometry] axis_centre_mm must be a number, got 'x'",
        ),
    ],
)
def test_machine_and_sensor_files_are_checked_like_every_file(tmp_path, capsys, flag, text, line):
    path = tmp_path / "f.toml"
    path.write_text(text)
    assert main(["simulate", flag, str(path), "-o", str(tmp_path / "r.mcap")]) == 2
    assert capsys.readouterr().err == f"imu-square simulate: error: {path}: {line}\n"
    assert not (tmp_path / "r.mcap").exists()
