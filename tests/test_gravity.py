"""Gravity coupling separated with two feeds: split, joint fit, CLI, Monte Carlo.

The simulator's truth states, per feed, what theta_y - theta_x reads on the
circle (gravity coupling included, ``feeds[i].expected_squareness_rad``), and
what it reads freed of it (``expected_squareness_gravity_free_rad``); the
joint fit must find the second from runs that only see the first.
"""

import functools
import json
import math
from dataclasses import replace

import numpy as np
import pytest
from scipy import stats

from imu_square.cli import main
from imu_square.errors import AnalysisError
from imu_square.io.mcap import write_mcap
from imu_square.io.recording import SensorInfo
from imu_square.pipeline.feeds import split_feeds
from imu_square.pipeline.gravity import analyze_feeds, separate_gravity
from imu_square.pipeline.squareness import AnalysisOptions
from imu_square.program import TestProgram
from imu_square.simulate import Geometry, MachineModel, SensorModel, simulate_run
from imu_square.simulate.sensor_noise import sensor_noise
from imu_square.units import URAD

# The paper's circle (r = 100 mm) at 6000 and 3000 mm/min: v^2/r = 0.1 and 0.025
# m/s^2. The dwell (2 s) exceeds a tenth of the slow period (12.6 s), which the
# segmentation needs to see the blocks apart.
PROGRAM = TestProgram(radius_m=0.1, feeds_m_per_s=(0.1, 0.05), cycles_per_feed=(4, 3), dwell_s=2.0)
# 10 urad per 100 mm on each gradient: a gravity phase of 2.0 and 7.9 mrad at the two feeds
TILT = (1e-4, 1e-4, 1e-4, 1e-4)
MACHINE = MachineModel(
    geometry=Geometry(machine_squareness_rad=50e-6), tilt_per_m=TILT, tau_x_s=2e-3, tau_y_s=2.5e-3
)
LOW_NOISE = 1e-7  # m/s^2/sqrt(Hz): a noise floor of 0.3 urad after the separation
SENSOR = SensorModel(
    sample_rate_hz=200.0,
    noise_density_m_s2_rthz=LOW_NOISE,
    eps_c_rad=math.radians(2.1),
    beta_rad=20e-6,
)
OPTIONS = AnalysisOptions(bootstrap_n=0)


@functools.cache
def two_feed_run(events=True, program=PROGRAM, seed=1):
    return simulate_run(program, MACHINE, SENSOR, seed=seed, events=events)


@pytest.mark.parametrize("events", [True, False])
def test_split_cuts_in_the_rest_between_the_feeds(events):
    rec, truth = two_feed_run(events)
    parts = split_feeds(rec, options=OPTIONS)
    assert [p.feed for p in parts] == [0, 1]
    assert [p.feed_mm_per_min for p in parts] == pytest.approx([6000.0, 3000.0])
    # the cut lies in the dwell between the last fast block and the first slow one
    end_fast, start_slow = truth["blocks"][1]["end_s"], truth["blocks"][2]["start_s"]
    cut = parts[1].recording.time_s[0] + ((parts[1].recording.time_ns[0] - rec.time_ns[0]) * 1e-9)
    assert end_fast < cut < start_slow
    assert parts[0].recording.n_samples + parts[1].recording.n_samples == rec.n_samples
    for p in parts:
        assert p.recording.program == p.program == PROGRAM.at_feed(p.feed)
        blocks = sorted({e.block for e in p.recording.events if e.kind == "block_start"})
        assert blocks == ([0, 1] if events else [])
        assert "split_feeds: feed" in p.recording.processing[-1]


def test_split_refuses_a_missing_feed():
    one, _ = simulate_run(PROGRAM.at_feed(0), MACHINE, SENSOR, seed=2, events=False)
    with pytest.raises(
        AnalysisError, match=r"no motion at 3000 mm/min: the program runs 6000, 3000"
    ):
        split_feeds(one, program=PROGRAM, options=OPTIONS)


def check_separation(sep, truth, tol_urad=1.0):
    """The acceptance: squareness freed of gravity within tol_urad; kappa and phases right."""
    free = truth["expected_squareness_gravity_free_rad"]
    assert abs(sep.squareness_rad - free) < tol_urad * URAD
    assert abs(sep.squareness_rad - free) < 4 * sep.u_squareness_rad + 0.2 * URAD
    # kappa's uncertainty is the squareness's over g r / A: a few 1e-3 urad/m here
    kappa = truth["gravity_coupling_rad_per_m"]
    assert sep.gravity_coupling_rad_per_m == pytest.approx(kappa, abs=0.05 * URAD)
    for f, g in zip(sep.feeds, sep.gravity_phase_rad, strict=True):
        (ft,) = (t for t in truth["feeds"] if t["feed_mm_per_min"] == f.feed_mm_per_min)
        expected = ft["expected_squareness_rad"] - free
        assert expected > 1900 * URAD  # the plain result is off by mrad
        assert g == pytest.approx(expected, abs=2 * URAD)


def test_joint_fit_frees_the_squareness_of_gravity_coupling():
    rec, truth = two_feed_run()
    feeds = analyze_feeds([("run", rec)], OPTIONS)
    for f, ft in zip(feeds, truth["feeds"], strict=True):
        plain_error = f.result.squareness_rad - ft["expected_squareness_rad"]
        assert abs(plain_error) < 4 * f.result.u_squareness_rad + 0.2 * URAD
    sep = separate_gravity(feeds)
    check_separation(sep, truth)
    # first-order weights A_i / (A_1 - A_2): 4/3 and -1/3
    assert sep.weights == pytest.approx((4 / 3, -1 / 3), rel=1e-3)
    u = [f.result.u_squareness_rad for f in feeds]
    assert sep.u_squareness_rad == pytest.approx(math.hypot(4 / 3 * u[0], u[1] / 3), rel=1e-3)
    assert sep.separation_cost > 1
    assert math.isnan(sep.residual_chi2)


def test_one_recording_per_feed_gives_the_same():
    _, truth = two_feed_run()
    sources = []
    for f in range(2):
        rec, _ = simulate_run(PROGRAM.at_feed(f), MACHINE, SENSOR, seed=10 + f)
        sources.append((f"feed{f}.mcap", rec))
    sep = separate_gravity(analyze_feeds(sources, OPTIONS))
    check_separation(sep, truth)
    assert [f.source for f in sep.feeds] == ["feed0.mcap", "feed1.mcap"]


def test_three_feeds_check_the_model():
    program = TestProgram(
        radius_m=0.1, feeds_m_per_s=(0.1, 0.07, 0.05), cycles_per_feed=(4, 3, 3), dwell_s=2.0
    )
    rec, truth = simulate_run(program, MACHINE, SENSOR, seed=4)
    sep = separate_gravity(analyze_feeds([("run", rec)], OPTIONS))
    check_separation(sep, truth)
    # chi^2 on one degree of freedom: below its 99.9 % quantile
    assert 0 <= sep.residual_chi2 < stats.chi2.ppf(0.999, 1)
    assert sum(sep.weights) == pytest.approx(1.0, rel=1e-12)


def test_refusals_name_what_is_wrong():
    rec, _ = two_feed_run()
    feeds = analyze_feeds([("run", rec)], OPTIONS)
    with pytest.raises(AnalysisError, match=r"needs the same circle at two feeds or more.*6000"):
        separate_gravity(feeds[:1])
    other = replace(feeds[1], program=replace(feeds[1].program, radius_m=0.05), source="b")
    with pytest.raises(AnalysisError, match=r"the same circle: run has r = 100 mm .* b r = 50 mm"):
        separate_gravity([feeds[0], other])
    with pytest.raises(AnalysisError, match=r"must differ by at least 10%"):
        separate_gravity([feeds[0], replace(feeds[0], source="again")])


def write_run(path, rec, truth):
    write_mcap(rec, path)
    path.with_name(path.stem + ".truth.json").write_text(json.dumps(truth))


def test_cli_separates_gravity_from_one_or_two_files(tmp_path, capsys):
    rec, truth = two_feed_run()
    both = tmp_path / "both.mcap"
    write_run(both, rec, truth)
    assert main(["analyze", str(both), "--separate-gravity", "--json", "--bootstrap", "0"]) == 0
    out = capsys.readouterr()
    doc = json.loads(out.out)
    free = truth["expected_squareness_gravity_free_rad"] / URAD
    assert abs(doc["squareness_urad"] - free) < 1.0
    assert doc["gravity_coupling_urad_per_m"] == pytest.approx(
        truth["gravity_coupling_rad_per_m"] / URAD, abs=0.05
    )
    assert doc["recordings"] == [str(both)]
    assert [f["feed_mm_per_min"] for f in doc["feeds"]] == [6000.0, 3000.0]
    for f, ft in zip(doc["feeds"], truth["feeds"], strict=True):
        assert abs(f["squareness_urad"] - ft["expected_squareness_rad"] / URAD) < 2.0
        assert f["recording"] == str(both)
    assert "freed of gravity coupling" in out.err and "at 3000 mm/min" in out.err

    files = []
    for f in range(2):
        part, part_truth = simulate_run(PROGRAM.at_feed(f), MACHINE, SENSOR, seed=20 + f)
        files.append(tmp_path / f"feed{f}.mcap")
        write_run(files[-1], part, part_truth)
    argv = ["analyze", *map(str, files), "--separate-gravity", "--json", "--bootstrap", "0"]
    assert main(argv) == 0
    doc = json.loads(capsys.readouterr().out)
    assert abs(doc["squareness_urad"] - free) < 1.0
    assert [f["recording"] for f in doc["feeds"]] == [str(p) for p in files]


def test_cli_refuses_two_feeds_without_the_flag_and_one_feed_with_it(tmp_path, capsys):
    rec, truth = two_feed_run()
    both = tmp_path / "both.mcap"
    write_run(both, rec, truth)
    assert main(["analyze", str(both)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [
        f"imu-square analyze: error: {both}: the program runs 2 feeds (6000, 3000 mm/min): "
        "analyse it with --separate-gravity, which also reports each feed's plain result"
    ]
    one, one_truth = simulate_run(PROGRAM.at_feed(0), MACHINE, SENSOR, seed=5)
    path = tmp_path / "one.mcap"
    write_run(path, one, one_truth)
    assert main(["analyze", str(path), "--separate-gravity"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    # refused from the program, before any feed is analysed: one line, no result
    assert len(err) == 1, err
    assert err[0].startswith("imu-square analyze: error: separating gravity coupling")
    assert "needs the same circle at two feeds or more" in err[0] and "got 6000 mm/min" in err[0]
    other = TestProgram(radius_m=0.05, feeds_m_per_s=(0.05,), cycles_per_feed=(3,), dwell_s=2.0)
    part, part_truth = simulate_run(other, MACHINE, SENSOR, seed=6)
    small = tmp_path / "small.mcap"
    write_run(small, part, part_truth)
    assert main(["analyze", str(path), str(small), "--separate-gravity"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "the feeds must run the same circle" in err[0], err


@pytest.mark.slow
def test_uncertainty_matches_the_closed_form_over_seeds():
    """Monte Carlo: the spread of the separated squareness over seeds is the closed form's.

    The closed form propagates each feed's Cramér-Rao bound ``sqrt(2) d / (A
    sqrt(T))`` through the weights; the estimator's efficiency (bound over
    standard deviation, squared) is near 1, so the ratio of the sample standard
    deviation over n seeds to the bound lies in the chi-square interval of n - 1
    degrees of freedom (two-sided 0.1 %), widened by the efficiency range
    [0.85, 1].
    """
    n = 24
    d = 6.86e-5  # the paper's sensor, 7 ug/sqrt(Hz)
    quiet = replace(SENSOR, noise_density_m_s2_rthz=0.0)
    base, truth = simulate_run(PROGRAM, MACHINE, quiet, seed=0)
    free = truth["expected_squareness_gravity_free_rad"]
    errors, bounds, us = [], [], []
    for seed in range(n):
        rng = np.random.default_rng(100 + seed)
        noise = sensor_noise(base.n_samples, base.sample_rate_hz, d, 0.0, rng)
        rec = replace(
            base,
            accel=base.accel + noise,
            sensor=SensorInfo(noise_density_m_s2_rthz=d),
        )
        sep = separate_gravity(analyze_feeds([("run", rec)], OPTIONS))
        errors.append(sep.squareness_rad - free)
        bounds.append(sep.crb_rad)
        us.append(sep.u_squareness_rad)
    errors = np.array(errors)
    bound = float(np.mean(bounds))
    lo = math.sqrt(stats.chi2.ppf(0.0005, n - 1) / (n - 1))
    hi = math.sqrt(stats.chi2.ppf(0.9995, n - 1) / (n - 1)) / math.sqrt(0.85)
    ratio = float(np.std(errors, ddof=1)) / bound
    assert lo < ratio < hi, ratio
    # unbiased: the mean error within 3.5 standard errors (plus the low-noise bias bound)
    assert abs(np.mean(errors)) < 3.5 * np.std(errors, ddof=1) / math.sqrt(n) + 1 * URAD
    # the reported type A uncertainty agrees with the spread on average
    assert float(np.sqrt(np.mean(np.square(us)))) == pytest.approx(np.std(errors, ddof=1), rel=0.5)


def test_cli_refuses_one_run_given_twice(tmp_path, capsys):
    # the same two-feed run twice (or a copy of it) would count each feed twice and
    # report an uncertainty sqrt(2) too small
    rec, truth = two_feed_run()
    both = tmp_path / "both.mcap"
    write_run(both, rec, truth)
    copy = tmp_path / "copy.mcap"
    copy.write_bytes(both.read_bytes())
    for second in (both, copy):
        assert main(["analyze", str(both), str(second), "--separate-gravity"]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and "hold the same samples" in err, err
        assert f"{both} and {second}" in err
