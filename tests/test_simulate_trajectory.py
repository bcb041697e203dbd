"""The commanded timeline: axis reversals on blocks that start or end on a
reversal angle, and ramps that do not fit in a block.

A block whose start or end angle is a multiple of 90 degrees lands exactly on
an axis reversal angle (X at k*pi, Y at pi/2 + k*pi); rounding must not count
it as a crossing inside the block. The reference is the commanded velocity
itself: the number of its sign changes on a fine grid.
"""

import contextlib
import math

import numpy as np
import pytest

from imu_square.errors import ConfigError, ImuSquareWarning
from imu_square.program import TestProgram
from imu_square.simulate import MachineModel, SensorModel, simulate_run, with_effects
from imu_square.simulate.trajectory import build_timeline

RAMP_S = 0.05
# omega = 10 rad/s: a ramp covers 0.25 rad, more than a zero overshoot
SWEEP = [
    (start, overshoot, order)
    for start in range(-720, 721, 90)
    for overshoot in (0, 90, 180, 270)
    for order in (("ccw", "cw"), ("cw", "ccw"))
]


def sign_changes(v):
    """Sign changes of a sampled velocity, ignoring the samples at rest."""
    s = np.sign(v[np.abs(v) > 1e-12])
    return int(np.count_nonzero(np.diff(s)))


def sweep_timeline(start, overshoot, order):
    program = TestProgram(
        radius_m=0.1,
        feed_m_per_s=1.0,
        cycles_per_direction=2,
        dwell_s=0.1,
        start_angle_rad=math.radians(start),
        overshoot_rad=math.radians(overshoot),
        order=order,
    )
    warns = (
        pytest.warns(ImuSquareWarning, match=r"feed ramps reach into the analysed cycles")
        if overshoot == 0
        else contextlib.nullcontext()
    )
    with warns:
        return build_timeline(program, RAMP_S, "trapezoid", 0.1, 0.1)


def test_reversal_count_equals_sign_changes_of_commanded_velocity():
    """All 272 cases: start -720..720 step 90 x overshoot 0/90/180/270 x order x axis."""
    mismatches = []
    for start, overshoot, order in SWEEP:
        timeline = sweep_timeline(start, overshoot, order)
        t = np.arange(0.0, timeline.duration_s, 2e-4)
        for axis in (0, 1):
            times, directions, initial = timeline.reversals(axis)
            _, v, _ = timeline.axis_path(t, axis)
            if len(times) != sign_changes(v):
                mismatches.append((start, overshoot, order[0], axis, len(times), sign_changes(v)))
            # the first motion and every reversal alternate direction
            assert np.all(np.diff([initial, *directions]) != 0)
    assert mismatches == []


def test_block_ending_on_a_reversal_angle_adds_no_reversal_after_it():
    """Start 270, overshoot 180: Y's last reversal used to be the end of the last block."""
    program = TestProgram(
        radius_m=0.1,
        feed_m_per_s=0.1,
        cycles_per_direction=2,
        overshoot_rad=math.pi,
        start_angle_rad=math.radians(270.0),
    )
    machine, sensor = with_effects(["reversal_spikes"], None, SensorModel(sample_rate_hz=200.0))
    recording, truth = simulate_run(program, machine, sensor, seed=0, lead_out_s=1.0)
    end = truth["blocks"][-1]["end_s"]
    assert all(t < end for t in truth["reversal_times_s"]["y"])
    t = recording.time_s - recording.time_s[0]
    # after the motion (and the 0.5 ms spike time constant's tail) the table is at rest
    assert np.abs(recording.accel[t > end + 0.05, :2]).max() == 0.0


def test_backlash_run_starting_on_a_reversal_angle_does_not_crash():
    """Start 90, overshoot 270, CW first: the crossing at the block end exceeded the
    block angle by one ulp and the ramp inverse took a square root of a negative."""
    program = TestProgram(
        radius_m=0.1,
        feed_m_per_s=1.0,
        cycles_per_direction=2,
        overshoot_rad=math.radians(270.0),
        start_angle_rad=math.radians(90.0),
        order=("cw", "ccw"),
    )
    machine, sensor = with_effects(["backlash"], None, SensorModel(sample_rate_hz=200.0))
    _, truth = simulate_run(program, machine, sensor, seed=0, lead_in_s=0.5, lead_out_s=0.5)
    n_y = len(truth["reversal_times_s"]["y"])
    timeline = build_timeline(program, machine.ramp_s, machine.ramp_profile, 0.5, 0.5)
    _, v, _ = timeline.axis_path(np.arange(0.0, timeline.duration_s, 2e-4), 1)
    assert n_y == sign_changes(v)


def test_ramps_longer_than_the_block_are_refused():
    # r = 20 mm at 0.6 m/s: omega = 30 rad/s, a 720 deg block lasts 0.419 s
    program = TestProgram(
        radius_m=0.02, feed_m_per_s=0.6, cycles_per_direction=2, overshoot_rad=0.0
    )
    with pytest.raises(
        ConfigError, match=r"ramp_s = 1\.0 s is longer than the block duration 0\.418879 s"
    ):
        simulate_run(program, MachineModel(ramp_s=1.0), SensorModel(sample_rate_hz=200.0))


def test_ramps_reaching_into_the_analysed_cycles_warn():
    # 0.15 s ramps at 5 rad/s cover 0.375 rad = 21.5 deg, more than 10 deg of overshoot
    program = TestProgram(
        radius_m=0.02, feed_m_per_s=0.1, cycles_per_direction=2, overshoot_rad=math.radians(10)
    )
    with pytest.warns(ImuSquareWarning, match=r"covers 21\.49 deg of arc, more than .* 10 deg"):
        build_timeline(program, 0.15, "trapezoid", 0.1, 0.1)
    # the paper's test: 0.15 s at 1 rad/s = 4.3 deg, inside the 180 deg overshoot
    build_timeline(TestProgram(), 0.15, "trapezoid", 0.1, 0.1)
