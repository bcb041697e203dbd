"""A diagnostic's own baseline: its value over the nights of the machine's baseline.

The squareness's baseline (:mod:`imu_square.monitor.stats.baseline`) is set
from some nights; every diagnostic takes its baseline from the same nights'
fits. With ``v_k`` and ``u_k`` their values and uncertainties and ``s`` the
values' sample standard deviation:

- the baseline value is the mean of the ``v_k``, its uncertainty
  ``u_B = sqrt(max(s^2, mean(u_k^2)) / n)``, as the squareness's;
- ``between = sqrt(max(0, s^2 - mean(u_k^2)))`` is the night-to-night scatter
  the nights' own uncertainties do not hold. A fit's uncertainty is its
  recording's noise alone; a machine's backlash or friction also moves with
  its temperature and lubrication from one night to the next. The charts
  take each night's ``sqrt(u^2 + between^2)``, so that they are designed on
  the scatter the baseline's nights showed, not on the noise only (with a
  simulated machine, which does not change between nights, ``between`` is 0
  but for the scatter of ``s``).
"""

import math
from dataclasses import dataclass

import numpy as np

# Nights with a value a diagnostic's baseline needs (its scatter needs two).
MIN_NIGHTS = 2


@dataclass(frozen=True)
class DiagnosticBaseline:
    """A diagnostic over the baseline's nights.

    Attributes
    ----------
    value : float
        Mean over the nights. [SI]
    u_value : float
        Its standard uncertainty. [SI]
    between : float
        Night-to-night scatter beyond the nights' own uncertainties. [SI]
    sigma : float
        A typical night's uncertainty with it, ``sqrt(median(u_k^2) + between^2)``. [SI]
    n_nights : int
        Nights it was taken from.
    """

    value: float
    u_value: float
    between: float
    sigma: float
    n_nights: int

    @property
    def nu(self):
        """Degrees of freedom of :attr:`sigma`; None where it is the nights' own ``u``.

        ``between`` is estimated from :attr:`n_nights` nights, so where it
        dominates a night's ``change / sigma`` follows Student's t, not the
        normal (Welch-Satterthwaite, the nights' own ``u`` taken as exact).
        """
        if self.between == 0.0:
            return None
        return max(1.0, (self.n_nights - 1) * (self.sigma / self.between) ** 4)


def diagnostic_baseline(values, uncertainties):
    """The baseline of a diagnostic from the baseline nights' values.

    Parameters
    ----------
    values, uncertainties : sequence of float
        Each baseline night's value and standard uncertainty. [SI]

    Returns
    -------
    DiagnosticBaseline or None
        None with fewer than :data:`MIN_NIGHTS` nights.
    """
    v = np.asarray(values, dtype=float)
    u = np.asarray(uncertainties, dtype=float)
    if v.size < MIN_NIGHTS:
        return None
    s2 = float(np.var(v, ddof=1))
    noise2 = float(np.mean(u**2))
    between = math.sqrt(max(0.0, s2 - noise2))
    return DiagnosticBaseline(
        value=float(np.mean(v)),
        u_value=math.sqrt(max(s2, noise2) / v.size),
        between=between,
        sigma=math.sqrt(float(np.median(u**2)) + between**2),
        n_nights=int(v.size),
    )
