"""Segmentation on closed-form signals: blocks, direction, frequency, refusals."""

from dataclasses import replace

import numpy as np
import pytest
from numpy.testing import assert_allclose
from pipeline_synth import synth_circle

from imu_square.errors import AnalysisError
from imu_square.pipeline.filter import lowpass
from imu_square.pipeline.segment import segment
from imu_square.program import TestProgram

PROG = TestProgram(cycles_per_direction=3, dwell_s=1.0)


def _segment(rec, program=None, events=()):
    xy = lowpass(rec.accel[:, :2], 4.0, 1, rec.sample_rate_hz)
    return segment(rec.time_s, xy, program or rec.program, events)


@pytest.mark.parametrize("ramp_s", [0.05, 0.5, 1.0])
def test_blocks_found_with_their_midpoints(ramp_s):
    rec, truth = synth_circle(PROG, ramp_s=ramp_s, fs=500.0, density=7e-5, lead_s=2.0)
    seg = _segment(rec)
    assert [b.direction for b in seg.blocks] == ["ccw", "cw"]
    for block, tb in zip(seg.blocks, truth["blocks"], strict=True):
        # Mirrored ramps: the midpoint is exact up to noise and the sampling grid.
        assert abs(block.t_mid_s - 0.5 * (tb["t0"] + tb["t1"])) < max(2e-3, 4 * block.u_t_mid_s)
        assert np.sign(block.omega_rad_s) == block.sign
        assert 0 < block.u_t_mid_s < 2e-2
    # Phase slope over 3 cycles with this noise: ~2e-5 relative.
    assert_allclose(seg.omega_rad_s, PROG.omega_rad_s, rtol=1e-4)
    assert abs(seg.period_disagreement) < 1e-4


def test_period_disagreement_from_a_feed_override():
    # The machine runs 3 % slower than programmed: the data say so.
    run = replace(PROG, feed_m_per_s=PROG.feed_m_per_s * 0.97)
    rec, _ = synth_circle(run, fs=200.0)
    seg = _segment(rec, PROG)
    assert_allclose(seg.period_disagreement, 1 / 0.97 - 1, rtol=1e-4)


def test_events_pick_the_blocks_among_extra_motion():
    # Three blocks ran (ccw, cw, ccw), the program has two: the markers say which.
    three = replace(PROG, order=("ccw", "cw", "ccw"))
    rec, truth = synth_circle(three, fs=200.0, events=True)
    events = [
        ((e.time_ns - rec.time_ns[0]) * 1e-9, e.kind, e.block - 1)
        for e in rec.events
        if e.block >= 1
    ]
    later = replace(PROG, order=("cw", "ccw"), start_angle_rad=three.blocks()[1].start_angle_rad)
    seg = _segment(rec, later, events)
    tb = truth["blocks"][1]
    assert abs(seg.blocks[0].t_mid_s - 0.5 * (tb["t0"] + tb["t1"])) < 5e-3


def test_without_events_extra_motion_is_matched_by_spacing():
    three = replace(PROG, order=("ccw", "cw", "ccw"))
    rec, truth = synth_circle(three, fs=200.0)
    seg = _segment(rec, PROG)
    mids = [0.5 * (tb["t0"] + tb["t1"]) for tb in truth["blocks"][:2]]
    assert_allclose([b.t_mid_s for b in seg.blocks], mids, atol=5e-3)


def test_ellipse_is_not_a_circle():
    rec, _ = synth_circle(PROG, fs=200.0, density=7e-5)
    squashed = rec.accel.copy()
    squashed[:, 1] *= 0.3  # a = (A cos, 0.3 A sin): magnitude varies by ~40 % rms
    with pytest.raises(AnalysisError, match=r"block 0 \(ccw\) is not a circle: .* varies by"):
        _segment(replace(rec, accel=squashed))


def test_wrong_direction_is_refused():
    rec, _ = synth_circle(PROG, fs=200.0)
    reversed_order = replace(PROG, order=("cw", "ccw"))
    with pytest.raises(AnalysisError, match=r"block 0 should run cw but the data turn counter"):
        _segment(rec, reversed_order)


def test_no_motion_is_refused():
    rec, _ = synth_circle(PROG, fs=200.0, density=7e-5)
    idle = replace(rec, accel=np.column_stack([rec.accel[:, :2] * 0 + 1e-3, rec.accel[:, 2]]))
    with pytest.raises(AnalysisError, match=r"^no motion: .* the table did not move"):
        _segment(idle)


def test_back_and_forth_line_is_not_a_circle():
    rec, _ = synth_circle(PROG, fs=200.0, density=7e-5)
    line = rec.accel.copy()
    line[:, 1] = 0.0  # only x moves: the acceleration vector flips, never turns
    with pytest.raises(AnalysisError, match=r"no circular motion matching the program"):
        _segment(replace(rec, accel=line))


def test_block_cut_by_the_end_of_the_recording_is_refused():
    rec, truth = synth_circle(PROG, fs=200.0, lead_s=1.0)
    stop = int((truth["blocks"][1]["t1"] - 0.5) * 200)
    cut = replace(rec, accel=rec.accel[:stop], time_ns=rec.time_ns[:stop], seq=rec.seq[:stop])
    with pytest.raises(AnalysisError, match=r"block 1 \(cw\) is cut off by the end"):
        _segment(cut)


def test_speed_is_unbiased_when_the_circle_is_off_the_rest_level():
    # Gravity coupling k_xx = 1e-4 rad/m on r = 100 mm at 0.025 m/s^2: at rest on the
    # start point (phi = 0) the x channel reads g k r = 1e-4 m/s^2 more than the circle's
    # centre, 0.4 % of v^2/r, so the acceleration vector taken about the rest level turns
    # unevenly at omega. Fitted without that ripple, the speed came out 33 ppm slow.
    from imu_square.simulate import MachineModel, SensorModel, simulate_run

    program = TestProgram(radius_m=0.1, feed_m_per_s=0.05, cycles_per_direction=3, dwell_s=2.0)
    machine = MachineModel(tilt_per_m=(1e-4, 0.0, 0.0, 0.0))
    sensor = SensorModel(sample_rate_hz=200.0, noise_density_m_s2_rthz=1e-7)
    rec, _ = simulate_run(program, machine, sensor, seed=0, events=False)
    seg = _segment(rec, program)
    assert_allclose(seg.omega_rad_s, program.omega_rad_s, rtol=3e-6)


def test_a_table_at_rest_is_no_motion_not_a_long_interval():
    # Only noise: the envelope's highest level is the noise's, far below v^2/r. It used
    # to read "found 1 motion interval(s) ... the longest 19.4 s".
    rec, _ = synth_circle(PROG, fs=200.0, density=7e-5)
    rng = np.random.default_rng(3)
    rest = rec.accel.copy()
    rest[:, :2] = 7e-5 * 9.81 * np.sqrt(100.0) * rng.standard_normal((rec.n_samples, 2))
    with pytest.raises(AnalysisError, match=r"^no motion: .* v\^2/r = 0\.1 m/s\^2: the table did"):
        _segment(replace(rec, accel=rest))
