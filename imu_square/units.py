"""Physical constants and the unit factors the package converts with.

Inside the code everything is SI (m, s, m/s^2, rad). Multiply a value given in
a file's or a person's unit by its factor here to get SI, and divide to show it:
``5 * UM`` is 5 µm in metres, ``theta / URAD`` is an angle in µrad (= µm/m).
"""

G = 9.80665  # standard gravity [m/s^2]

MM = 1e-3  # millimetre [m]
UM = 1e-6  # micrometre [m]
MM_PER_MIN = 1e-3 / 60.0  # feed [m/s]
MS = 1e-3  # millisecond [s]
HOUR = 3600.0  # [s]
URAD = 1e-6  # microradian = µm/m [rad]
UG = 1e-6 * G  # micro-g [m/s^2]

SQUARENESS_UNIT = "µm/m"  # the one display unit of squareness in human output
