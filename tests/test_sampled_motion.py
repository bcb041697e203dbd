"""One code path for either motion: our own trajectory, sampled as a controller would, is
the same motion to the simulator and gives the same recording and result."""

import math

import numpy as np
import pytest
from numpy.testing import assert_allclose

from imu_square.errors import ControllerError
from imu_square.linuxcnc.samples import block_spans, parse_halsampler
from imu_square.pipeline.squareness import analyze
from imu_square.program import program_from_mapping
from imu_square.simulate import MachineModel, SensorModel, simulate_run
from imu_square.simulate.geometry import Geometry
from imu_square.simulate.sampled_motion import SampledMotion, ServoSamples
from imu_square.simulate.trajectory import build_timeline

PERIOD_S = 1e-3
PROGRAM = program_from_mapping(
    {
        "radius_mm": 25.0,
        "feed_mm_per_min": 9000.0,
        "cycles_per_direction": 6,
        "dwell_s": 1.0,
        "start_angle_deg": 30.0,
        "order": ["ccw", "cw", "cw", "ccw"],
    }
)
MACHINE = MachineModel(
    geometry=Geometry(machine_squareness_rad=40e-6),
    ramp_s=0.1,
    tau_x_s=2e-3,
    tau_y_s=2.5e-3,
    backlash_x_m=3e-6,
    spike_y_m_s2=0.02,
)
SENSOR = SensorModel(noise_density_m_s2_rthz=7e-6 * 9.80665, eps_c_rad=math.radians(2.1))
# Block 0 starts on this sample of our trajectory's samples.
LEAD_IN_SAMPLES = 500


def sampled(program, machine, marker_pad_s=0.2):
    """Our own trajectory sampled every servo period, with block markers around each block."""
    lead = LEAD_IN_SAMPLES * PERIOD_S
    timeline = build_timeline(program, machine.ramp_s, machine.ramp_profile, lead, 0.6)
    t = np.arange(math.floor(timeline.duration_s / PERIOD_S) + 1) * PERIOD_S
    xy = np.column_stack([timeline.axis_path(t, axis)[0] for axis in (0, 1)])
    markers = np.zeros(len(t), dtype=np.int64)
    for b in timeline.blocks:
        markers[t >= b.t_start_s - marker_pad_s] += 1
        markers[t >= b.t_end_s + marker_pad_s] += 1
    samples = ServoSamples(PERIOD_S, xy, markers, {"source": "test"})
    return samples, timeline


@pytest.fixture(scope="module")
def motions():
    samples, _ = sampled(PROGRAM, MACHINE)
    motion = SampledMotion(samples, PROGRAM, block_spans(samples.markers, PROGRAM.n_blocks))
    timeline = build_timeline(PROGRAM, MACHINE.ramp_s, MACHINE.ramp_profile, 3.0, 3.0)
    return motion, timeline


def test_blocks_are_found_where_our_trajectory_put_them(motions):
    motion, timeline = motions
    assert len(motion.blocks) == len(timeline.blocks) == 4
    for got, want in zip(motion.blocks, timeline.blocks, strict=True):
        assert (got.index, got.direction, got.sign) == (want.index, want.direction, want.sign)
        # starts and ends on servo samples: within one period
        assert got.t_start_s == pytest.approx(want.t_start_s, abs=PERIOD_S)
        assert got.t_end_s == pytest.approx(want.t_end_s, abs=PERIOD_S)
        # the analysed cycles begin after the ramp, where the angle is linear in time
        assert_allclose(got.analysed_window_s, want.analysed_window_s, atol=PERIOD_S / 10)
        assert got.omega_rad_s == pytest.approx(want.omega_rad_s, rel=1e-9)
        assert got.angle_rad == pytest.approx(want.angle_rad, abs=1e-9)
        assert math.remainder(got.start_angle_rad - want.start_angle_rad, 2 * math.pi) == (
            pytest.approx(0.0, abs=1e-9)
        )
        assert got.ramp_s == pytest.approx(0.99 * MACHINE.ramp_s, abs=2 * PERIOD_S)
    assert motion.duration_s == pytest.approx(timeline.duration_s, abs=PERIOD_S)
    assert motion.as_run(PROGRAM).feed_m_per_s == pytest.approx(0.15, rel=1e-9)


def test_path_between_samples_is_the_commanded_one(motions):
    motion, timeline = motions
    rng = np.random.default_rng(1)
    t = np.sort(rng.uniform(0.0, timeline.duration_s, 20000))
    edges = np.array([(b.t_start_s, b.t_start_s + MACHINE.ramp_s) for b in timeline.blocks])
    edges = np.concatenate([edges, edges + (timeline.blocks[0].duration_s - MACHINE.ramp_s)])
    # the trapezoid's acceleration steps at the ramp ends; the spline rounds a step
    # over a few servo periods (its error falls to 0.43 of itself a period)
    far = np.all(np.abs(t[:, None] - edges.ravel()[None, :]) > 0.015, axis=1)
    step = 0.025 * PROGRAM.omega_rad_s / MACHINE.ramp_s  # tangential acceleration [m/s^2]
    for axis in (0, 1):
        got = motion.axis_path(t, axis)
        want = timeline.axis_path(t, axis)
        assert_allclose(got[0], want[0], atol=1e-7)  # m
        assert_allclose(got[0][far], want[0][far], atol=1e-10)
        assert_allclose(got[1], want[1], atol=1e-3 * 0.15)  # m/s: 1e-3 of the feed
        assert_allclose(got[1][far], want[1][far], atol=1e-8)
        assert_allclose(got[2][far], want[2][far], atol=5e-5)  # m/s^2, of 0.9
        assert np.max(np.abs(got[2] - want[2])) < 0.5 * step


def test_reversals_are_those_of_our_trajectory(motions):
    motion, timeline = motions
    for axis in (0, 1):
        got_t, got_d, got_first = motion.reversals(axis)
        want_t, want_d, want_first = timeline.reversals(axis)
        assert got_first == want_first
        assert_allclose(got_d, want_d)
        # a block starts between two samples: its reversal is on the one before
        starts = np.isin(want_t, [b.t_start_s for b in timeline.blocks])
        assert_allclose(got_t[starts], want_t[starts], atol=PERIOD_S)
        assert_allclose(got_t[~starts], want_t[~starts], atol=2e-5)


def test_the_simulator_runs_either_motion_to_the_same_result(motions):
    motion, _ = motions
    ours, truth_ours = simulate_run(PROGRAM, MACHINE, SENSOR, seed=7)
    theirs, truth_theirs = simulate_run(PROGRAM, MACHINE, SENSOR, seed=7, motion=motion)
    assert truth_ours["motion"]["source"] == "imu-square trajectory"
    assert truth_theirs["motion"]["source"] == "test"
    assert truth_theirs["motion"]["feeds_run_mm_per_min"] == [pytest.approx(9000.0, rel=1e-9)]
    for key in ("expected_squareness_rad", "servo_mismatch_rad", "omega_rad_s"):
        assert truth_theirs[key] == pytest.approx(truth_ours[key], rel=1e-9)
    assert_allclose(
        [b["analysed_start_s"] for b in truth_theirs["blocks"]],
        [b["analysed_start_s"] for b in truth_ours["blocks"]],
        atol=PERIOD_S,
    )
    a, b = analyze(ours), analyze(theirs)
    # the same noise on both: the results differ by far less than their uncertainty
    assert b.squareness_rad == pytest.approx(a.squareness_rad, abs=0.02 * a.u_squareness_rad)
    # eps_c is anchored on the block starts, which the samples know to a servo period
    assert b.eps_c_rad == pytest.approx(a.eps_c_rad, abs=PERIOD_S * PROGRAM.omega_rad_s / 10)


def test_a_motion_of_another_program_is_refused(motions):
    motion, _ = motions
    other = program_from_mapping({**PROGRAM.to_mapping(), "dwell_s": 2.0})
    with pytest.raises(ControllerError, match="another program"):
        simulate_run(other, MACHINE, SENSOR, seed=1, motion=motion)


@pytest.mark.parametrize(
    ("change", "match"),
    [
        ({"radius_mm": 30.0}, r"leaves the circle of 30 mm by 5 mm: it ran another program"),
        ({"cycles_per_direction": 5}, r"ran 2520\.00 deg from 30\.00 deg, the program 2160\.00"),
        ({"start_angle_deg": 40.0}, r"from 30\.00 deg, the program .* from 40\.00 deg"),
        ({"order": ["cw", "ccw", "cw", "ccw"]}, r"ran -?\d+\.\d+ deg from"),
    ],
)
def test_blocks_that_do_not_match_the_program_are_refused(change, match):
    samples, _ = sampled(PROGRAM, MACHINE)
    other = program_from_mapping({**PROGRAM.to_mapping(), **change})
    with pytest.raises(ControllerError, match=match):
        SampledMotion(samples, other, block_spans(samples.markers, other.n_blocks))


def test_markers_must_count_two_per_block():
    samples, _ = sampled(PROGRAM, MACHINE)
    with pytest.raises(ControllerError, match=r"expected 10 \(one at the start and one at the end"):
        block_spans(samples.markers, 5)
    doubled = samples.markers.copy()
    doubled[doubled > 3] += 1
    with pytest.raises(ControllerError, match="block markers ran"):
        block_spans(doubled, 4)


def test_halsampler_output_is_read_and_lost_samples_refused():
    text = "0 1000.5 -2.25 0 \n1 1001.5 -2.5 1 \n2 1002.5 -2.75 1 \n3 10"
    xy, markers = parse_halsampler(text)
    assert_allclose(xy, [[1000.5e-6, -2.25e-6], [1001.5e-6, -2.5e-6], [1002.5e-6, -2.75e-6]])
    assert markers.tolist() == [0, 1, 1]
    with pytest.raises(ControllerError, match="FIFO overflowed: samples lost"):
        parse_halsampler("0 1 2 0\noverrun\n1 1 2 0\n")
    with pytest.raises(ControllerError, match="sample 3 follows sample 1: samples lost"):
        parse_halsampler("0 1 2 0\n1 1 2 0\n3 1 2 0\n")
    with pytest.raises(ControllerError, match="no samples"):
        parse_halsampler("")
