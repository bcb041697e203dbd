"""Thermal drift of the measurand: a first-order regression (paper, Section 4 [1]_).

The sensor's own non-orthogonality drifts while its electronics warm up, and
``theta_y - theta_x`` drifts with it; the paper "compensated with the
application of a first-order regression". Here that is a regression within a
night, by ordinary least squares from ``statsmodels`` with its standard errors,
over the cycles: each CCW and each flipped CW cycle's ``theta_y - theta_x``
against the sensor temperature over that cycle (or, without a temperature
channel, the time since the board was powered), with a CCW/CW indicator,
because the servo mismatch adds ``+m`` to CCW and ``-m`` to CW and all CCW
cycles come before all CW cycles::

    s_j = a + m' d_j + b (x_j - x_ref)        d_j = +1 (CCW), -1 (CW)

``a`` is the night's value corrected to the reference ``x_ref``. With one CCW
block then one CW block the slope is learnt from the trend *within* each
block, so its price is an inflated uncertainty of ``a`` (stated).

The regressor is the temperature when every value has one, else the time
since power-on: the board's sample counter starts at zero at power-up
(``docs/protocol.md``), so ``seq * dt`` is its uptime (exact until the counter
wraps, 49.7 days at 1 kHz; a sensor on that long has warmed up).

References
----------
.. [1] K. Szipka, A. Archenti, G. W. Vogl, M. A. Donmez, CIRP Annals 68 (2019).
"""

import math
from dataclasses import dataclass

import numpy as np

from imu_square.errors import AnalysisError
from imu_square.json_values import json_safe

# A slope is "significant" below this p-value (two-sided t-test).
SIGNIFICANCE = 0.05


@dataclass(frozen=True)
class DriftFit:
    """A first-order regression of ``theta_y - theta_x`` on a drift variable.

    Attributes
    ----------
    regressor : str
        ``"temperature_c"`` [degC] or ``"time_since_power_on_s"`` [s].
    p_value : float
        Two-sided p-value of ``b = 0``.
    reference : float
        ``x_ref``, the value the result is corrected to. [degC or s]
    n : int
        Observations.
    dof : int
        Residual degrees of freedom.
    value_at_reference_rad : float
        ``theta_y - theta_x`` at ``x_ref``. [rad]
    u_value_at_reference_rad : float
        Its standard error. [rad]
    uncorrected_rad : float
        The plain (unregressed) value for comparison: the mean of the CCW/CW
        pair means within the night. [rad]
    u_uncorrected_rad : float
        Its standard error from the same data. [rad]
    slope_rad_per_unit : float
        Fitted slope ``b``. [rad per degC or rad per s]
    u_slope_rad_per_unit : float
        Its standard error. [rad per unit]
    """

    regressor: str
    p_value: float
    reference: float
    n: int
    dof: int
    value_at_reference_rad: float
    u_value_at_reference_rad: float
    uncorrected_rad: float
    u_uncorrected_rad: float
    slope_rad_per_unit: float
    u_slope_rad_per_unit: float

    @property
    def significant(self):
        """Whether the slope differs from zero at :data:`SIGNIFICANCE`."""
        return bool(self.p_value < SIGNIFICANCE)

    def to_json_dict(self):
        """JSON-ready, angles in µrad, with :attr:`significant`."""
        return json_safe(self, urad=True) | {"significant": self.significant}


def cycle_drift_variable(result, recording):
    """The drift variable of each cycle of a run: temperature if recorded, else uptime.

    Parameters
    ----------
    result : RunResult
        The run's analysis, with its per-cycle times and temperatures.
    recording : Recording
        The recording it came from (for the board's uptime at the first sample).

    Returns
    -------
    regressor : str
        ``"temperature_c"`` or ``"time_since_power_on_s"``.
    x_ccw, x_cw : ndarray, shape (n_pairs,)
        The variable over each CCW and each CW cycle. [degC or s]
    """
    pc = result.per_cycle
    t_ccw, t_cw = pc["temperature_ccw_c"], pc["temperature_cw_c"]
    if np.all(np.isfinite(t_ccw)) and np.all(np.isfinite(t_cw)):
        return "temperature_c", np.asarray(t_ccw), np.asarray(t_cw)
    uptime = power_on_offset_s(recording)
    return "time_since_power_on_s", uptime + pc["t_ccw_s"], uptime + pc["t_cw_s"]


def power_on_offset_s(recording):
    """The board's uptime at a recording's first sample, from its sample counter. [s]

    Parameters
    ----------
    recording : Recording
        The recording.

    Returns
    -------
    float
        ``seq[0] * dt``. [s]
    """
    return float(recording.seq[0]) * recording.dt_ns * 1e-9


def fit_night_drift(result, recording, reference=None):
    """Regress one night's per-cycle ``theta_y - theta_x`` on its drift variable.

    Parameters
    ----------
    result : RunResult
        The night's analysis.
    recording : Recording
        Its recording.
    reference : float, optional
        ``x_ref`` [degC or s]; the night's mean of the variable if None.

    Returns
    -------
    DriftFit

    Raises
    ------
    AnalysisError
        Too few cycles, or a drift variable that does not vary.
    """
    import statsmodels.api as sm

    regressor, x_ccw, x_cw = cycle_drift_variable(result, recording)
    pc = result.per_cycle
    y = np.concatenate([pc["squareness_ccw_rad"], pc["squareness_cw_rad"]])
    x = np.concatenate([x_ccw, x_cw])
    if y.size < 4:
        raise AnalysisError(
            f"a drift regression needs at least 4 values, got {y.size}: too few to fit a slope"
        )
    if not np.all(np.isfinite(x)):
        raise AnalysisError(f"the drift variable {regressor} has missing values")
    spread = float(np.ptp(x))
    if not spread > 0 or not math.isfinite(spread):
        raise AnalysisError(
            f"the drift variable {regressor} does not vary (all {x[0]:g}): no slope to fit"
        )
    d = np.concatenate([np.ones(x_ccw.size), -np.ones(x_cw.size)])
    x_ref = float(np.mean(x)) if reference is None else float(reference)
    design = np.column_stack([np.ones_like(x), d, x - x_ref])
    fit = sm.OLS(y, design).fit()
    plain = sm.OLS(y, design[:, :2]).fit()  # the same fit without the slope
    return DriftFit(
        regressor=regressor,
        slope_rad_per_unit=float(fit.params[2]),
        u_slope_rad_per_unit=float(fit.bse[2]),
        p_value=float(fit.pvalues[2]),
        reference=x_ref,
        value_at_reference_rad=float(fit.params[0]),
        u_value_at_reference_rad=float(fit.bse[0]),
        uncorrected_rad=float(plain.params[0]),
        u_uncorrected_rad=float(plain.bse[0]),
        n=int(fit.nobs),
        dof=int(fit.df_resid),
    )
