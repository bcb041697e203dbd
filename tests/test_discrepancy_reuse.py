"""What the nightly diagnostic fit takes again instead of recomputing equals the recomputation.

A short circle (50 mm at 3000 mm/min, 4 cycles each way, 200 Hz) of a machine
with a servo mismatch, a backlash and friction spikes: the base model's fit
leaves them in its residual, as on a real night.
"""

import math

import numpy as np
import pytest
from numpy.testing import assert_allclose

from imu_square.discrepancy.diagnose import _held_shapes, _identifiable
from imu_square.discrepancy.workflow import fit_base
from imu_square.monitor.diagnostics.catalog import DEFAULT_EFFECTS
from imu_square.program import TestProgram
from imu_square.simulate import MachineModel, SensorModel, simulate_run
from imu_square.units import UG

PROGRAM = TestProgram(radius_m=0.05, feed_m_per_s=0.05, cycles_per_direction=4, dwell_s=1.0)
SENSOR = SensorModel(
    model="test", sample_rate_hz=200.0, noise_density_m_s2_rthz=7 * UG, eps_c_rad=math.radians(2.1)
)
MACHINE = MachineModel(tau_x_s=2e-3, tau_y_s=2.6e-3, backlash_x_m=3e-6, spike_y_m_s2=0.01)
# shapes that do most to the model when their sizes are not zero: a first-order servo,
# the yaw of both straightnesses, a spike and a backlash leading their reversals
SHAPES = {
    "servo_mismatch": {"first_order": 1.0},
    "backlash": {"take_up_ms": 2.0, "onset": 3.0},
    "reversal_spikes": {"tau_ms": 8.0, "onset_tau": -2.0},
    "straightness_yaw": {"yaw_x": 1.0, "yaw_y": 1.0},
    "structural_vibration": {"frequency_hz": 25.0, "damping_ratio": 0.1},
}


@pytest.fixture(scope="module")
def base_fit():
    recording, _ = simulate_run(PROGRAM, MACHINE, SENSOR, seed=5)
    return fit_base(recording, PROGRAM)


@pytest.mark.parametrize("shapes", [{}, SHAPES], ids=["typical shapes", "other shapes"])
def test_the_screen_takes_the_base_models_derivatives_which_the_held_shapes_leave(base_fit, shapes):
    problem, base, params = base_fit
    sizes, held = _held_shapes(DEFAULT_EFFECTS, shapes)
    start = base.state
    for p, value in held.items():
        start = p.set(start, value)
    # the reference: the base parameters' derivatives taken again with the shapes held
    again = np.column_stack([problem.space.fit_vector(c) for c in problem.columns(start, params)])
    scale = np.abs(again).max(axis=0)
    assert_allclose(base.jacobian / scale, again / scale, rtol=0, atol=1e-12)
    _, jac = _identifiable(problem, start, base, sizes)
    assert_allclose(jac[:, : len(params)], base.jacobian, rtol=0, atol=0)


def test_a_jacobians_state_outlasts_its_columns(base_fit):
    problem, base, params = base_fit
    problem.samples(base.state)
    runs = problem.model.evaluations
    problem.columns(base.state, params)  # more columns than the problem keeps states
    problem.samples(base.state)  # as the next step's residual asks
    assert problem.model.evaluations == runs + len(params)
