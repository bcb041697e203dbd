"""Fit the simulator to a recording: least squares on the whitened cycle-averaged traces.

:class:`Problem` ties the forward model, the recording's features and the
noise model together. Its residual is the whitened fit vector of
``recording - model`` (:meth:`FeatureSpace.fit_vector`), so the residual sum
of squares is ``-2 log L`` up to a constant and differences of it between
nested models are likelihood-ratio statistics. The minimisation is
:func:`scipy.optimize.least_squares` (trust region); its Jacobian is the
simulator's own finite differences, one evaluation per parameter.
"""

from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from imu_square.log import logger


@dataclass(frozen=True)
class FitOutcome:
    """A fitted model.

    Attributes
    ----------
    state : ModelState
        The fitted model.
    params : tuple of Parameter
        The parameters that were free.
    rss : float
        Residual sum of squares of the fit vector (-2 log L + const).
    residual : Features
        Features of recording minus model.
    columns : tuple of Features
        Derivative of the model's features by each free parameter (display units).
    jacobian : ndarray, shape (n, p)
        Fit vectors of :attr:`columns`.
    cov : ndarray, shape (p, p)
        Covariance of the free parameters (inverse Fisher information). [display units^2]
    """

    state: object
    params: tuple
    rss: float
    residual: object
    columns: tuple
    jacobian: np.ndarray
    cov: np.ndarray

    def value(self, param):
        """A parameter's fitted value (display units)."""
        return param.get(self.state)

    def uncertainty(self, param):
        """Standard uncertainty of a free parameter (display units); NaN if it was fixed."""
        for i, p in enumerate(self.params):
            if p.key == param.key:
                return float(np.sqrt(max(self.cov[i, i], 0.0)))
        return float("nan")


class Problem:
    """The recording, its noise floor and the forward model.

    Parameters
    ----------
    model : ForwardModel
        The simulator at the analysed samples.
    space : FeatureSpace
        Whitening and views.
    data : Features
        Features of the recording.
    """

    def __init__(self, model, space, data):
        self.model = model
        self.space = space
        self.data = data
        self._cache = None

    def model_features(self, state):
        """Features of the model, remembered for the last state asked."""
        if self._cache is not None and self._cache[0] is state:
            return self._cache[1]
        f = self.model.features(state)
        self._cache = (state, f)
        return f

    def residual(self, state):
        """Features of recording minus model."""
        return self.data - self.model_features(state)

    def rss(self, state):
        """Residual sum of squares of the fit vector."""
        return float(np.sum(self.space.fit_vector(self.residual(state)) ** 2))

    def columns(self, state, params, at=None):
        """Finite-difference derivatives of the model's features.

        Parameters
        ----------
        state : ModelState
            Where.
        params : sequence of Parameter
            By which parameters (display units).
        at : Features, optional
            The model's features at ``state`` when already known.

        Returns
        -------
        list of Features
        """
        f0 = self.model_features(state) if at is None else at
        out = []
        for p in params:
            v = p.get(state)
            h = p.step if v + p.step <= p.high else -p.step
            out.append((self.model.features(p.set(state, v + h)) - f0).scaled(1.0 / h))
        return out

    def fit(self, state, params, max_nfev=12):
        """Least-squares fit of ``params`` starting from ``state``.

        Parameters
        ----------
        state : ModelState
            Start; parameters not in ``params`` stay as they are.
        params : sequence of Parameter
            The free parameters.
        max_nfev : int
            Most evaluations of the residual (each Jacobian costs one more
            evaluation per parameter).

        Returns
        -------
        FitOutcome
        """
        params = tuple(params)
        x0 = np.array([p.get(state) for p in params], dtype=float)
        lo = np.array([p.low for p in params])
        hi = np.array([p.high for p in params])
        x0 = np.clip(x0, lo, hi)
        scale = np.array([p.step for p in params]) * 10.0

        def state_at(x):
            s = state
            for p, v in zip(params, x, strict=True):
                s = p.set(s, float(v))
            return s

        memo = {}

        def at(x):
            key = x.tobytes()
            if key not in memo:
                memo.clear()
                memo[key] = state_at(x)
            return memo[key]

        def fun(x):
            return self.space.fit_vector(self.residual(at(x)))

        last = {}

        def jac(x):
            cols = self.columns(at(x), params)
            last["x"], last["cols"] = x.copy(), cols
            return -np.column_stack([self.space.fit_vector(c) for c in cols])

        if params:
            sol = least_squares(
                fun,
                x0,
                jac=jac,
                bounds=(lo, hi),
                x_scale=scale,
                method="trf",
                ftol=1e-9,
                xtol=1e-9,
                gtol=1e-10,
                max_nfev=max_nfev,
            )
            logger.debug(
                "fit of %d parameters: %d evaluations, cost %.3f, %s",
                len(params),
                sol.nfev,
                2 * sol.cost,
                sol.message,
            )
            final = at(sol.x)
            if "x" in last and np.array_equal(last["x"], sol.x):
                cols = last["cols"]
            else:  # the Jacobian at the solution, for the covariance
                cols = self.columns(final, params)
        else:
            final, cols = state, []
        jmat = (
            np.column_stack([self.space.fit_vector(c) for c in cols]) if cols else np.zeros((0, 0))
        )
        cov = np.linalg.pinv(jmat.T @ jmat) if cols else np.zeros((0, 0))
        return FitOutcome(
            state=final,
            params=params,
            rss=self.rss(final),
            residual=self.residual(final),
            columns=tuple(cols),
            jacobian=jmat,
            cov=cov,
        )

    def gaps(self, outcome):
        """Every view's gap at a fitted model (:meth:`FeatureSpace.gaps`)."""
        return self.space.gaps(outcome.residual, self.space.hat_dof(list(outcome.columns)))
