"""imu-square: machine-tool squareness from a table-mounted accelerometer.

The method is that of Szipka, Archenti, Vogl and Donmez, "Identification of
machine tool squareness errors via inertial measurements", CIRP Annals 68
(2019) [1]_.

References
----------
.. [1] K. Szipka, A. Archenti, G. W. Vogl, M. A. Donmez, CIRP Annals -
   Manufacturing Technology 68 (2019).
"""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("imu-square")
except PackageNotFoundError:  # running from a source tree that is not installed
    __version__ = "0.0.0+unknown"
