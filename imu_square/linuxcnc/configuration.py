"""The simulated machine LinuxCNC runs: a configuration folder kept in the project.

``imu_square/data/linuxcnc/`` holds the INI file (every setting that shapes the
motion is documented in it), the HAL file with the sampler, the headless
display and the marker M-code. A run copies them into its own folder.
"""

import hashlib
from dataclasses import dataclass
from importlib.resources import files
from pathlib import Path

from imu_square.linuxcnc.ini import read_ini, read_limits

INI_NAME = "imu-square-sim.ini"
HAL_NAME = "imu-square-sim.hal"
DISPLAY_NAME = "display.py"
MARKER_NAME = "marker-mcode.sh"
FILES = (INI_NAME, HAL_NAME, DISPLAY_NAME, MARKER_NAME)


@dataclass(frozen=True)
class Configuration:
    """A LinuxCNC configuration folder imu-square can run.

    Attributes
    ----------
    folder : Path
        Holds :data:`FILES`.
    """

    folder: Path

    def read(self, name):
        """One of :data:`FILES`, as bytes."""
        return (self.folder / name).read_bytes()

    def digest(self):
        """SHA-256 over the files' names and contents (hex)."""
        h = hashlib.sha256()
        for name in FILES:
            data = self.read(name)
            h.update(f"{name}\0{len(data)}\0".encode())
            h.update(data)
        return h.hexdigest()

    @property
    def servo_period_s(self):
        """``[EMCMOT] SERVO_PERIOD``: the planner's cycle and the sample period. [s]"""
        return int(read_ini(self.folder / INI_NAME)["EMCMOT"]["SERVO_PERIOD"][-1]) * 1e-9

    def describe(self):
        """What the truth file says about the configuration (JSON-ready)."""
        return {
            **read_limits(self.folder / INI_NAME).as_dict(),
            "ini": INI_NAME,
            "sha256": self.digest(),
            "servo_period_s": self.servo_period_s,
        }


def default_configuration():
    """The project's simulated machining centre (``imu_square/data/linuxcnc``)."""
    return Configuration(Path(str(files("imu_square").joinpath("data", "linuxcnc"))))
