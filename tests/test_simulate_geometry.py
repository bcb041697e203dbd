"""The geometric error map reproduces Chapman's Appendix I and his machines 1-5."""

import math

import numpy as np
import pytest
from numpy.testing import assert_allclose

from imu_square.errors import ConfigError
from imu_square.simulate import Geometry, chapman_machine
from imu_square.units import UM


def test_equation_1_bow_is_s_at_the_travel_ends():
    g = chapman_machine(2)
    dx, dy = g.deviation(np.array([-0.4, 0.0, 0.2, 0.4]), np.zeros(4))
    # Eq. 1: dy = 4 S x^2 / L^2 with S = 10 um, L = 800 mm
    assert_allclose(dy, [10 * UM, 0.0, 2.5 * UM, 10 * UM], rtol=1e-12, atol=1e-18)
    assert_allclose(dx, 0.0, atol=1e-18)


def test_equation_2_and_3_with_associated_yaw():
    g = chapman_machine(3)
    x, y = 0.2, 0.3
    dx, dy = g.deviation(x, y)
    # Eq. 2: dx = -y (theta0 + 8 S x / L^2) = -0.3 (15 + 25) um/m
    assert_allclose(dx, -0.3 * (15 * UM + 8 * 10 * UM * 0.2 / 0.64), rtol=1e-12)
    assert_allclose(dx, -12 * UM, rtol=1e-12)
    # Eq. 3: the Y component is Eq. 1
    assert_allclose(dy, 4 * 10 * UM * 0.2**2 / 0.64, rtol=1e-12)


def test_equation_4_without_yaw():
    g = chapman_machine(2)
    dx, dy = g.deviation(0.2, 0.3)
    assert_allclose(dx, -0.3 * 15 * UM, rtol=1e-12)
    assert_allclose(dy, 2.5 * UM, rtol=1e-12)


def test_y_axis_terms_by_symmetry():
    g = chapman_machine(5)
    dx, dy = g.deviation(0.0, 0.4)
    # bow of the Y axis in X: 4 S y^2 / L^2 = S at the end of the travel, plus -y alpha
    assert_allclose(dx, 10 * UM - 0.4 * 15 * UM, rtol=1e-12)
    assert_allclose(dy, 0.0, atol=1e-18)
    _, dy = g.deviation(0.1, 0.4)
    # associated yaw of Y turns X clockwise: dy = -x 8 S y / L^2 (+ X bow 4 S x^2/L^2)
    assert_allclose(dy, -0.1 * 8 * 10 * UM * 0.4 / 0.64 + 4 * 10 * UM * 0.01 / 0.64, rtol=1e-12)


def test_machine_3_axis_angle_goes_from_minus_35_to_plus_65():
    g = chapman_machine(3)
    assert_allclose(g.axis_angle_y_to_x(np.array([-0.4, 0.0, 0.4])), [-35e-6, 15e-6, 65e-6])


@pytest.mark.parametrize("n", [1, 3, 5])
def test_local_squareness_is_uniform_for_machines_without_bare_straightness(n):
    """Chapman: machines 1, 3 and 5 give 15 um/m at every test location."""
    g = chapman_machine(n)
    x, y = np.meshgrid(np.linspace(-0.3, 0.3, 7), np.linspace(-0.3, 0.3, 7))
    assert_allclose(g.local_machine_squareness(x, y), 15e-6, rtol=1e-12)


def test_machine_2_local_squareness_varies_along_x():
    g = chapman_machine(2)
    # the X axis tilts by 8 S x / L^2 while Y stays put: 15 - 125 um/m/m * x
    assert_allclose(
        g.local_machine_squareness(np.array([-0.4, 0.0, 0.4]), 0.0),
        [65e-6, 15e-6, -35e-6],
        rtol=1e-12,
    )


def ballbar_squareness(g, centre, radius, t=0.0):
    """Least-squares fit of the actual circle's radial deviation; -2 (sin 2phi term) / r.

    The radial deviation is linearised (``dx cos + dy sin``), as ballbar
    software does; the exact radius adds (tangential deviation)^2 / 2r, a
    1e-8 rad effect for 10 um errors on a 150 mm circle.
    """
    phi = np.linspace(0, 2 * math.pi, 720, endpoint=False)
    x = centre[0] + radius * np.cos(phi)
    y = centre[1] + radius * np.sin(phi)
    dx, dy = g.deviation(x, y, t)
    dr = dx * np.cos(phi) + dy * np.sin(phi)
    design = np.column_stack(
        [np.ones_like(phi), np.cos(phi), np.sin(phi), np.cos(2 * phi), np.sin(2 * phi)]
    )
    coef, *_ = np.linalg.lstsq(design, dr, rcond=None)
    return -2 * coef[4] / radius


@pytest.mark.parametrize("n", [1, 2, 3, 4, 5])
@pytest.mark.parametrize("centre", [(0.0, 0.0), (0.25, -0.15), (-0.2, 0.3)])
def test_ballbar_fit_of_actual_path_equals_local_squareness(n, centre):
    g = chapman_machine(n)
    expected = g.local_machine_squareness(*centre)
    assert_allclose(ballbar_squareness(g, centre, 0.15), expected, rtol=1e-9, atol=1e-15)


def test_squareness_drift_and_scale():
    g = Geometry(
        machine_squareness_rad=10e-6,
        machine_squareness_rate_rad_s=1e-8,
        scale_x=20e-6,
        scale_y=-5e-6,
    )
    dx, dy = g.deviation(0.1, 0.2, t=100.0)
    assert_allclose(dx, 20e-6 * 0.1 - 0.2 * (10e-6 + 1e-6), rtol=1e-12)
    assert_allclose(dy, -5e-6 * 0.2, rtol=1e-12)
    assert_allclose(g.local_machine_squareness(0.0, 0.0, t=100.0), 11e-6, rtol=1e-12)


def test_axis_centre_moves_chapman_origin():
    g = Geometry(straightness_x_m=10e-6, axis_centre_m=(0.4, 0.0))
    _, dy = g.deviation(np.array([0.0, 0.4, 0.8]), 0.0)
    assert_allclose(dy, [10e-6, 0.0, 10e-6], rtol=1e-12, atol=1e-20)


def test_apply_position_matches_deviation():
    g = chapman_machine(5)
    rng = np.random.default_rng(1)
    x, y, t = rng.uniform(-0.4, 0.4, 50), rng.uniform(-0.4, 0.4, 50), rng.uniform(0, 1e3, 50)
    zeros = np.zeros(50)
    pos, vel, acc = g.apply((x, zeros, zeros), (y, zeros, zeros), t)
    dx, dy = g.deviation(x, y, t)
    assert_allclose(pos, np.column_stack([x + dx, y + dy]), rtol=0, atol=1e-16)
    assert_allclose(vel, 0.0, atol=0)
    assert_allclose(acc, 0.0, atol=0)


def test_chapman_machine_number_is_checked():
    with pytest.raises(
        ConfigError, match=r"chapman_machine n must be one of \(1, 2, 3, 4, 5, 6, 7\), got 8"
    ):
        chapman_machine(8)
