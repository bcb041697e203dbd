"""The model-discrepancy workflow on recordings whose truth is known.

A short circle (50 mm at 3000 mm/min: omega = 1 rad/s, v^2/r = 0.05 m/s^2,
4 cycles each way) sampled at 200 Hz with the paper's 7 ug/sqrt(Hz) keeps
each run to a few seconds; ``benchmarks/discrepancy.py`` runs the paper's test
and the acceptance set.
"""

import json
import math
from dataclasses import replace

import numpy as np
import pytest
from scipy import stats

from imu_square.cli import main
from imu_square.discrepancy import VIEWS, DiscrepancyOptions, find_discrepancy
from imu_square.discrepancy.localise import TRANSIENT_ZERO_PAD, residual_curves
from imu_square.discrepancy.parameters import effect_model_parameters
from imu_square.discrepancy.result import headline_is_honest
from imu_square.discrepancy.selection import _shape_grid
from imu_square.discrepancy.workflow import fit_base, steps_in_model
from imu_square.io.mcap import read_mcap, write_mcap
from imu_square.program import TestProgram
from imu_square.simulate import (
    MachineModel,
    SensorModel,
    data_path,
    read_machine,
    read_sensor,
    simulate_run,
    with_effects,
)
from imu_square.units import UG

PROGRAM = TestProgram(radius_m=0.05, feed_m_per_s=0.05, cycles_per_direction=4, dwell_s=1.0)
SENSOR = SensorModel(
    model="test", sample_rate_hz=200.0, noise_density_m_s2_rthz=7 * UG, eps_c_rad=math.radians(2.1)
)


def record(tmp_path, machine=None, sensor=SENSOR, seed=1, program=PROGRAM, name="run.mcap"):
    recording, truth = simulate_run(program, machine or MachineModel(), sensor, seed=seed)
    path = tmp_path / name
    write_mcap(recording, path)
    return path, truth


def run_cli(capsys, *argv):
    code = main(["discrepancy", *map(str, argv)])
    out = capsys.readouterr()
    return code, out.out, out.err


@pytest.mark.slow
def test_views_of_clean_recordings_follow_their_null_distribution():
    """On clean recordings each view's p-value is uniform and its mean S / nu is 1."""
    n = 30
    p_values = {v: [] for v in VIEWS}
    ratios = {v: [] for v in VIEWS}
    dof = {}
    fit_p = []
    for seed in range(n):
        recording, _ = simulate_run(PROGRAM, MachineModel(), SENSOR, seed=500 + seed)
        problem, base, params = fit_base(recording, PROGRAM)
        gaps = problem.gaps(base)
        for v in VIEWS:
            p_values[v].append(gaps[v].p_value)
            ratios[v].append(gaps[v].gap ** 2)
            dof[v] = gaps[v].dof
        nu = problem.space.fit_vector(base.residual).size - len(params)
        fit_p.append(stats.chi2.sf(base.rss, nu))
    for v in VIEWS:
        # uniform p-values (Kolmogorov-Smirnov, 9 views at 1e-3 each)
        assert stats.kstest(p_values[v], "uniform").pvalue > 1e-3, v
        if v != "band":  # the band view is a maximum over octaves: its mean exceeds 1
            sd = math.sqrt(2 / dof[v] / n)  # of the mean of chi2(nu)/nu over n runs
            assert abs(np.mean(ratios[v]) - 1) < 4 * sd, (v, np.mean(ratios[v]))
    assert stats.kstest(fit_p, "uniform").pvalue > 1e-3


def test_noise_floor_is_the_sensor_density_and_finds_a_1f_corner():
    recording, _ = simulate_run(PROGRAM, MachineModel(), SENSOR, seed=3)
    noise = fit_base(recording, PROGRAM)[0].space.noise
    # relative sd of the density from the scatter: sqrt(1 / (2 dof))
    tol = 5 / math.sqrt(2 * noise.dof)
    np.testing.assert_allclose(noise.density_m_s2_rthz, 7 * UG, rtol=tol)
    assert np.all(noise.flicker_corner_hz < 0.05)
    flicker = replace(SENSOR, flicker_corner_hz=0.3)
    corners = []
    for seed in range(6):
        recording, _ = simulate_run(PROGRAM, MachineModel(), flicker, seed=seed)
        corners.append(fit_base(recording, PROGRAM)[0].space.noise.flicker_corner_hz)
    # a 0.3 Hz corner, from 8 cycles: about +-0.15 Hz per run and axis
    assert 0.2 < np.mean(corners) < 0.4


def test_clean_recording_names_nothing_and_exits_0(tmp_path, capsys):
    path, _ = record(tmp_path, seed=11)
    code, out, err = run_cli(capsys, path, "--json")
    assert code == 0
    doc = json.loads(out)
    assert doc["named_effects"] == [] and doc["ambiguous"] == [] and doc["steps"] == []
    assert set(doc["base_gap"]) == set(VIEWS) == set(doc["final_gap"])
    assert all(g < 1.3 for g in doc["final_gap"].values())
    assert "explains the recording down to the noise" in err


def test_transient_periodogram_is_one_on_average_under_the_null():
    recording, _ = simulate_run(PROGRAM, MachineModel(), SENSOR, seed=4)
    problem, base, _ = fit_base(recording, PROGRAM)
    curves = residual_curves(problem.space, base.residual)
    # independent frequencies, one resolution apart, without 0 and the bins' Nyquist frequency
    power = curves.transient_power[TRANSIENT_ZERO_PAD:-1:TRANSIENT_ZERO_PAD]
    channels = len([y for y in curves.transient.values() if not np.all(np.isnan(y))])
    assert channels == 8
    # each frequency's power is a mean of 8 chi2(2) / 2: sd 1 / sqrt(8) per frequency
    sd = 1.0 / math.sqrt(channels * power.size)
    assert abs(power.mean() - 1.0) < 4 * sd, power.mean()


# 5 ms at 1 rad/s is 5 mrad of phase against this test's noise floor of about 0.3 mrad
LAG = MachineModel(tau_x_s=2e-3, tau_y_s=7e-3)


def test_servo_mismatch_is_named_measured_and_the_gap_closes(tmp_path, capsys):
    path, _ = record(tmp_path, machine=LAG, seed=2)
    plot = tmp_path / "gaps.png"
    code, out, err = run_cli(capsys, path, "--json", "--plot", plot)
    assert code == 1
    doc = json.loads(out)
    assert doc["named_effects"] == ["servo_mismatch"] and doc["ambiguous"] == []
    (step,) = doc["steps"]
    assert step["effect"] == "servo_mismatch" and step["p_value"] < 1e-6
    assert set(step) >= {"effect", "parameters", "gap_before", "gap_after", "statistic", "p_value"}
    params = step["parameters"]
    mismatch = params["tau_y_ms"]["value"] - params["tau_x_ms"]["value"]
    u = params["tau_y_ms"]["u_value"] or params["tau_x_ms"]["u_value"]
    assert abs(mismatch - 5.0) < 3 * u and params["tau_y_ms"]["unit"] == "ms"
    assert step["gap_before"]["cw_vs_ccw"] > 1.5 > 1.2 > step["gap_after"]["cw_vs_ccw"]
    assert all(g < 1.3 for g in doc["final_gap"].values())
    assert plot.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert "step 1: servo_mismatch" in err and "tau_y_ms" in err


def test_two_effects_are_named_in_turn(tmp_path):
    machine = replace(LAG, backlash_x_m=5e-6, backlash_y_m=3e-6, backlash_take_up_s=0.02)
    path, _ = record(tmp_path, machine=machine, seed=4)
    result = find_discrepancy(read_mcap(path), DiscrepancyOptions(suggest=False))
    assert set(result.named_effects) == {"servo_mismatch", "backlash"}
    values = {v.name: v for v in result.model}
    for name, truth in (("backlash.x_um", 5.0), ("backlash.y_um", 3.0)):
        assert abs(values[name].value - truth) < 4 * values[name].u_value, name
    assert max(g.gap for g in result.final_gap.values()) < 1.3


def test_look_alike_effects_are_named_together_with_the_tests_that_separate_them(tmp_path):
    """A sensor gain, a machine scale and a gravity coupling all change the amplitudes."""
    _, sensor = with_effects(["sensor_gain_mismatch"], sensor=SENSOR)
    path, _ = record(tmp_path, sensor=sensor, seed=5)
    result = find_discrepancy(read_mcap(path))
    (group,) = result.ambiguous
    assert set(group) == {"sensor_gain_mismatch", "scale_mismatch", "gravity_coupling"}
    assert result.named_effects == ()
    (suggestion,) = result.suggested_tests
    pairs = {frozenset(p["effects"]): p["separated_by"] for p in suggestion["pairs"]}
    turned = "the same test with the sensor turned 90°"
    # a gain lives in the sensor frame, a scale in the machine's: only turning tells them apart
    assert pairs[frozenset({"sensor_gain_mismatch", "scale_mismatch"})] == [turned]
    # gravity's share does not grow with the feed, inertia's does
    gravity_scale = pairs[frozenset({"gravity_coupling", "scale_mismatch"})]
    assert "the same circle at twice the feed" in gravity_scale and turned not in gravity_scale
    # every member's own fit of the gap is reported
    (step,) = result.steps
    assert set(step.alternatives) == set(group) - {step.effect}
    members = {step.effect: step.parameters, **step.alternatives}
    gains = {p.name: p.value for p in members["sensor_gain_mismatch"]}
    assert gains["gain_y_percent"] == pytest.approx(0.5, abs=0.08)


def test_effects_outside_the_allowed_ones_leave_a_gap(tmp_path, capsys):
    path, _ = record(tmp_path, machine=LAG, seed=6)
    _, out, err = run_cli(capsys, path, "--json", "--effects-allowed", "backlash,reversal_spikes")
    doc = json.loads(out)
    assert doc["candidates"] == ["backlash", "reversal_spikes"]
    assert "servo_mismatch" not in doc["named_effects"]
    assert doc["final_gap"]["cw_vs_ccw"] > 1.5
    assert any("gap above the noise floor is left in" in n for n in doc["notes"])
    assert "note: a gap above the noise floor is left in" in err
    # the first line a person reads says so, and so does the JSON
    first = err.splitlines()[1]
    assert first.startswith("a gap is left") and "NOT explained" in first, first
    assert "explains" not in first
    assert doc["explained"] is False and doc["headline"] == first
    assert headline_is_honest(doc)
    left = {g["view"]: g for g in doc["gap_left"]}
    assert "cw_vs_ccw" in left and left["cw_vs_ccw"]["p_value"] < 1e-3
    # a lag of y against x: a residual at the circle frequency in the direction difference
    assert left["cw_vs_ccw"]["band"]["harmonics"] == [1, 1]
    assert "position angle" in left["cw_vs_ccw"]["where"]
    assert f"gap left in cw_vs_ccw ({left['cw_vs_ccw']['gap']:.2f})" in err


def _honest_cases(tmp_path):
    """Named, look-alike, gap-left and clean outcomes, each with its JSON."""
    spikes = MachineModel(spike_x_m_s2=0.02, spike_y_m_s2=-0.02)
    yield "clean", record(tmp_path, seed=11, name="clean.mcap")[0], ()
    yield "servo named", record(tmp_path, machine=LAG, seed=2, name="lag.mcap")[0], ()
    yield (
        "servo not allowed",
        record(tmp_path, machine=LAG, seed=6, name="lag6.mcap")[0],
        (
            "--effects-allowed",
            "backlash",
        ),
    )
    yield (
        "spikes not allowed",
        record(tmp_path, machine=spikes, seed=3, name="sp.mcap")[0],
        (
            "--effects-allowed",
            "servo_mismatch",
        ),
    )


def test_the_first_line_never_says_explained_while_a_gap_is_left(tmp_path, capsys):
    """The headline rule (issue 22 section 2); the benchmarks check it on every case."""
    seen = set()
    for name, path, extra in _honest_cases(tmp_path):
        _, out, err = run_cli(capsys, path, "--json", "--no-suggest", *extra)
        doc = json.loads(out)
        assert headline_is_honest(doc), (name, doc["headline"])
        assert err.splitlines()[1] == doc["headline"]
        seen.add(doc["explained"])
        if not doc["explained"]:
            assert all(g["where"] for g in doc["gap_left"]), name
    assert seen == {True, False}


def test_the_honesty_check_refuses_a_false_headline():
    views = {v: {"gap": 1.0, "p_value": 0.5} for v in VIEWS}
    doc = {"views": {"final": views}, "explained": True, "headline": "the base model explains it"}
    assert headline_is_honest(doc)
    views["reversals"] = {"gap": 21.0, "p_value": 1e-30}
    assert not headline_is_honest(doc)
    doc.update(explained=False, headline="a gap is left that no candidate explains, in reversals")
    assert not headline_is_honest(doc)  # "explains" in a headline with a gap left
    doc["headline"] = "a gap is left in reversals (21.00): the recording is NOT explained"
    assert headline_is_honest(doc)


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--effects-allowed", "servo_mismatch,wobble"], "unknown effect 'wobble'"),
        (["--significance", "1.5"], "significance must be a probability in (0, 1), got 1.5"),
    ],
)
def test_user_errors_are_one_line_and_exit_2(tmp_path, capsys, argv, message):
    path, _ = record(tmp_path, seed=7)
    code, out, err = run_cli(capsys, path, *argv)
    assert code == 2 and out == ""
    assert err.count("\n") == 1 and message in err and "Traceback" not in err


def test_a_missing_recording_is_a_user_error(tmp_path, capsys):
    code, _, err = run_cli(capsys, tmp_path / "nope.mcap")
    assert code == 2 and "nope.mcap" in err and err.count("\n") == 1


def test_a_recording_without_circles_is_refused_naming_the_file(tmp_path, capsys):
    recording, _ = simulate_run(PROGRAM, MachineModel(), SENSOR, seed=8)
    still = replace(recording, accel=np.tile(recording.accel[:1], (recording.n_samples, 1)))
    path = tmp_path / "still.mcap"
    write_mcap(still, path)
    code, _, err = run_cli(capsys, path)
    assert code == 2 and f"{path}: " in err and "no motion: " in err


@pytest.mark.slow
def test_the_written_model_reproduces_the_recording_in_imu_square_simulate(tmp_path, capsys):
    machine = replace(LAG, backlash_x_m=5e-6, backlash_y_m=3e-6, backlash_take_up_s=0.02)
    path, _ = record(tmp_path, machine=machine, seed=9)
    model = tmp_path / "model"
    code, out, _ = run_cli(capsys, path, "--json", "--model-out", model)
    assert code == 1
    first = json.loads(out)
    sim = tmp_path / "sim.mcap"
    argv = ["simulate", "--seed", "31", "-o", str(sim)]
    for name in ("program", "machine", "sensor"):
        argv += [f"--{name}", str(model / f"{name}.toml")]
    assert main(argv) == 0
    capsys.readouterr()
    code, out, _ = run_cli(capsys, sim, "--json")
    second = json.loads(out)
    assert code == 1 and set(second["named_effects"]) == set(first["named_effects"])
    # the same gap views within the noise: S / nu of two independent recordings of the
    # same model differ by about sqrt(2 (nu + 2 lambda)) / nu
    for view in VIEWS:
        a, b = first["views"]["base"][view], second["views"]["base"][view]
        nu = a["dof"]
        excess = max(a["statistic"] - nu, 0.0)
        sd = math.sqrt(2 * (nu + 2 * excess)) / nu
        if view != "band":
            assert abs(a["gap"] ** 2 - b["gap"] ** 2) < 5 * sd, view
        for doc in (first, second):  # the final model explains each down to the noise
            assert doc["views"]["final"][view]["p_value"] > 1e-3, view


def test_a_lag_of_x_is_written_as_a_lag_of_x(tmp_path, capsys):
    """Only the mismatch is identifiable; the written lags are both within their range."""
    path, _ = record(tmp_path, machine=MachineModel(tau_x_s=6e-3, tau_y_s=1e-3), seed=12)
    model = tmp_path / "model"
    code, out, _ = run_cli(capsys, path, "--json", "--model-out", model, "--no-suggest")
    assert code == 1 and json.loads(out)["named_effects"] == ["servo_mismatch"]
    machine = read_machine(model / "machine.toml")
    assert machine.tau_y_s == 0.0
    assert machine.tau_x_s == pytest.approx(5e-3, abs=0.6e-3)  # about 3 sd


def _independent_circle_csv(path, tau_x_s, tau_y_s, fs=200.0, seed=5):
    """A circle test with servo lags, in a few lines of numpy (not the project's simulator).

    CCW then CW, 4 cycles each plus 180 deg at both ends, linear feed ramps of
    0.2 s, 1 s dwell, white noise of 7 ug/sqrt(Hz), gravity on z.
    """
    r, v, cycles, over, dwell, ramp, lead = 0.05, 0.05, 4, np.pi, 1.0, 0.2, 2.0
    w = v / r
    total = 2 * np.pi * cycles + 2 * over
    dur = total / w + ramp

    def progress(t):  # angle, speed, acceleration since the block start
        tc = np.clip(t, 0, dur)
        up, down = tc < ramp, tc > dur - ramp
        s = np.where(up, w * tc**2 / (2 * ramp), w * (tc - ramp / 2))
        s = np.where(down, total - w * (dur - tc) ** 2 / (2 * ramp), s)
        ds = np.where(up, w * tc / ramp, np.where(down, w * (dur - tc) / ramp, w))
        dds = np.where(up, w / ramp, np.where(down, -w / ramp, 0.0))
        moving = (t >= 0) & (t <= dur)
        return s, np.where(moving, ds, 0.0), np.where(moving, dds, 0.0)

    t = np.arange(0, 2 * lead + 2 * dur + dwell, 1 / fs)
    acc = np.zeros((t.size, 3))
    acc[:, 2] = 9.80665
    for t0, sign, phi0 in ((lead, 1, 0.0), (lead + dur + dwell, -1, total)):
        for axis, tau in ((0, tau_x_s), (1, tau_y_s)):
            s, ds, dds = progress(t - tau - t0)
            phi, dphi, ddphi = phi0 + sign * s, sign * ds, sign * dds
            if axis == 0:
                a = -r * (np.cos(phi) * dphi**2 + np.sin(phi) * ddphi)
            else:
                a = r * (np.cos(phi) * ddphi - np.sin(phi) * dphi**2)
            acc[:, axis] += np.where(ds > 0, a, 0.0)
    acc += np.random.default_rng(seed).normal(0, 7e-6 * 9.80665 * np.sqrt(fs / 2), acc.shape)
    header = "time_s,accel_x,accel_y,accel_z"
    np.savetxt(
        path, np.column_stack([t, acc]), delimiter=",", header=header, comments="", fmt="%.7f"
    )


def test_a_csv_from_an_independent_generator_runs_through_import(tmp_path, capsys):
    csv = tmp_path / "lag.csv"
    _independent_circle_csv(csv, tau_x_s=0.0, tau_y_s=0.004)
    program = tmp_path / "program.toml"
    program.write_text(PROGRAM.to_toml())
    mcap = tmp_path / "lag.mcap"
    argv = ["import", str(csv), "--program", str(program), "-o", str(mcap)]
    assert main([*argv, "--start-time", "2026-09-01T02:30:00Z"]) == 0
    capsys.readouterr()
    code, out, _ = run_cli(capsys, mcap, "--json")
    assert code == 1
    doc = json.loads(out)
    assert doc["named_effects"] == ["servo_mismatch"]
    p = doc["steps"][0]["parameters"]
    mismatch = p["tau_y_ms"]["value"] - p["tau_x_ms"]["value"]
    u = p["tau_y_ms"]["u_value"] or p["tau_x_ms"]["u_value"]
    assert abs(mismatch - 4.0) < 3 * u
    assert max(doc["final_gap"].values()) < 1.3


@pytest.mark.parametrize(
    ("option", "target", "message"),
    [
        ("--plot", "nodir/gaps.png", "the folder"),
        ("--plot", "gaps.txt", "plot format (suffix) must be one of"),
        ("--plot", "afile", "got ''"),
        ("--model-out", "afile", "cannot create the model folder"),
        ("--model-out", "afile/model", "cannot create the model folder"),
    ],
)
def test_a_bad_output_is_one_line_before_the_work_and_damages_nothing(
    tmp_path, capsys, option, target, message
):
    path, _ = record(tmp_path, seed=7)
    (tmp_path / "afile").write_text("precious")
    code, out, err = run_cli(capsys, path, option, tmp_path / target)
    assert code == 2 and out == ""
    assert err.count("\n") == 1 and message in err and "Traceback" not in err
    assert (tmp_path / "afile").read_text() == "precious"
    assert "noise floor" not in err  # refused before the fit, not after it


def test_a_run_that_fails_leaves_no_model_folder_behind(tmp_path, capsys):
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(b"not an mcap file")
    model = tmp_path / "new" / "model"
    code, out, err = run_cli(capsys, bad, "--model-out", model)
    assert code == 2 and out == "" and err.count("\n") == 1
    assert not (tmp_path / "new").exists()


@pytest.mark.parametrize("target", ["link", "link/model"])
def test_a_model_folder_through_a_broken_link_is_refused_before_the_work(tmp_path, capsys, target):
    # The check walked up to the first existing folder and passed; making the folder
    # after the fit then raised FileExistsError as a traceback, and the fit was lost.
    path, _ = record(tmp_path, seed=7)
    (tmp_path / "link").symlink_to(tmp_path / "gone")
    code, out, err = run_cli(capsys, path, "--model-out", tmp_path / target)
    assert code == 2 and out == ""
    assert err.count("\n") == 1 and "Traceback" not in err
    assert "cannot create the model folder" in err and "gone" in err and "does not exist" in err
    assert "noise floor" not in err  # refused before the fit, not after it
    assert (tmp_path / "link").is_symlink() and not (tmp_path / "gone").exists()


def test_analyze_refuses_a_plot_in_a_missing_folder_before_the_work(tmp_path, capsys):
    path, _ = record(tmp_path, seed=7)
    code = main(["analyze", str(path), "--plot", str(tmp_path / "nodir" / "a.png")])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and "does not exist" in err


def test_a_two_feed_recording_is_refused_in_the_user_s_terms(tmp_path, capsys):
    program = TestProgram(
        radius_m=0.05, feeds_m_per_s=(0.05, 0.03), cycles_per_feed=(3, 2), dwell_s=1.0
    )
    path, _ = record(tmp_path, program=program, name="two.mcap")
    code, out, err = run_cli(capsys, path)
    assert code == 2 and out == "" and err.count("\n") == 1
    assert f"{path}: the program runs 2 feeds (3000, 1800 mm/min)" in err
    assert "period_s" not in err and "at_feed" not in err


def test_model_files_that_cannot_be_written_after_the_fit_are_one_line_and_exit_4(tmp_path):
    # a disk that fills during the fit: the folder passed the check, the files cannot be written
    import resource
    import signal
    import subprocess
    import sys

    path, _ = record(tmp_path, seed=7)

    def no_room():
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # a write past it fails with EFBIG
        resource.setrlimit(resource.RLIMIT_FSIZE, (0, 0))

    model = tmp_path / "model"
    argv = [sys.executable, "-m", "imu_square.cli", "discrepancy", str(path), "--model-out"]
    proc = subprocess.run(
        [*argv, str(model)], capture_output=True, text=True, timeout=300, preexec_fn=no_room
    )
    assert proc.returncode == 4, proc.stderr
    errors = [line for line in proc.stderr.splitlines() if "error" in line]
    assert errors == [
        f"imu-square discrepancy: error: {model}: writing the model files failed: File too large"
    ], proc.stderr
    assert "Traceback" not in proc.stderr


@pytest.mark.slow
def test_a_short_take_up_off_the_reversal_is_named_backlash_not_a_spike():
    """A take-up of 2.3 ms centred 2.7 ms after each reversal, about 4x its limit.

    The acceptance set's case (the paper's circle, 5 cycles each way, 7 ug/sqrt(Hz)
    at 500 Hz) that named reversal_spikes alone while the take-up's timing was
    scanned on two values only: a spike's free onset fitted it better than the
    nearest take-up. With the timing scanned as finely as the spike's the two
    explain it within the separation level: "one of" them, never the spike alone.
    """
    machine = MachineModel(
        backlash_x_m=0.027e-6,
        backlash_y_m=-0.030e-6,
        backlash_take_up_s=2.27e-3,
        backlash_onset=1.2,
    )
    sensor = replace(
        read_sensor(data_path("sensor_paper.toml")),
        sample_rate_hz=500.0,
        eps_c_rad=math.radians(-1.3),
    )
    program = TestProgram(cycles_per_direction=5)
    recording, _ = simulate_run(program, machine, sensor, seed=7)
    result = find_discrepancy(recording, DiscrepancyOptions(suggest=False))
    named = [(e,) for e in result.named_effects] + list(result.ambiguous)
    assert [set(g) for g in named] in ([{"backlash"}], [{"backlash", "reversal_spikes"}])
    (step,) = result.steps
    fitted = step.parameters if step.effect == "backlash" else step.alternatives["backlash"]
    values = {v.name: v for v in fitted}
    for name, truth in (("x_um", 0.027), ("y_um", -0.030)):
        assert abs(values[name].value - truth) < 3 * values[name].u_value, name


def test_the_spike_scan_tries_each_timing_in_its_own_form():
    # after and led: friction building up (skewed); centred: that, or a stick zone
    # (symmetric). The form rides on the timing's grid axis: 4 x 9 points, not 2 x 3 x 9.
    grid = _shape_grid(effect_model_parameters("reversal_spikes"), 200.0)
    assert len(grid) == 36
    forms = {(g["onset_tau"], g["symmetric"]) for g in grid}
    assert forms == {(0.0, 0.0), (-2.0, 0.0), (-2.0, 1.0), (-4.0, 0.0)}
    assert sorted({g["tau_ms"] for g in grid if g["symmetric"]}) == sorted(
        {g["tau_ms"] for g in grid}
    )


@pytest.mark.slow
def test_a_skewed_spike_centred_on_the_reversal_keeps_its_form():
    """A skewed spike 11.7 ms wide whose peak is on the reversal, 6.9x its limit.

    The acceptance set's case (the paper's circle, 5 cycles each way, 7 ug/sqrt(Hz)
    at 500 Hz): its width falls between two grid points, and the symmetric bump
    screens best. Held in the fit, that form left a gap a backlash was named for;
    the refit decides between the forms' best grid points.
    """
    machine = MachineModel(
        geometry=replace(MachineModel().geometry, machine_squareness_rad=-23.5e-6),
        spike_x_m_s2=4.39e-3,
        spike_y_m_s2=5.94e-3,
        spike_tau_s=11.74e-3,
        spike_onset=-2.0,
    )
    sensor = replace(
        read_sensor(data_path("sensor_paper.toml")),
        sample_rate_hz=500.0,
        eps_c_rad=math.radians(-1.95),
    )
    program = TestProgram(cycles_per_direction=5)
    recording, _ = simulate_run(program, machine, sensor, seed=1509013270)
    result = find_discrepancy(recording, DiscrepancyOptions(suggest=False))
    assert result.named_effects == ("reversal_spikes",) and result.explained, result.headline()
    (step,) = result.steps
    values = {v.name: v for v in step.parameters}
    assert values["symmetric"].value == 0.0
    for name, truth in (("peak_x_m_s2", 4.39e-3), ("peak_y_m_s2", 5.94e-3)):
        assert abs(values[name].value - truth) < 3 * values[name].u_value, name


def test_an_effect_dropped_and_added_again_is_named_once():
    # on our own set a 10x spike was added, dropped by the Wald test beside a backlash and
    # added again: the headline read "with reversal_spikes, backlash, reversal_spikes"
    from types import SimpleNamespace

    steps = [SimpleNamespace(effect=e) for e in ("reversal_spikes", "backlash", "reversal_spikes")]
    kept = steps_in_model(steps, {"reversal_spikes", "backlash"})
    assert kept == [steps[1], steps[2]]
    assert steps_in_model(steps, {"backlash"}) == [steps[1]]
