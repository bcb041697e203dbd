"""A LinuxCNC INI file's limits, and the arc limit LinuxCNC plans with (no LinuxCNC needed)."""

import pytest

from imu_square.errors import ConfigError
from imu_square.linuxcnc.configuration import default_configuration
from imu_square.linuxcnc.ini import ARC_NORMAL_SHARE, read_ini, read_limits

SIM_INI = default_configuration().folder / "imu-square-sim.ini"

INCH_INI = """\
# a small router in inches
[TRAJ]
LINEAR_UNITS = inch
MAX_LINEAR_VELOCITY = 4.0
[AXIS_X]
MAX_VELOCITY = 5.0
MAX_ACCELERATION = 30.0
; Y is slower
[AXIS_Y]
MAX_VELOCITY = 3.0
MAX_ACCELERATION = 20.0
[HAL]
HALFILE = a.hal
HALFILE = b.hal
"""


def test_the_simulated_machining_centre():
    limits = read_limits(SIM_INI)
    assert limits.max_velocity_m_s == (0.5, 0.5)
    assert limits.max_accel_m_s2 == (10.0, 10.0)
    assert limits.max_feed_m_s == 0.5
    # sqrt(3)/2 of 10 m/s^2: the 25 mm circle runs at 27,918 mm/min, not 30,000
    assert limits.arc_accel_m_s2 == pytest.approx(8.660254, rel=1e-6)
    assert limits.arc_feed_m_s(0.025) * 6e4 == pytest.approx(27918.15, abs=0.01)
    # a large circle is held by the feed limit instead
    assert limits.arc_feed_m_s(1.0) == 0.5


def test_inch_units_the_smaller_axis_and_repeated_keys(tmp_path):
    path = tmp_path / "router.ini"
    path.write_text(INCH_INI)
    limits = read_limits(path)
    assert limits.max_velocity_m_s == pytest.approx((5 * 0.0254, 3 * 0.0254))
    assert limits.max_feed_m_s == pytest.approx(3 * 0.0254)  # Y, below [TRAJ]'s 4 in/s
    assert limits.arc_accel_m_s2 == pytest.approx(ARC_NORMAL_SHARE * 20 * 0.0254)
    assert read_ini(path)["HAL"]["HALFILE"] == ["a.hal", "b.hal"]
    assert read_limits(SIM_INI).max_linear_velocity_m_s == 0.5


@pytest.mark.parametrize(
    ("change", "match"),
    [
        (("LINEAR_UNITS = inch", "LINEAR_UNITS = furlong"), r"LINEAR_UNITS must be one of .*"),
        (("MAX_ACCELERATION = 20.0", "MAX_ACCELERATION = -2"), r"\[AXIS_Y\] MAX_ACCELERATION must"),
        (("MAX_VELOCITY = 5.0", "MAX_VELOCITY = fast"), r"\[AXIS_X\] MAX_VELOCITY must be a nu"),
        (("MAX_VELOCITY = 3.0\n", ""), r"router\.ini: \[AXIS_Y\] MAX_VELOCITY is missing"),
        (("[AXIS_Y]", "AXIS_Y"), r"router\.ini:9: expected \[SECTION\], KEY = VALUE or a comment"),
    ],
)
def test_bad_ini_files_are_one_line_each(tmp_path, change, match):
    path = tmp_path / "router.ini"
    path.write_text(INCH_INI.replace(*change))
    with pytest.raises(ConfigError, match=match):
        read_limits(path)


def test_a_missing_ini_file(tmp_path):
    with pytest.raises(ConfigError, match=r"nope\.ini: cannot read the LinuxCNC INI file"):
        read_limits(tmp_path / "nope.ini")
