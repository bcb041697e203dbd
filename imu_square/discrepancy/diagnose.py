"""Fit a fixed set of effects to a recording: each size's estimate and its uncertainty.

The discrepancy workflow (:func:`~imu_square.discrepancy.find_discrepancy`)
searches the vocabulary for the effects a recording needs. A monitor knows the
effects it watches and asks for their sizes every night, named or not: a
trend has to start below the detection limit to be seen early.
:func:`fit_effects` fits them all at once, with the base model:

1. the base model is fitted (:func:`~imu_square.discrepancy.workflow.fit_base`);
2. every effect of the set joins it with its shapes held (a time constant, a
   frequency, a flag: the values given, else the declared typical ones) and
   its sizes at zero;
3. sizes that one circle test cannot determine are held at zero and said to
   be so, by the rule of the screening
   (:data:`~imu_square.discrepancy.selection.IDENTIFIABLE_SD`): a common servo
   lag of both axes is the time anchor, so the servo mismatch is fitted as
   one axis's lag;
4. Gauss-Newton steps on the whitened fit vector, the Jacobian taken again
   at each but after a step that moved no parameter by more than
   :data:`REUSE_JACOBIAN_U` of its uncertainty (then the step is a chord
   step on the last one). The first :data:`UNCLIPPED_STEPS` take the unclipped residual:
   the effects not yet in the model stand beyond the clipping at a few noise
   sigmas (:data:`~imu_square.discrepancy.model_fit.CLIP_SIGMA`), where the
   clipped residual would show only a few sigmas of a friction spike many
   times larger; and the time lags move the spikes' onsets, so the
   derivatives by the anchors and the lags change completely once the spikes
   are in the model (the second step is the first with them right). More
   unclipped steps follow, up to :data:`UNCLIPPED_MAX` in all, while one
   still moves a parameter by more than :data:`UNCLIPPED_UNTIL_U` of its
   uncertainty: a backlash of microns leaves the sensor's rotation and the
   time anchors hundreds of u off after two steps, from where clipped steps
   crawl a few u a step (measured: 8 steps left a 2 µm backlash at 1.83 µm,
   u 0.001 µm). The next steps take the clipped residual, as every fit of the workflow does,
   and stop after one that moved no parameter by more than :data:`SETTLED_U`
   of its standard uncertainty (the step after it would move them by a
   fraction of that: 0.1-0.3 u measured after a step of 0.6-0.8 u), or after
   ``max_steps``;
5. the uncertainties are the inverse Fisher information at the last step,
   scaled up by ``sqrt(rss / dof)`` when that exceeds 1 (what the fixed set
   does not explain is not white noise).

Each Jacobian costs one simulator run per parameter (the base model's come
with its fit): on the paper's test (200 s at 1 kHz) with six effects, about
80 runs and 2-3.5 s in all (``benchmarks/diagnostics.py``).
"""

import math
import time
from dataclasses import dataclass, field, replace

import numpy as np
from scipy import linalg

from imu_square.blas import one_blas_thread
from imu_square.discrepancy.parameters import effect_model_parameters
from imu_square.discrepancy.result import FittedValue
from imu_square.discrepancy.selection import IDENTIFIABLE_SD
from imu_square.discrepancy.workflow import fit_base
from imu_square.errors import ConfigError
from imu_square.simulate.effects import SIZE

# Gauss-Newton steps on the unclipped residual before the clipped ones.
UNCLIPPED_STEPS = 2
# ... and more of them, up to UNCLIPPED_MAX, while one moves a parameter by more than this many
# of its standard uncertainties: a large effect (a backlash of microns) leaves the rotation
# and the time anchors far off after two steps, where clipped steps crawl.
UNCLIPPED_UNTIL_U = 10.0
UNCLIPPED_MAX = 5
# A step that moved no parameter by more than this many of its standard uncertainties keeps
# the Jacobian for the next (a chord step: one simulator run instead of one a parameter). So
# close, the derivatives do not change: a clean recording's fit moves 1.4 u, then 0.06 u;
# the demo machine's (all six effects) 1137 u, 32 u, 4.3 u, then 0.13 u.
REUSE_JACOBIAN_U = 5.0
# The steps stop after a clipped one that moved no parameter by more than this many of its
# standard uncertainties.
SETTLED_U = 1.0


@dataclass(frozen=True)
class EffectFit:
    """A fixed set of effects fitted to one recording.

    Attributes
    ----------
    values : tuple of FittedValue
        Every size of every effect, named ``effect.parameter`` (the names of
        ``imu-square discrepancy``), in the order of the effects and their
        declarations; a size held because this test cannot determine it has
        ``identifiable=False``, value 0 and ``u_value`` NaN. [display units]
    covariance : ndarray, shape (n, n)
        Covariance of :attr:`values` (scaled as their uncertainties); rows and
        columns of a held size are zero. [display units^2]
    shapes : dict of str to float
        The shapes held, ``effect.parameter`` to value. [display units]
    rss : float
        Residual sum of squares of the fit vector at the fit (``-2 log L`` up
        to a constant).
    dof : int
        Components of the fit vector less the parameters fitted.
    scale : float
        ``max(1, sqrt(rss / dof))``, by which the Fisher uncertainties were
        multiplied. [1]
    steps : int
        Gauss-Newton steps taken.
    settled : bool
        Whether the last step moved no parameter by more than :data:`SETTLED_U`
        of its uncertainty.
    last_step_u : float
        The largest move of a parameter in the last step, in its standard
        uncertainties. [1]
    evaluations : int
        Simulator runs.
    timings_s : dict of str to float
        ``base_fit`` (the pipeline, the features and the base model) and
        ``effects`` (the steps). [s]
    """

    values: tuple
    covariance: np.ndarray
    shapes: dict
    rss: float
    dof: int
    scale: float
    steps: int
    settled: bool
    last_step_u: float
    evaluations: int
    timings_s: dict = field(default_factory=dict)

    def value(self, key):
        """The :class:`FittedValue` named ``key`` (``effect.parameter``)."""
        for v in self.values:
            if v.name == key:
                return v
        raise KeyError(key)


def _held_shapes(effects, shapes):
    """The effects' parameters, and the state changes that set their shapes."""
    sizes, held = [], {}
    for effect in effects:
        given = dict(shapes.get(effect, {}))
        for p in effect_model_parameters(effect):
            if p.role == SIZE:
                sizes.append(p)
            else:
                value = given.pop(p.name, p.declared.typical)
                held[p] = float(value)
        if given:
            names = sorted(p.name for p in effect_model_parameters(effect) if p.role != SIZE)
            raise ConfigError(
                f"shape of {effect}: unknown parameter {sorted(given)[0]!r}; allowed: {names}"
            )
    return sizes, held


def _identifiable(problem, state, base, sizes):
    """The sizes this test determines: pivoted QR of their derivatives, base projected out.

    ``state`` is the base model's fit with the effects' shapes held and their
    sizes zero; a shape does nothing while its sizes are zero, so the base
    model's own derivatives at its fit stand for the base parameters (one
    simulator run a base parameter fewer).
    """
    n_base = len(base.params)
    cols = problem.columns(state, sizes)
    jac = np.column_stack([base.jacobian, *(problem.space.fit_vector(c) for c in cols)])
    q, _ = np.linalg.qr(jac[:, :n_base])
    m = jac[:, n_base:]
    m = m - q @ (q.T @ m)
    span = np.array([p.declared.high - p.declared.low for p in sizes]) / 2
    _, rr, piv = linalg.qr(m * span, mode="economic", pivoting=True)
    diag = np.abs(np.diag(rr))
    rank = int(np.sum((diag >= IDENTIFIABLE_SD) & (diag >= 1e-8 * diag.max())))
    keep = sorted(piv[:rank].tolist())
    columns = [*range(n_base), *(n_base + i for i in keep)]
    return [sizes[i] for i in keep], jac[:, columns]


def _unclipped(problem, state):
    """The fit vector of recording minus model, nothing clipped."""
    model = problem.model
    features = model.operator.transform(problem.data_xy - problem.samples(state))
    return problem.space.fit_vector(replace(features, prior=-model.prior(state)))


@one_blas_thread()  # small least-squares problems (imu_square.blas)
def fit_effects(recording, program, effects, shapes=None, analysis=None, max_steps=8, motion=None):
    """Fit a fixed set of effects to a recording (module docstring).

    Parameters
    ----------
    recording : Recording
        The test as recorded.
    program : TestProgram
        The program it ran.
    effects : sequence of str
        Effects of the vocabulary (:data:`imu_square.simulate.presets.EFFECTS`).
    shapes : dict of str to dict of str to float, optional
        Shape values to hold, by effect and parameter (display units); the
        declared typical value for a shape not given.
    analysis : AnalysisOptions, optional
        The pipeline's options (no bootstrap by default).
    max_steps : int
        Most Gauss-Newton steps (at least one clipped after the unclipped ones).
    motion : SampledMotion, optional
        The commanded motion the model takes (a controller's); our own
        trajectory when None.

    Returns
    -------
    EffectFit

    Raises
    ------
    AnalysisError
        Where the pipeline refuses the recording.
    ConfigError
        An effect outside the vocabulary, or a shape it does not have.
    """
    effects = tuple(dict.fromkeys(effects))
    sizes, held = _held_shapes(effects, shapes or {})
    t0 = time.perf_counter()
    problem, base, base_params = fit_base(recording, program, analysis, motion=motion)
    t1 = time.perf_counter()
    start = base.state
    for p, value in held.items():
        start = p.set(start, value)
    free, jac = _identifiable(problem, start, base, sizes)
    params = [*base_params, *free]
    x = np.array([p.get(start) for p in params])
    state, steps, clipped = start, 0, False
    while True:
        if clipped:
            r = problem.space.fit_vector(problem.residual(state))
        else:
            r = _unclipped(problem, state)
        cov = np.linalg.pinv(jac.T @ jac)
        dx = cov @ (jac.T @ r)
        x = x + dx
        for p, v in zip(params, x, strict=True):
            state = p.set(state, float(v))
        steps += 1
        moved = np.max(np.abs(dx) / np.sqrt(np.maximum(np.diag(cov), 1e-300)))
        if steps >= max(max_steps, UNCLIPPED_STEPS + 1) or (clipped and moved <= SETTLED_U):
            break
        clipped = (
            clipped
            or steps >= UNCLIPPED_MAX
            or (steps >= UNCLIPPED_STEPS and moved <= UNCLIPPED_UNTIL_U)
        )
        if moved > REUSE_JACOBIAN_U:
            jac = np.column_stack(
                [problem.space.fit_vector(c) for c in problem.columns(state, params)]
            )
    rss = problem.rss(state)
    dof = max(jac.shape[0] - len(params), 1)
    scale = max(1.0, math.sqrt(rss / dof))
    u = np.sqrt(np.maximum(np.diag(cov), 0.0)) * scale
    fitted = {p.key: (x[i], u[i]) for i, p in enumerate(params)}
    at = [next(i for i, q in enumerate(params) if q.key == p.key) for p in sizes if p.key in fitted]
    free_at = [i for i, p in enumerate(sizes) if p.key in fitted]
    covariance = np.zeros((len(sizes), len(sizes)))
    covariance[np.ix_(free_at, free_at)] = cov[np.ix_(at, at)] * scale**2
    values = tuple(
        FittedValue(p.key, float(fitted[p.key][0]), float(fitted[p.key][1]), p.unit)
        if p.key in fitted
        else FittedValue(p.key, 0.0, math.nan, p.unit, identifiable=False)
        for p in sizes
    )
    return EffectFit(
        values=values,
        covariance=covariance,
        shapes={p.key: v for p, v in held.items()},
        rss=rss,
        dof=int(dof),
        scale=scale,
        steps=steps,
        settled=bool(moved <= SETTLED_U),
        last_step_u=float(moved),
        evaluations=problem.model.evaluations,
        timings_s={"base_fit": t1 - t0, "effects": time.perf_counter() - t1},
    )
