"""Fit the simulator to a recording: least squares on the whitened cycle-averaged traces.

:class:`Problem` ties the forward model, the recording's features and the
noise model together. Its residual is the whitened fit vector of
``recording - model`` (:meth:`FeatureSpace.fit_vector`), so the residual sum
of squares is ``-2 log L`` up to a constant and differences of it between
nested models are likelihood-ratio statistics. The minimisation is
:func:`scipy.optimize.least_squares` (trust region); its Jacobian is the
simulator's own finite differences, one evaluation per parameter.
"""

from dataclasses import dataclass, replace

import numpy as np
from scipy.optimize import least_squares

from imu_square.log import logger

# Residual samples are held within this many standard deviations of the white noise.
CLIP_SIGMA = 4.0
# Most evaluations of the residual a fit takes (the fit "to convergence" of the workflow).
FIT_NFEV = 12


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


def _remember(store, state, compute, keep=4):
    """``compute()`` for ``state``, kept (by identity) for the ``keep`` states last asked.

    The least recently asked goes first: a Jacobian's columns ask for their
    state once a column, so it outlasts the perturbed ones and the next
    step's residual finds it (first in, first out evicted it after four
    columns: a simulator run more a Jacobian).
    """
    key = id(state)
    if key in store and store[key][0] is state:
        store[key] = store.pop(key)  # now the most recent
        return store[key][1]
    value = compute()
    if len(store) >= keep:
        store.pop(next(iter(store)))
    store[key] = (state, value)
    return value


class Problem:
    """The recording, its noise floor and the forward model.

    The residual is formed sample by sample, ``recording - model``, and each
    sample is held within ``CLIP_SIGMA`` standard deviations of the white
    noise before the features are taken (a Huber-like loss). With the model
    right and the noise Gaussian that touches 6 samples in 100 000 and the
    statistics are unchanged; it bounds the pull of what the model does not
    have yet, and of the simulator's friction spike and vibration, which
    start with a step in acceleration sampled without an anti-aliasing
    filter: one sample on the wrong side of such a step would otherwise cost
    ``(h / sigma)^2``, hundreds, and make the likelihood a staircase in the
    time parameters.

    Parameters
    ----------
    model : ForwardModel
        The simulator at the analysed samples.
    space : FeatureSpace
        Whitening and views.
    data_xy : ndarray, shape (m, 2)
        The recording's x and y at the analysed samples. [m/s^2]
    """

    def __init__(self, model, space, data_xy):
        self.model = model
        self.space = space
        self.data_xy = np.asarray(data_xy, dtype=np.float64)
        self.clip = CLIP_SIGMA * np.sqrt(space.noise.sigma2)
        self._samples = {}
        self._residuals = {}

    def samples(self, state):
        """The model's x and y at the analysed samples, remembered for the last few states."""
        return _remember(self._samples, state, lambda: self.model.samples(state))

    def residual(self, state):
        """Features of recording minus model (samples clipped), with the anchors' prior."""

        def compute():
            r = self.data_xy - self.samples(state)
            np.clip(r, -self.clip, self.clip, out=r)
            return replace(self.model.operator.transform(r), prior=-self.model.prior(state))

        return _remember(self._residuals, state, compute)

    def change(self, start, end):
        """Features of how the model changes from one state to another (nothing clipped)."""
        f = self.model.operator.transform(self.samples(end) - self.samples(start))
        return replace(f, prior=self.model.prior(end) - self.model.prior(start))

    def rss(self, state):
        """Residual sum of squares of the fit vector."""
        return float(np.sum(self.space.fit_vector(self.residual(state)) ** 2))

    def columns(self, state, params):
        """Finite-difference derivatives of the model's features (nothing clipped).

        Parameters
        ----------
        state : ModelState
            Where.
        params : sequence of Parameter
            By which parameters (display units).

        Returns
        -------
        list of Features
        """
        out = []
        for p in params:
            v = p.get(state)
            h = p.step if v + p.step <= p.high else -p.step
            out.append(self.change(state, p.set(state, v + h)).scaled(1.0 / h))
        return out

    def fit(self, state, params, max_nfev=FIT_NFEV):
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
                # the sum of squares is ~ the number of components (10^4): a relative
                # 1e-6 is a change of ~0.01 in -2 log L, below any test's resolution
                ftol=1e-6,
                xtol=1e-6,
                gtol=1e-8,
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
