"""Stage 2 of the paper: cross terms fitted to the stage-1 residuals.

Degenerate for a circle (:mod:`imu_square.pipeline.sine_fit`): stage 1 has already
absorbed every component at ``omega``, so the cross terms come out zero up to
noise whatever the sensor's rotation; the pipeline keeps the value as
``eps_c_stage2_rad`` only to show it.
"""

from dataclasses import dataclass

import numpy as np

from imu_square.pipeline.newton import fit_newton
from imu_square.pipeline.sine_fit import robust_norm


@dataclass(frozen=True)
class CrossTermFit:
    """Stage 2 of the paper: cross terms fitted to the stage-1 residuals.

    Attributes
    ----------
    c_x, c_y : ndarray, shape (n_fits,)
        Amplitudes C_x (in a_y) and C_y (in a_x) of Eqs. 1-2. [m/s^2]
    eps_c : ndarray, shape (n_fits,)
        ``arctan(C / A)`` averaged over both axes, Eq. 3. [rad]
    """

    c_x: np.ndarray
    c_y: np.ndarray
    eps_c: np.ndarray


def fit_cross_terms(phi, stage1, norm=None, **irls_options):
    """Stage 2 as in the paper: fit the cross terms to the stage-1 residuals.

    ``a_x`` residual ``= C_y cos(phi + pi/2 - theta_y) + const`` and ``a_y``
    residual ``= C_x cos(phi - theta_x) + const``, with the stage-1 phases held,
    then ``eps_c = arctan(C_x / A_y)`` and ``arctan(C_y / A_x)`` (Eq. 3),
    averaged. Degenerate for a circle: see the module docstring.

    Parameters
    ----------
    phi : ndarray, shape (n_obs,)
        Commanded position angle. [rad]
    stage1 : CircleFit
        The stage-1 fits on the same ``phi``.
    norm : statsmodels.robust.norms.RobustNorm, optional
        Tukey biweight if None.
    **irls_options
        Options of :func:`imu_square.pipeline.sine_fit.fit_irls`; the fits are solved by
        :func:`imu_square.pipeline.newton.fit_newton`, started at zero.

    Returns
    -------
    CrossTermFit
    """
    phi = np.asarray(phi, dtype=np.float64)
    norm = robust_norm() if norm is None else norm
    zero = np.zeros(2)  # the stage-1 fit leaves nothing at omega: the solution is near 0
    c_y = np.empty(stage1.theta_x.size)
    c_x = np.empty_like(c_y)
    for i in range(c_y.size):
        ex = np.column_stack([np.ones_like(phi), np.cos(phi + np.pi / 2 - stage1.theta_y[i])])
        ey = np.column_stack([np.ones_like(phi), np.cos(phi - stage1.theta_x[i])])
        pw = stage1.x.prior_weights[i]
        pw = None if np.all(pw == 1.0) else pw[None]  # points without data, left out
        fx, _ = fit_newton(ex, stage1.x.resid[i], zero, norm, prior_weights=pw, **irls_options)
        fy, _ = fit_newton(ey, stage1.y.resid[i], zero, norm, prior_weights=pw, **irls_options)
        c_y[i], c_x[i] = fx[0, 1], fy[0, 1]
    eps = 0.5 * (np.arctan(c_x / stage1.amp_y) + np.arctan(c_y / stage1.amp_x))
    return CrossTermFit(c_x=c_x, c_y=c_y, eps_c=eps)
