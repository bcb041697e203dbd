"""Physics simulator of the circle test: machine + sensor -> Recording with ground truth.

The model and its sign conventions are those of ``docs/model.md``. Every
derivative is analytic: the commanded path, the feed ramps, the drive effects
at reversals and the geometric error map are carried as exact position,
velocity and acceleration.
"""

from imu_square.simulate.files import data_path
from imu_square.simulate.geometry import Geometry, chapman_machine
from imu_square.simulate.machine import MachineModel, read_machine
from imu_square.simulate.presets import EFFECTS, with_effects
from imu_square.simulate.run import simulate_run
from imu_square.simulate.sensor import SensorModel, read_sensor

__all__ = [
    "EFFECTS",
    "Geometry",
    "MachineModel",
    "SensorModel",
    "chapman_machine",
    "data_path",
    "read_machine",
    "read_sensor",
    "simulate_run",
    "with_effects",
]
