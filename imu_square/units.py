"""Physical constants shared by the package."""

G = 9.80665  # standard gravity [m/s^2]
