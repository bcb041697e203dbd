"""Robust sine fits: vectorised IRLS and the paper's two-stage fit.

Stage 1 (paper, Section 4 [1]_) fits, per axis, on samples mapped to their
commanded position angle ``phi`` (``docs/model.md``)::

    a_x(phi) = c_x - A_x cos(phi - theta_x)
    a_y(phi) = c_y - A_y sin(phi - theta_y)

which is linear in ``[1, cos(phi), sin(phi)]``; the fit is a least-squares
fit with bisquare (Tukey biweight) weights, by iteratively reweighted least
squares (IRLS). :func:`fit_irls` solves many such fits at once (one row of
``endog`` per fit, a shared design) with closed-form 3x3 weighted normal
equations, and reproduces ``statsmodels`` ``RLM(endog, exog,
M=TukeyBiweight()).fit()`` with its default options to rounding. Two
``statsmodels`` details are kept on purpose so that the numbers agree: the
"dev" criterion evaluates ``rho(resid / s2)`` where ``s2`` is the weighted
residual *variance* of the last WLS step (not the robust scale), and the
iteration count starts at 1 for the OLS start.

Stage 2 of the paper fits the cross terms ``C_y cos(phi + pi/2 - theta_y)``
(in ``a_x``) and ``C_x cos(phi - theta_x)`` (in ``a_y``) to the stage-1
residuals and reads the sensor rotation from ``C = A tan(eps_c)`` (Eq. 3).
:func:`imu_square.pipeline.stage2.fit_cross_terms` implements it as written,
but it is degenerate: both stages use the same frequency, so stage 1 has
already absorbed every component at ``omega`` and the stage-2 amplitudes are
zero up to noise whatever ``eps_c`` is (a rotation of a perfect circle is
indistinguishable from a time shift). The pipeline therefore estimates ``eps_c`` from the mean
phase ``(theta_x + theta_y) / 2`` with ``phi`` anchored at the middle of each
block's motion (:mod:`imu_square.pipeline.rotation`, ``docs/model.md``).

References
----------
.. [1] K. Szipka, A. Archenti, G. W. Vogl, M. A. Donmez, "Identification of
   machine tool squareness errors via inertial measurements", CIRP Annals 68
   (2019).
"""

import warnings
from dataclasses import dataclass, field, fields, replace

import numpy as np
from statsmodels.robust import norms

from imu_square.errors import AnalysisError, ImuSquareWarning
from imu_square.validation import check_option

NORMS = {
    "tukey": norms.TukeyBiweight,
    "huber": norms.HuberT,
    "ols": norms.LeastSquares,
}
DEFAULT_TUNING = {"tukey": 4.685, "huber": 1.345, "ols": None}
_MAD_TO_SD = 0.6744897501960817  # scipy.stats.norm.ppf(0.75), as statsmodels.robust.scale.mad


def robust_norm(name="tukey", tuning=None):
    """A ``statsmodels`` robust norm by name.

    Parameters
    ----------
    name : {"tukey", "huber", "ols"}
        Tukey biweight (the paper's bisquare), Huber, or plain least squares.
    tuning : float, optional
        Tuning constant in units of the robust scale; the norm's default
        (4.685 for Tukey, 95 % efficiency at the normal) if None.

    Returns
    -------
    statsmodels.robust.norms.RobustNorm
    """
    check_option("robust norm", name, NORMS)
    if name == "ols":
        return norms.LeastSquares()
    return NORMS[name](DEFAULT_TUNING[name] if tuning is None else float(tuning))


@dataclass(frozen=True)
class FitResult:
    """Robust linear fits of several rows sharing one design.

    Attributes
    ----------
    params : ndarray, shape (n_fits, n_params)
        Coefficients. [unit of endog]
    bse : ndarray, shape (n_fits, n_params)
        Standard errors, ``statsmodels`` "H1" covariance. [unit of endog]
    cov : ndarray, shape (n_fits, n_params, n_params)
        Covariance of ``params`` ("H1"). [unit of endog squared]
    resid : ndarray, shape (n_fits, n_obs)
        Residuals. [unit of endog]
    weights : ndarray, shape (n_fits, n_obs)
        Robust weights of the last IRLS step, in [0, 1].
    prior_weights : ndarray, shape (n_fits, n_obs)
        Inverse relative variance of each observation, 0 for none (all ones
        unless given).
    scale : ndarray, shape (n_fits,)
        Robust scale (MAD about zero / 0.6745) of the residuals. [unit of endog]
    iterations : ndarray of int, shape (n_fits,)
        IRLS iterations, counting the OLS start as 1 (as ``statsmodels``).
    converged : ndarray of bool, shape (n_fits,)
        Whether the criterion fell below ``tol`` before ``maxiter``.
    options : dict
        Norm, tuning constant, ``maxiter``, ``tol``, ``conv``, ``update_scale``.
    """

    params: np.ndarray
    bse: np.ndarray
    cov: np.ndarray
    resid: np.ndarray
    weights: np.ndarray
    prior_weights: np.ndarray
    scale: np.ndarray
    iterations: np.ndarray
    converged: np.ndarray
    options: dict = field(default_factory=dict)


def _mad0(resid, present=None):
    if present is None:
        return np.median(np.abs(resid), axis=-1, overwrite_input=True) / _MAD_TO_SD  # no copy
    return np.nanmedian(np.where(present, np.abs(resid), np.nan), axis=-1) / _MAD_TO_SD


def _rho(norm, z):
    if type(norm) is norms.TukeyBiweight:  # same formula as statsmodels, without its temporaries
        u = np.minimum(np.square(z / norm.c), 1.0)
        return norm.c**2 / 6.0 * (1.0 - (1.0 - u) ** 3)
    return norm.rho(z)


def _weights(norm, z, overwrite=False):
    # overwrite: z is a temporary of the caller's, reused for the weights. A fresh
    # array costs more than the arithmetic here (page faults of a new allocation).
    if type(norm) is norms.TukeyBiweight:  # (1 - u)^2 where u <= 1, else 0; one array, in place
        u = np.divide(z, norm.c, out=z if overwrite else None)
        np.square(u, out=u)
        np.subtract(1.0, u, out=u)
        np.fmax(u, 0.0, out=u)  # fmax: a NaN z weighs 0, as in np.where(u <= 1, ...)
        return np.square(u, out=u)
    return norm.weights(z)


def _psi_and_deriv(norm, z, overwrite=False):
    # overwrite: z is the caller's temporary and becomes psi (as in _weights).
    if type(norm) is norms.TukeyBiweight:  # statsmodels' formulas, with v = max(1 - (z/c)^2, 0)
        v = np.divide(z, norm.c)
        np.square(v, out=v)
        np.subtract(1.0, v, out=v)
        np.fmax(v, 0.0, out=v)  # 0 beyond c: psi and psi' vanish there
        dpsi = 5.0 * v  # psi' = v^2 - 4 (z/c)^2 v = v (5 v - 4)
        dpsi -= 4.0
        dpsi *= v
        psi = np.multiply(z, v, out=z if overwrite else None)
        psi *= v
        return psi, dpsi
    return norm.psi(z), norm.psi_deriv(z)


def _solve_weighted(exog, outer, endog, w):
    p = exog.shape[1]
    xtwx = (w @ outer).reshape(-1, p, p)
    xtwy = (w * endog) @ exog
    return np.linalg.solve(xtwx, xtwy[..., None])[..., 0]


def fit_irls(
    exog,
    endog,
    norm=None,
    *,
    maxiter=50,
    tol=1e-8,
    conv="dev",
    update_scale=True,
    start_params=None,
    freeze_scale_after=None,
    prior_weights=None,
    covariance=True,
):
    """Robust linear regression of every row of ``endog`` on ``exog`` by IRLS.

    Same algorithm and defaults as ``statsmodels.robust.robust_linear_model.
    RLM(endog_row, exog, M=norm).fit(maxiter, tol, scale_est="mad", cov="H1",
    update_scale, conv)``, vectorised over rows; each row stops on its own
    criterion. With ``prior_weights`` it is that regression on the rows scaled
    by their square root, observations of weight 0 left out altogether (also
    from the scale and the covariance).

    Parameters
    ----------
    exog : ndarray, shape (n_obs, n_params)
        Design matrix, shared by all fits, full column rank.
    endog : ndarray, shape (n_obs,) or (n_fits, n_obs)
        Observations, one fit per row. [any unit]
    norm : statsmodels.robust.norms.RobustNorm, optional
        Tukey biweight with c = 4.685 if None.
    maxiter : int
        Maximum number of iterations (the OLS start counts as 1).
    tol : float
        Convergence tolerance on the criterion.
    conv : {"dev", "coefs"}
        Criterion: change of the deviance, or of every coefficient.
    update_scale : bool
        Re-estimate the scale at every iteration.
    start_params : ndarray, shape (n_params,) or (n_fits, n_params), optional
        Starting coefficients instead of OLS (``statsmodels``' ``start_params``);
        the starting scale is then the MAD of their residuals. [unit of endog]
    freeze_scale_after : int, optional
        Stop re-estimating a fit's scale after this many iterations. The MAD
        scale is a median, so with it IRLS can end in a 2-cycle (seen on single
        noisy cycles, up to 10 % of a standard error apart); with the scale
        fixed, IRLS descends and converges. None: statsmodels' behaviour.
    prior_weights : ndarray, shape (n_obs,) or (n_fits, n_obs), optional
        Inverse relative variance of each observation (e.g. how many cycles a
        point of a mean trace averages); 0 marks a missing observation, whose
        ``endog`` may be NaN. All ones if None.
    covariance : bool
        Compute ``cov`` and ``bse``; if False they are NaN (the fits are the
        same): for many fits whose spread, not covariance, is wanted, it saves
        about a fifth of the cost (the per-cycle fits).

    Returns
    -------
    FitResult

    Warns
    -----
    ImuSquareWarning
        If a fit reaches ``maxiter`` without converging.
    """
    check_option("conv", conv, ("dev", "coefs"))
    norm = robust_norm() if norm is None else norm
    exog = np.asarray(exog, dtype=np.float64)
    endog = np.atleast_2d(np.asarray(endog, dtype=np.float64))
    n, p = exog.shape
    if endog.shape[-1] != n:
        raise AnalysisError(f"endog must have {n} columns like exog's rows, got {endog.shape}")
    outer = (exog[:, :, None] * exog[:, None, :]).reshape(n, p * p)
    if prior_weights is None:
        prior = np.ones_like(endog)
        present, root = None, None
        df_resid = np.full(endog.shape[0], n - p)
    else:
        prior = np.broadcast_to(np.asarray(prior_weights, dtype=np.float64), endog.shape).copy()
        present = prior > 0
        endog = np.where(present, endog, 0.0)
        root = np.sqrt(prior)
        df_resid = np.count_nonzero(present, axis=-1) - p

    def scaled(r, idx=slice(None)):  # residuals in units of their own sd
        return r if root is None else r * root[idx]

    def mad(r, idx=slice(None)):
        return _mad0(scaled(r, idx), None if present is None else present[idx])

    if start_params is None:
        params = _solve_weighted(exog, outer, endog, prior)
    else:
        params = np.broadcast_to(np.asarray(start_params, dtype=np.float64), (endog.shape[0], p))
        params = params.copy()
    resid = endog - params @ exog.T
    scale = mad(resid)

    def criterion(params, resid, w, idx):
        if conv == "coefs":
            return params.copy()
        s2 = np.einsum("bn,bn->b", w, resid**2) / df_resid[idx]
        return _rho(norm, scaled(resid, idx) / s2[:, None]).sum(axis=-1)

    last = criterion(params, resid, prior, slice(None))
    iterations = np.ones(endog.shape[0], dtype=int)
    converged = np.zeros(endog.shape[0], dtype=bool)
    active = np.ones(endog.shape[0], dtype=bool)
    weights = np.ones_like(endog)
    while np.any(active):
        idx = np.flatnonzero(active)
        perfect = scale[idx] == 0.0
        if np.any(perfect):  # exact fit: nothing left to reweight
            converged[idx[perfect]] = True
            active[idx[perfect]] = False
            idx = idx[~perfect]
            if idx.size == 0:
                break
        if idx.size == active.size:
            idx = slice(None)  # all rows: views, no copies
        w_i = _weights(norm, scaled(resid[idx], idx) / scale[idx, None], overwrite=True)
        wp_i = w_i if present is None else w_i * prior[idx]
        p_i = _solve_weighted(exog, outer, endog[idx], wp_i)
        r_i = endog[idx] - p_i @ exog.T
        if isinstance(idx, slice):  # all rows: the new arrays replace the old, no copies
            weights, params, resid = w_i, p_i, r_i
        else:
            weights[idx], params[idx], resid[idx] = w_i, p_i, r_i
        if update_scale:
            new_scale = mad(r_i, idx)
            if freeze_scale_after is not None:
                frozen = iterations[idx] >= freeze_scale_after
                new_scale = np.where(frozen, scale[idx], new_scale)
            scale[idx] = new_scale
        crit = criterion(p_i, r_i, wp_i, idx)
        iterations[idx] += 1
        change = np.abs(crit - last[idx])
        small = ~np.any(change > tol, axis=-1) if conv == "coefs" else ~(change > tol)
        last[idx] = crit
        converged[idx] = small
        active[idx] = ~small & (iterations[idx] < maxiter)
    if not np.all(converged):
        warnings.warn(
            f"robust fit did not converge in maxiter={maxiter} iterations for "
            f"{int(np.sum(~converged))} of {converged.size} fits",
            ImuSquareWarning,
            stacklevel=2,
        )
    if covariance:
        cov = _cov_h1(norm, exog, scaled(resid), scale, present, prior, outer)
    else:
        cov = np.full((endog.shape[0], p, p), np.nan)
    if present is not None:
        resid = np.where(present, resid, np.nan)
        weights = np.where(present, weights, 0.0)
    return FitResult(
        params=params,
        bse=np.sqrt(np.diagonal(cov, axis1=-2, axis2=-1)),
        cov=cov,
        resid=resid,
        weights=weights,
        prior_weights=prior,
        scale=scale,
        iterations=iterations,
        converged=converged,
        options={
            "norm": type(norm).__name__,
            "tuning": getattr(norm, "c", getattr(norm, "t", None)),
            "maxiter": maxiter,
            "tol": tol,
            "conv": conv,
            "update_scale": update_scale,
            "freeze_scale_after": freeze_scale_after,
            "scale_est": "mad",
            "cov": "H1",
        },
    )


def _cov_h1(norm, exog, resid, scale, present, prior, outer):
    """statsmodels' "H1" covariance; ``resid`` already scaled by sqrt(prior)."""
    n, p = exog.shape
    safe = np.where(scale > 0, scale, 1.0)
    sresid = np.where(scale[:, None] > 0, resid / safe[:, None], 0.0)
    psi, dpsi = _psi_and_deriv(norm, sresid)
    if present is None:
        m = dpsi.mean(axis=-1)
        k = 1 + p / n * dpsi.var(axis=-1) / m**2
        ss_psi = np.sum(psi**2, axis=-1)
        factor = k**2 * (ss_psi * scale**2 / (n - p)) / m**2
        return factor[:, None, None] * np.linalg.inv(exog.T @ exog)[None]
    n_i = np.count_nonzero(present, axis=-1)
    m = np.sum(dpsi * present, axis=-1) / n_i
    var = np.sum((dpsi - m[:, None]) ** 2 * present, axis=-1) / n_i
    k = 1 + p / n_i * var / m**2
    ss_psi = np.sum(psi**2 * present, axis=-1)
    factor = k**2 * (ss_psi * scale**2 / (n_i - p)) / m**2
    return factor[:, None, None] * np.linalg.inv((prior @ outer).reshape(-1, p, p))


def sine_design(phi):
    """Design matrix ``[1, cos(phi), sin(phi)]``.

    Parameters
    ----------
    phi : ndarray, shape (n_obs,)
        Commanded position angle. [rad]

    Returns
    -------
    ndarray, shape (n_obs, 3)
    """
    phi = np.asarray(phi, dtype=np.float64)
    return np.column_stack([np.ones_like(phi), np.cos(phi), np.sin(phi)])


@dataclass(frozen=True)
class CircleFit:
    """Stage-1 fits of both axes, for several traces sharing one phi grid.

    Attributes
    ----------
    theta_x, theta_y : ndarray, shape (n_fits,)
        Phase shifts of the model in the module docstring. [rad]
    amp_x, amp_y : ndarray, shape (n_fits,)
        Amplitudes A_x, A_y. [m/s^2]
    offset_x, offset_y : ndarray, shape (n_fits,)
        Constant terms c_x, c_y. [m/s^2]
    u_theta_x, u_theta_y : ndarray, shape (n_fits,)
        Standard errors of the phases from the fits' covariance (they assume
        independent residuals, which low-passed data are not; the pipeline's
        uncertainty comes from the scatter over cycles). [rad]
    x, y : FitResult
        The underlying linear fits, columns ``[1, cos, sin]``.
    """

    theta_x: np.ndarray
    theta_y: np.ndarray
    amp_x: np.ndarray
    amp_y: np.ndarray
    offset_x: np.ndarray
    offset_y: np.ndarray
    u_theta_x: np.ndarray
    u_theta_y: np.ndarray
    x: FitResult
    y: FitResult

    @property
    def squareness(self):
        """``theta_y - theta_x`` (paper, Eq. 4). [rad]"""
        return self.theta_y - self.theta_x

    @property
    def mean_phase(self):
        """``(theta_x + theta_y) / 2``, the sensor rotation when phi is anchored. [rad]"""
        return mean_phase(self.theta_x, self.theta_y)


def mean_phase(theta_x, theta_y):
    """``(theta_x + theta_y) / 2``, the sensor rotation when phi is anchored.

    Taken as ``theta_x`` plus half the wrapped difference, so that a sensor
    turned by about 180 deg (thetas either side of +-pi) averages to +-pi, not 0.

    Parameters
    ----------
    theta_x, theta_y : ndarray
        Phases of the x and y fits. [rad]

    Returns
    -------
    ndarray
        In [-pi, pi). [rad]
    """
    half = 0.5 * (np.mod(theta_y - theta_x + np.pi, 2 * np.pi) - np.pi)
    return np.mod(theta_x + half + np.pi, 2 * np.pi) - np.pi


def circle_phases(params_x, params_y):
    """Phases ``theta_x``, ``theta_y`` of stage-1 coefficients.

    Parameters
    ----------
    params_x, params_y : ndarray, shape (n_fits, 3)
        Coefficients ``[c, cos, sin]`` of the x and of the y fits. [m/s^2]

    Returns
    -------
    theta_x, theta_y : ndarray, shape (n_fits,)
        [rad]
    """
    # a_x = c - A cos(phi - th) = c - A cos(th) cos(phi) - A sin(th) sin(phi)
    # a_y = c - A sin(phi - th) = c + A sin(th) cos(phi) - A cos(th) sin(phi)
    return (
        np.arctan2(-params_x[:, 2], -params_x[:, 1]),
        np.arctan2(params_y[:, 1], -params_y[:, 2]),
    )


def _u_phase(a, b, cov, da, db):
    # theta = atan2(a, b): delta-method standard error from the 2x2 covariance.
    r2 = a**2 + b**2
    ga, gb = b / r2, -a / r2
    var = ga**2 * cov[:, da, da] + gb**2 * cov[:, db, db] + 2 * ga * gb * cov[:, da, db]
    return np.sqrt(var)


def fit_circle(
    phi,
    accel_x,
    accel_y,
    norm=None,
    start_params=None,
    prior_weights=None,
    covariance=True,
    **irls_options,
):
    """Stage 1: robust sine fit of both axes in the position-angle domain.

    Parameters
    ----------
    phi : ndarray, shape (n_obs,)
        Commanded position angle of each observation. [rad]
    accel_x, accel_y : ndarray, shape (n_obs,) or (n_fits, n_obs)
        Sensor x and y acceleration at ``phi``. [m/s^2]
    norm : statsmodels.robust.norms.RobustNorm, optional
        Tukey biweight (c = 4.685) if None.
    start_params : tuple of 2 ndarray, optional
        Starting coefficients ``[c, cos, sin]`` for x and for y, each of shape
        (3,) or (n_fits, 3); OLS if None. [m/s^2]
    prior_weights : ndarray, shape (n_obs,) or (n_fits, n_obs), optional
        Inverse relative variance of each point, 0 where it holds no data
        (:func:`fit_irls`); the same for both axes.
    covariance : bool
        Compute the fits' covariance; if False it and ``u_theta_x``,
        ``u_theta_y`` are NaN (:func:`fit_irls`).
    **irls_options
        Passed to :func:`fit_irls`.

    Returns
    -------
    CircleFit
    """
    exog = sine_design(phi)
    # Both axes in one batch of independent rows: half the per-iteration overhead.
    accel_x, accel_y = np.atleast_2d(accel_x), np.atleast_2d(accel_y)
    n_x = accel_x.shape[0]
    if start_params is not None:
        starts = zip(start_params, (accel_x, accel_y), strict=True)
        start_params = np.concatenate([np.broadcast_to(s, (a.shape[0], 3)) for s, a in starts])
    if prior_weights is not None:
        prior_weights = np.concatenate(
            [np.broadcast_to(prior_weights, a.shape) for a in (accel_x, accel_y)]
        )
    both = fit_irls(
        exog,
        np.concatenate([accel_x, accel_y]),
        norm,
        start_params=start_params,
        prior_weights=prior_weights,
        covariance=covariance,
        **irls_options,
    )
    fx, fy = _rows(both, slice(None, n_x)), _rows(both, slice(n_x, None))
    theta_x, theta_y = circle_phases(fx.params, fy.params)
    u_x = _u_phase(-fx.params[:, 2], -fx.params[:, 1], fx.cov, 2, 1)
    u_y = _u_phase(fy.params[:, 1], -fy.params[:, 2], fy.cov, 1, 2)
    return CircleFit(
        theta_x=theta_x,
        theta_y=theta_y,
        amp_x=np.hypot(fx.params[:, 1], fx.params[:, 2]),
        amp_y=np.hypot(fy.params[:, 1], fy.params[:, 2]),
        offset_x=fx.params[:, 0],
        offset_y=fy.params[:, 0],
        u_theta_x=u_x,
        u_theta_y=u_y,
        x=fx,
        y=fy,
    )


def _rows(fit, which):
    """The fits ``which`` (a slice) of a FitResult."""
    arrays = {f.name: getattr(fit, f.name)[which] for f in fields(FitResult) if f.name != "options"}
    return replace(fit, **arrays)


@dataclass(frozen=True)
class MeanFit:
    """Stage-1 fit of each direction's averaged cycles: row 0 CCW, row 1 flipped CW.

    Attributes
    ----------
    fit : CircleFit
        The fits of the two averaged traces.
    mean_x, mean_y : ndarray, shape (2, n_grid)
        The averaged traces on the phi grid. [m/s^2]
    amp_x_m_s2, amp_y_m_s2 : ndarray, shape (2,)
        Amplitudes corrected for the low-pass's gain at the circle frequency. [m/s^2]
    counts : ndarray of int, shape (2, n_grid)
        Cycles holding data at each grid point (all of them without bridged gaps).
    gain : float
        Amplitude gain of the low-pass and the resampling at the circle frequency.
    """

    fit: CircleFit
    mean_x: np.ndarray
    mean_y: np.ndarray
    amp_x_m_s2: np.ndarray
    amp_y_m_s2: np.ndarray
    counts: np.ndarray
    gain: float

    @property
    def amplitude_m_s2(self):
        """Mean amplitude over both axes and directions. [m/s^2]"""
        return float(np.mean([self.amp_x_m_s2, self.amp_y_m_s2]))

    @property
    def squareness_rad(self):
        """``theta_y - theta_x`` of each direction, wrapped into [-pi, pi). [rad]"""
        return wrap_angle(self.fit.squareness)


def wrap_angle(angle_rad):
    """Angles wrapped into [-pi, pi).

    Parameters
    ----------
    angle_rad : float or ndarray
        Angles. [rad]

    Returns
    -------
    ndarray
        The same angles modulo 2 pi. [rad]
    """
    return (np.asarray(angle_rad) + np.pi) % (2 * np.pi) - np.pi


def masked_mean(traces, valid):
    """Mean over cycles at each grid point, of the cycles holding data there.

    Parameters
    ----------
    traces : ndarray, shape (n_cycles, n_grid)
        Cycles on the phi grid, NaN where missing. [m/s^2]
    valid : ndarray of bool, shape (n_cycles, n_grid)
        Where the cycles hold data.

    Returns
    -------
    mean : ndarray, shape (n_grid,)
        The mean; 0 where no cycle holds data. [m/s^2]
    counts : ndarray of int, shape (n_grid,)
        Cycles averaged at each point.
    """
    counts = np.count_nonzero(valid, axis=0)
    total = np.sum(np.where(valid, traces, 0.0), axis=0)
    return total / np.maximum(counts, 1), counts


def fit_mean_traces(cycles, gain, norm=None, **irls_options):
    """Average each direction's cycles and fit the two mean traces.

    Each grid point averages the cycles that hold data there, and weighs in
    the fit by how many they are (none: left out).

    Parameters
    ----------
    cycles : CycleTraces
        The flipped, resampled cycles of both directions.
    gain : float
        Amplitude gain of the low-pass and the resampling at the circle
        frequency, divided out of the fitted amplitudes (the phases are
        untouched: both have zero phase).
    norm : statsmodels.robust.norms.RobustNorm, optional
        Tukey biweight if None.
    **irls_options
        Passed to :func:`fit_irls`.

    Returns
    -------
    MeanFit
    """
    dirs = (cycles.ccw, cycles.cw)
    mx = [masked_mean(c.x, c.valid) for c in dirs]
    my = [masked_mean(c.y, c.valid) for c in dirs]
    mean_x = np.stack([m for m, _ in mx])
    mean_y = np.stack([m for m, _ in my])
    counts = np.stack([n for _, n in mx])
    complete = all(c.complete for c in dirs)
    prior = None if complete else counts / np.array([[c.n] for c in dirs], dtype=np.float64)
    fit = fit_circle(cycles.phi_grid, mean_x, mean_y, norm, prior_weights=prior, **irls_options)
    return MeanFit(fit, mean_x, mean_y, fit.amp_x / gain, fit.amp_y / gain, counts, float(gain))
