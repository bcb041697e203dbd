"""Robust fits near a known solution by Newton's method: single cycles, resamples, stage 2.

:func:`imu_square.pipeline.sine_fit.fit_irls` solves the M-estimate's equations
``sum_i sqrt(p_i) psi(z_i) x_i = 0``, ``z_i = sqrt(p_i) r_i / s``, ``s`` the
MAD scale of the ``z``, by reweighted least squares, which converges
linearly: on a typical machine's spiky traces the error shrinks about four
times a step, so a resample started from its direction's fit takes nine or
ten steps to reach 1e-10 m/s^2. Newton's step uses ``psi'`` where IRLS uses
the weights ``psi(z) / z`` and converges quadratically at a fixed scale;
re-estimating the scale after every step, as IRLS does, keeps IRLS's fixed
point. So the estimate is the same, within the tolerance, in three or four
steps.

Newton needs a start near the solution and a Hessian ``sum p_i psi'(z_i) x_i
x_i^T`` that stays positive definite (Tukey's ``psi'`` is negative beyond
``c / sqrt(5)``). A row that loses either, or has not converged in
``newton_steps``, is handed to ``fit_irls`` from its start. Tukey's objective
is not convex, so two solvers from one start may still end at different
roots: on 300 hard rows of 256-512 points (up to 35 % outliers, starts up to
10 sd off) Newton and IRLS agreed to 1.2e-10; with 40 % of the points shifted
alike, or a few dozen points, the scale can grow under Newton's steps and
settle elsewhere. The pipeline's rows (512 points, started from a fit of
their own data's average) are far from that.
"""

import numpy as np

from imu_square.pipeline.sine_fit import _mad0, _psi_and_deriv, fit_irls


def fit_newton(
    exog, endog, start_params, norm, *, prior_weights=None, newton_tol=None, newton_steps=12, **irls
):
    """Robust linear fits of the rows of ``endog``, started near their solution.

    Same estimate as :func:`imu_square.pipeline.sine_fit.fit_irls` with
    ``conv="coefs"`` (every coefficient moves less than ``tol`` in the last
    step), the scale re-estimated at every step; only the coefficients are
    returned.

    Parameters
    ----------
    exog : ndarray, shape (n_obs, n_params)
        Design matrix, shared by all fits, full column rank.
    endog : ndarray, shape (n_fits, n_obs)
        Observations, one fit per row. [any unit]
    start_params : ndarray, shape (n_params,) or (n_fits, n_params)
        Starting coefficients, near the solution (e.g. the fit of the data the
        rows resample). [unit of endog]
    norm : statsmodels.robust.norms.RobustNorm
        The robust norm.
    prior_weights : ndarray, shape (n_obs,) or (n_fits, n_obs), optional
        Inverse relative variance of each observation, 0 where it holds no data
        (as in ``fit_irls``). All ones if None.
    newton_tol : float or ndarray of shape (n_fits,) or (n_fits, n_params), optional
        Largest change of the coefficients in the last Newton step: for all
        rows, each row, or each coefficient of each row (inf: not watched);
        ``irls``'s ``tol`` if None. [unit of endog]
    newton_steps : int
        Newton steps before a row is handed to IRLS.
    **irls
        ``fit_irls``'s options (``tol``, ``maxiter``, ``freeze_scale_after``)
        for the rows it takes over; with ``conv="dev"`` every row goes to it.

    Returns
    -------
    params : ndarray, shape (n_fits, n_params)
        The coefficients. [unit of endog]
    handed_over : int
        How many rows IRLS finished.
    """
    exog = np.asarray(exog, dtype=np.float64)
    endog = np.atleast_2d(np.asarray(endog, dtype=np.float64))
    n, p = exog.shape
    start = np.broadcast_to(np.asarray(start_params, dtype=np.float64), (endog.shape[0], p))
    params = start.copy()
    tol = irls.get("tol", 1e-8) if newton_tol is None else newton_tol
    tol = np.asarray(tol, dtype=np.float64)
    tol = np.broadcast_to(tol[:, None] if tol.ndim == 1 else tol, (endog.shape[0], p))
    prior = None
    if prior_weights is not None:  # one row for all fits too, as in fit_irls
        prior = np.broadcast_to(np.asarray(prior_weights, dtype=np.float64), endog.shape)
    if prior is not None:
        present = prior > 0
        endog = np.where(present, endog, 0.0)
        root = np.sqrt(prior)
    outer = (exog[:, :, None] * exog[:, None, :]).reshape(n, p * p)
    newton = np.full(endog.shape[0], irls.get("conv", "coefs") == "coefs")
    active = newton.copy()
    for _ in range(newton_steps):
        idx = np.flatnonzero(active)
        if idx.size == 0:
            break
        rows = slice(None) if idx.size == active.size else idx  # all rows: views, no copies
        z = params[rows] @ exog.T
        np.subtract(endog[rows], z, out=z)
        if prior is not None:
            z *= root[rows]
        scale = _mad0(z, None if prior is None else present[rows])  # of |z|: z is kept
        usable = scale > 0.0  # else an exact fit: nothing to move
        z /= np.where(usable, scale, 1.0)[:, None]
        psi, dpsi = _psi_and_deriv(norm, z, overwrite=True)
        if prior is not None:
            psi *= root[rows]
            dpsi *= prior[rows]
        hessian = (dpsi @ outer).reshape(-1, p, p)
        definite = _positive_definite(hessian)
        newton[idx[usable & ~definite]] = False  # IRLS takes these over
        usable &= definite
        hessian[~usable] = np.eye(p)
        step = np.linalg.solve(hessian, (psi @ exog)[..., None])[..., 0]
        step *= np.where(usable, scale, 0.0)[:, None]
        params[idx] += step
        active[idx] = usable & np.any(np.abs(step) > tol[idx], axis=-1)
    rest = np.flatnonzero(~newton | active)
    if rest.size:
        options = {k: v for k, v in irls.items() if k != "covariance"}
        again = fit_irls(
            exog,
            endog[rest],
            norm,
            start_params=start[rest],
            prior_weights=None if prior is None else prior[rest],
            covariance=False,
            **options,
        )
        params[rest] = again.params
    return params, int(rest.size)


def first_order_params(exog, fit, row, norm, change):
    """Coefficients of a fit after a change of its data, to first order.

    At an M-estimate, ``sum p_i psi(z_i) x_i = 0``; a change ``dy`` of the data
    moves the coefficients by ``(X^T P D X)^-1 X^T P D dy`` with ``D = psi'(z)``
    (the scale held). A start for :func:`fit_newton` on resampled data.

    Parameters
    ----------
    exog : ndarray, shape (n_obs, n_params)
        Design matrix of the fit.
    fit : FitResult
        The converged fits (:func:`imu_square.pipeline.sine_fit.fit_irls`).
    row : int
        Which of its fits.
    norm : statsmodels.robust.norms.RobustNorm
        Its robust norm.
    change : ndarray, shape (n_changes, n_obs)
        Changes of its data, one per row; ignored where it held none. [unit of endog]

    Returns
    -------
    ndarray, shape (n_changes, n_params)
        The fit's coefficients plus their first-order change; the fit's own
        where its ``psi'`` sum is not positive definite. [unit of endog]
    """
    prior = fit.prior_weights[row]
    z = np.nan_to_num(fit.resid[row]) * np.sqrt(prior) / fit.scale[row]
    _, dpsi = _psi_and_deriv(norm, z, overwrite=True)
    dpsi *= prior
    hessian = (exog.T * dpsi) @ exog
    params = np.broadcast_to(fit.params[row], (change.shape[0], exog.shape[1]))
    if not _positive_definite(hessian[None])[0]:
        return params.copy()
    if not np.all(prior > 0):
        change = np.where(prior > 0, change, 0.0)  # NaN where the fit held no data
    gradient = change @ (exog * dpsi[:, None])
    return params + np.linalg.solve(hessian, gradient.T).T


def _positive_definite(matrices):
    # Sylvester's criterion: every leading minor positive. Written out for 2x2 and 3x3
    # (the sine and cross-term fits): np.linalg.det costs ten times more on small batches.
    h = matrices
    p = h.shape[-1]
    if p > 3:
        return np.all([np.linalg.det(h[:, :k, :k]) > 0 for k in range(1, p + 1)], axis=0)
    a = h[:, 0, 0]
    if p == 1:
        return a > 0
    minor2 = a * h[:, 1, 1] - h[:, 0, 1] * h[:, 1, 0]
    if p == 2:
        return (a > 0) & (minor2 > 0)
    det = (
        a * (h[:, 1, 1] * h[:, 2, 2] - h[:, 1, 2] * h[:, 2, 1])
        - h[:, 0, 1] * (h[:, 1, 0] * h[:, 2, 2] - h[:, 1, 2] * h[:, 2, 0])
        + h[:, 0, 2] * (h[:, 1, 0] * h[:, 2, 1] - h[:, 1, 1] * h[:, 2, 0])
    )
    return (a > 0) & (minor2 > 0) & (det > 0)
