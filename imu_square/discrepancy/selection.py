"""Grow the model: add the candidate effect that best explains the gap, refit, repeat.

Each step:

1. *Screen* every candidate not yet in the model at the current fit. For an
   effect with shape parameters (a time constant, a frequency, a flag) its
   declared ``scan`` values are tried first: one simulator run per grid
   point, scored by the likelihood ratio of its x and y parts (an effect
   with more sizes than the two channels: one run per size). At the best
   grid point the derivative by each size parameter is taken (a finite
   difference of the simulator). Sizes whose whole physical range moves the
   fit vector by less than one standard deviation beyond what the current
   model can already do are *not identifiable* in this test and stay at
   zero (pivoted QR of the profiled derivatives). The linearised
   likelihood-ratio statistic of the rest is ``LR = |P r|^2`` with ``r`` the
   whitened residual and ``P`` the projection on the derivatives with the
   current model's own derivatives projected out; under the null it is
   chi-square with as many degrees of freedom as identifiable sizes.
2. The best few candidates by screening are refitted with all effects so
   far (:meth:`Problem.fit`: sizes and shapes free, flags held; a single
   size is first scanned on a grid). The likelihood-ratio statistic of each
   is the drop of the residual sum of squares; its p-value is the larger of
   that statistic's and of its sizes' Wald statistic's (the model's fit can
   be short of its optimum on a staircase likelihood, and a refit would
   credit the candidate with the rest), times ``G``, the shapes tried
   (Bonferroni). The best refit is the step: refitted to convergence if
   either p-value is within reach (a trial's two iterations can leave a
   shape short of its optimum, a ringing's damping traded for its size,
   and its sizes' Wald test then weak), the larger taken again there. A
   trial that ends worse than the model it extends started outside the
   linear region; if its screening promised more than the best trial
   realised, it is refitted from the model itself, and counts if it
   realises ``RESCUED_SHARE`` of that promise (the other trials are then
   converged too).
3. It joins the model if its adjusted p-value is below ``alpha / m``
   (Bonferroni over the ``m`` candidates still out), ``alpha`` the stated
   significance level (1 % by default); else the growth stops. Effects
   added before that the new one makes redundant are dropped (a Wald test
   on their sizes) and may be added again later.

Candidates that explain the gap as well as the one added, within
``chi2.isf(alpha_separation, 1)`` of its statistic, cannot be told apart
from it at this noise level: the step names them together ("one of"), and
fits each, so that the user sees every reading. The step's statistic is
that of a converged fit, a look-alike's of a trial fit two iterations
short: a look-alike whose trial is within the added one's own gain from
convergence is refitted to convergence before the comparison.
"""

import copy
import itertools
from dataclasses import dataclass, field, replace

import numpy as np
from scipy import linalg, stats

from imu_square.discrepancy.features import NYQUIST_FRACTION, Features
from imu_square.discrepancy.model_fit import FIT_NFEV
from imu_square.discrepancy.parameters import effect_model_parameters
from imu_square.log import logger
from imu_square.simulate.effects import SHAPE, SIZE

# Shape grids longer than FULL_SCAN are scanned at every COARSE_STEP-th point first
# (a product of two shapes' grids, up to FULL_SCAN points, is scanned whole: every third
# point of its flattened order would see one value of the faster-varying shape only).
COARSE_STEP = 3
FULL_SCAN = 16
# A candidate whose screening p-value is within this factor of the level is refitted,
# and the refit's likelihood ratio decides (the shape grid may miss the best shape).
REFIT_SLACK = 10.0
# At each step the best few candidates by screening are refitted; the best refit is added.
REFIT_TOP = 3
# ... those whose screening statistic is at least this fraction of the best's.
COMPETITIVE = 0.25
# Trial refits take this many evaluations of the residual; the chosen one is then
# refitted to convergence.
TRIAL_NFEV = 2
# A trial that ended worse than its model, refitted from the model, counts when it
# realises this share of its screening's likelihood ratio.
RESCUED_SHARE = 0.5
# Grid points of the scan of a candidate with a single identifiable size.
SCAN_POINTS = 13
# A size is identifiable when its whole physical range moves the fit vector by
# at least this many standard deviations beyond what the model already does.
IDENTIFIABLE_SD = 1.0


@dataclass
class Screen:
    """One candidate screened at a fitted model.

    Attributes
    ----------
    effect : str
        Its name.
    shape : dict of str to float
        The shape values (display units) at the best grid point.
    grid_size : int
        Grid points tried.
    informative : list of Parameter
        Its identifiable sizes.
    fixed : list of Parameter
        Its sizes that are not identifiable here (held at zero).
    vectors : ndarray, shape (n, q)
        Fit-vector derivatives by the identifiable sizes.
    lr : float
        Linearised likelihood-ratio statistic at the last screening.
    dof : int
        Its degrees of freedom (identifiable sizes).
    p_value, p_adjusted : float
        ``chi2.sf(lr, dof)`` and that times the grid size (capped at 1).
    coef, cov : ndarray
        Linearised estimates of the identifiable sizes and their covariance. [display units]
    grid : list
        ``(shape dict, fit-vector directions)`` of every grid point run (:meth:`_directions`).
    inert : set of str
        Keys of the sizes not identifiable at the first screening.
    forms : list of dict
        The best grid point of each other form (a flag scanned along another
        shape, such as the spike's symmetric bump): the refit decides.
    """

    effect: str
    shape: dict
    grid_size: int
    informative: list
    fixed: list
    vectors: np.ndarray
    lr: float = 0.0
    dof: int = 0
    p_value: float = 1.0
    p_adjusted: float = 1.0
    coef: np.ndarray = field(default_factory=lambda: np.zeros(0))
    cov: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    grid: list = field(default_factory=list)
    inert: set | None = None
    forms: list = field(default_factory=list)


def _shape_grid(params, sample_rate_hz):
    shapes = [p for p in params if p.role == SHAPE]
    # a shape scanned along another joins that one's grid axis, value by value
    along = {p.declared.scan_along: p for p in shapes if p.declared.scan_along}
    axes = []
    for p in shapes:
        if p.declared.scan_along:
            continue
        scan = p.declared.scan or (p.declared.typical,)
        if p.unit == "Hz":  # above the compared band a frequency only aliases
            scan = tuple(v for v in scan if v < NYQUIST_FRACTION * sample_rate_hz) or scan[:1]
        partner = along.get(p.declared.name)
        if partner is None:
            axes.append([{p.name: v} for v in scan])
        else:
            pairs = zip(scan, partner.declared.scan, strict=True)
            axes.append([{p.name: v, partner.name: w} for v, w in pairs])
    return [
        dict(kv for point in combo for kv in point.items()) for combo in itertools.product(*axes)
    ]


def _with_shape(state, params, shape):
    for p in params:
        if p.name in shape:
            state = p.set(state, shape[p.name])
    return state


def _orthonormal(jacobian):
    if jacobian.size == 0:
        return np.zeros((0, 0))
    q, r = np.linalg.qr(jacobian)
    keep = np.abs(np.diag(r)) > 1e-10 * np.max(np.abs(np.diag(r)))
    return q[:, keep]


def _perp(q, v):
    return v - q @ (q.T @ v) if q.size else v


def _lr(r, m):
    """Likelihood-ratio statistic of adding columns ``m`` (already profiled) for residual ``r``."""
    if m.shape[1] == 0:
        return 0.0, np.zeros(0), np.zeros((0, 0))
    gram = m.T @ m
    cov = np.linalg.pinv(gram)
    coef = cov @ (m.T @ r)
    return float(coef @ gram @ coef), coef, cov


class Screener:
    """Screens candidate effects at fitted models of one problem.

    Parameters
    ----------
    problem : Problem
        The recording and the forward model.
    """

    def __init__(self, problem):
        self.problem = problem
        self._basis = None
        space = problem.space
        template = problem.model.operator.transform(np.zeros_like(problem.data_xy))
        ones = replace(template, prior=np.zeros(problem.model.n_blocks))
        self.channel = []
        for a in range(2):
            blk = ones.block.copy()
            cyc = ones.cycle.copy()
            transient = ones.transient.copy()
            blk[:, a] = 1 + 1j
            cyc[:, a] = 1 + 1j
            transient[a] = 1.0
            self.channel.append(
                space.fit_vector(Features(blk, cyc, ones.reversal, transient, ones.prior)) != 0
            )

    def _score(self, screen, r, q):
        m = _perp(q, screen.vectors)
        screen.lr, screen.coef, screen.cov = _lr(r, m)
        screen.dof = m.shape[1]
        screen.p_value = float(stats.chi2.sf(screen.lr, screen.dof)) if screen.dof else 1.0
        screen.p_adjusted = min(1.0, screen.p_value * screen.grid_size)

    def _directions(self, state, params, shape):
        """Fit-vector directions of a shape, one per size (or per channel).

        The channel split of one run tells an x size from a y size; an effect
        with more sizes than channels runs each on its own (set together, the
        sizes would be scored in one fixed ratio: a ringing's in-phase and
        quadrature sizes at one phase, whose likelihood then peaks in frequency
        narrower than the grid).
        """
        sizes = [p for p in params if p.role == SIZE]
        s = _with_shape(state, params, shape)

        def run(group):
            end = s
            for p in group:
                end = p.set(end, 0.1 * p.declared.typical if p.declared.typical else p.step)
            return self.problem.space.fit_vector(self.problem.change(state, end))

        if len(sizes) <= 2:
            v = run(sizes)
            return np.column_stack([v * self.channel[0], v * self.channel[1]])
        return np.column_stack([run([p]) for p in sizes])

    def _stage2(self, screen, outcome, params, q):
        problem = self.problem
        # sizes found not identifiable at the first screening stay so (another effect
        # in the model does not make, say, the z channel visible)
        inert = screen.inert or set()
        sizes = [p for p in params if p.role == SIZE and p.key not in inert]
        state = _with_shape(outcome.state, params, screen.shape)
        # the effect is off at the current model: its shape changes nothing yet
        if not sizes:
            screen.informative = []
            screen.vectors = np.zeros((problem.space.fit_vector(outcome.residual).size, 0))
            screen.fixed = [p for p in params if p.role == SIZE]
            return
        cols = problem.columns(state, sizes)
        vec = np.column_stack([problem.space.fit_vector(c) for c in cols])
        m = _perp(q, vec)
        span = np.array([p.declared.high - p.declared.low for p in sizes]) / 2
        scaled = m * span
        _, rr, piv = linalg.qr(scaled, mode="economic", pivoting=True)
        diag = np.abs(np.diag(rr))
        rank = int(np.sum((diag >= IDENTIFIABLE_SD) & (diag >= 1e-8 * diag.max())))
        keep = sorted(piv[:rank].tolist())
        screen.informative = [sizes[i] for i in keep]
        screen.fixed = [p for p in params if p.role == SIZE and p not in screen.informative]
        if screen.inert is None:
            screen.inert = {p.key for p in screen.fixed}
        screen.vectors = vec[:, keep]

    def _q(self, outcome):
        """Orthonormal basis of the current model's derivatives, once per fit."""
        if self._basis is None or self._basis[0] is not outcome:
            self._basis = (outcome, _orthonormal(outcome.jacobian))
        return self._basis[1]

    def _scan(self, outcome, params, grid, r, q):
        """Directions of the grid points worth trying: every third, then the best's neighbours."""
        scored = {}

        def score(i):
            if i not in scored:
                v = self._directions(outcome.state, params, grid[i])
                scored[i] = (v, _lr(r, _perp(q, v))[0])
            return scored[i][1]

        coarse = range(0, len(grid), COARSE_STEP) if len(grid) > FULL_SCAN else range(len(grid))
        best = max(coarse, key=score)
        for i in range(best - COARSE_STEP + 1, best + COARSE_STEP):
            if 0 <= i < len(grid):
                score(i)
        return [(grid[i], scored[i][0]) for i in sorted(scored)]

    def screen(self, effect, outcome):
        """Screen one candidate at a fitted model (simulator runs: grid (x sizes if > 2), sizes).

        Parameters
        ----------
        effect : str
            A name of the vocabulary.
        outcome : FitOutcome
            The current model (the effect's sizes are zero in it).

        Returns
        -------
        Screen
        """
        problem = self.problem
        params = effect_model_parameters(effect)
        grid = _shape_grid(params, problem.model.layout.dt_s**-1)
        screen = Screen(effect, grid[0], len(grid), [], [], np.zeros((0, 0)), inert=None)
        q = self._q(outcome)
        r = problem.space.fit_vector(outcome.residual)
        if len(grid) > 1:
            screen.grid = self._scan(outcome, params, grid, r, q)
        screen.shape = self._best_shape(screen, r, q)
        self._stage2(screen, outcome, params, q)
        self._score(screen, r, q)
        return screen

    def _best_shape(self, screen, r, q):
        if not screen.grid:
            return screen.shape
        keys = [p.name for p in effect_model_parameters(screen.effect) if p.declared.scan_along]
        best = {}
        for shape, v in screen.grid:
            form = tuple(shape[k] for k in keys)
            score = _lr(r, _perp(q, v))[0]
            if form not in best or score > best[form][0]:
                best[form] = (score, shape)
        ranked = sorted(best.values(), key=lambda b: -b[0])
        screen.forms = [shape for _, shape in ranked[1:]]
        return ranked[0][1]

    def rescreen(self, screen, outcome, fresh=False):
        """Score a screened candidate again at a new fit.

        The shape is chosen again from the directions of the grid points
        already run; the size derivatives are taken again at the new model
        when ``fresh`` (an effect added since can change them: a servo lag
        moves the friction spikes) or when the shape changed.
        """
        q = self._q(outcome)
        r = self.problem.space.fit_vector(outcome.residual)
        shape = self._best_shape(screen, r, q)
        if fresh or shape != screen.shape:
            screen.shape = shape
            self._stage2(screen, outcome, effect_model_parameters(screen.effect), q)
        self._score(screen, r, q)
        return screen


@dataclass(frozen=True)
class Step:
    """One step of the model's growth.

    Attributes
    ----------
    effect : str
        The effect added to the model.
    one_of : tuple of str
        The effects that explain the gap as well (the added one first).
    params : tuple of Parameter
        The effect's fitted parameters (identifiable sizes, then free shapes).
    fixed : tuple of Parameter
        Its sizes not identifiable in this test (held at zero).
    before, after : FitOutcome
        The model before and after the step.
    statistic : float
        Likelihood-ratio statistic (drop of the residual sum of squares).
    dof : int
        Its degrees of freedom.
    p_value : float
        Its p-value times the shape grid size (the level it is compared with
        is ``alpha / m``).
    threshold : float
        ``alpha / m``.
    alternatives : dict of str to Screen
        The screens of the look-alikes, with their linearised fits.
    dropped : tuple of str
        Effects added earlier that this step made redundant (removed).
    """

    effect: str
    one_of: tuple
    params: tuple
    fixed: tuple
    before: object
    after: object
    statistic: float
    dof: int
    p_value: float
    threshold: float
    alternatives: dict
    dropped: tuple = ()


def _refit(problem, outcome, screen, starts, max_nfev=TRIAL_NFEV):
    """Refit with the candidate added, from each start of its sizes; the best fit."""
    params = effect_model_parameters(screen.effect)
    shapes = [p for p in params if p.role == SHAPE and not p.declared.is_flag]
    best = None
    for coef in starts:
        state = _with_shape(outcome.state, params, screen.shape)
        for p, v in zip(screen.informative, coef, strict=True):
            state = p.set(state, float(v))
        new = problem.fit(state, list(outcome.params) + screen.informative + shapes, max_nfev)
        if best is None or new.rss < best.rss:
            best = new
    return best, shapes


def _scan(problem, outcome, screen, starts, sd):
    """The best value of a single size on a grid around its starts.

    Each grid point costs one simulator run; the other parameters follow by
    one Gauss-Newton step on the current model's derivatives. A lag that
    moves a sharp feature (a friction spike starts with a step in
    acceleration) makes the likelihood a staircase at the sample period,
    which a local fit does not cross.
    """
    p = screen.informative[0]
    params = effect_model_parameters(screen.effect)
    base = _with_shape(outcome.state, params, screen.shape)
    values = [float(s[0]) for s in starts]
    grid = np.linspace(min(values) - 2 * sd, max(values) + 2 * sd, SCAN_POINTS)
    q = _orthonormal(outcome.jacobian)
    best, best_rss = values[0], np.inf
    for v in grid:
        r = problem.space.fit_vector(problem.residual(p.set(base, float(v))))
        rss = float(np.sum(_perp(q, r) ** 2))
        if rss < best_rss:
            best, best_rss = float(v), rss
    return best


def _trial(problem, outcome, screen, first):
    """Refit with one candidate added: ``(adjusted p, -LR, fit, free shapes)``.

    Starts from its linearised estimate at the current model and, when that
    differs by more than 3 standard deviations from its estimate at the base
    model, from the latter too (at the base model a lag is read off the
    circle's phase alone; with a friction spike in the model since, which the
    lag moves, the local slope can mislead).
    """
    starts = [screen.coef]
    sizes0, coef0, cov0 = first
    same = [p.key for p in sizes0] == [p.key for p in screen.informative] and coef0.size
    if same:
        z = (coef0 - screen.coef) / np.sqrt(np.maximum(np.diag(cov0), 1e-300))
        if np.max(np.abs(z)) > 3:
            starts.append(coef0)
    if len(screen.informative) == 1:
        sd = np.sqrt(max(screen.cov[0, 0], cov0[0, 0] if same else 0.0))
        starts = [np.array([_scan(problem, outcome, screen, starts, sd)])]
    fit, shapes = _refit(problem, outcome, screen, starts)
    # a form screened second can refit better (a skewed spike's width between two grid
    # points screens as the symmetric bump): the refit decides
    for form in screen.forms:
        other, _ = _refit(problem, outcome, replace(screen, shape=form), starts)
        if other.rss < fit.rss:
            fit, screen.shape = other, form
    lr = outcome.rss - fit.rss
    return _p_adjusted(fit, screen, lr), -lr, fit, shapes


def _converged(problem, outcome, screen, trial):
    """A trial refitted to convergence from where it ended."""
    fit = problem.fit(trial[2].state, trial[2].params)
    lr = outcome.rss - fit.rss
    return _p_adjusted(fit, screen, lr), -lr, fit, trial[3]


def _trial_from_model(problem, outcome, screen):
    """A trial refitted from the model itself (its sizes zero), to convergence.

    For a trial whose linearised start lay outside the linear region, so that
    it ended worse than the model it extends: a servo lag added moves a
    ringing already in the model by a good part of its period.
    """
    start = [np.zeros(len(screen.informative))]
    fit, shapes = _refit(problem, outcome, screen, start, FIT_NFEV)
    lr = outcome.rss - fit.rss
    return _p_adjusted(fit, screen, lr), -lr, fit, shapes


def _p_adjusted(fit, screen, lr):
    """The step's p-value: the larger of the likelihood ratio's and its sizes' Wald test's.

    On a staircase likelihood the current model's fit is not exactly at its
    optimum, and a refit with a candidate added also collects what the
    other parameters had left: the likelihood ratio alone would credit the
    candidate with it. Its own sizes must be significant too.
    """
    keys = [p.key for p in fit.params]
    idx = [keys.index(p.key) for p in screen.informative]
    theta = np.array([p.get(fit.state) for p in screen.informative])
    wald = float(theta @ np.linalg.pinv(fit.cov[np.ix_(idx, idx)]) @ theta)
    p = max(stats.chi2.sf(lr, screen.dof), stats.chi2.sf(wald, screen.dof))
    return min(1.0, float(p) * screen.grid_size)


def _wald_drop(problem, outcome, added, threshold):
    """Remove the effects the current fit no longer needs (Wald test on their sizes).

    Parameters
    ----------
    added : dict of str to (list of Parameter, int)
        Effects in the model: their identifiable sizes and shape grid size.

    Returns
    -------
    outcome : FitOutcome
    dropped : list of str
    """
    dropped = []
    while len(added) > 1:
        keys = [p.key for p in outcome.params]
        worst, worst_p = None, 0.0
        for effect, (sizes, grid) in added.items():
            idx = [keys.index(p.key) for p in sizes]
            theta = np.array([p.get(outcome.state) for p in sizes])
            cov = outcome.cov[np.ix_(idx, idx)]
            w = float(theta @ np.linalg.pinv(cov) @ theta)
            p_val = min(1.0, float(stats.chi2.sf(w, len(sizes))) * grid)
            if p_val > worst_p:
                worst, worst_p = effect, p_val
        if worst_p <= threshold:
            break
        sizes, _ = added.pop(worst)
        params = effect_model_parameters(worst)
        state = outcome.state
        for p in params:
            if p.role == SIZE:
                state = p.set(state, 0.0)
        free = [p for p in outcome.params if p.effect != worst]
        outcome = problem.fit(state, free)
        dropped.append(worst)
        logger.debug("dropped %s (Wald p %.3g)", worst, worst_p)
    return outcome, dropped


def grow(problem, outcome, candidates, alpha=0.01, alpha_separation=0.01, max_steps=6):
    """Forward selection from the base fit, dropping effects a later one makes redundant.

    Parameters
    ----------
    problem : Problem
        The recording and the forward model.
    outcome : FitOutcome
        The base model's fit.
    candidates : sequence of str
        Effects that may be added.
    alpha : float
        Family-wise significance level of each step.
    alpha_separation : float
        Level at which a look-alike is told apart from the effect added.
    max_steps : int
        Most effects added.

    Returns
    -------
    steps : list of Step
    outcome : FitOutcome
        The final model.
    screens : dict of str to Screen
        Every candidate's screen at the final model.
    """
    screener = Screener(problem)
    screens = {e: screener.screen(e, outcome) for e in candidates}
    first = {
        e: (list(s.informative), np.array(s.coef), np.array(s.cov)) for e, s in screens.items()
    }
    logger.debug(
        "screened %d candidates with %d simulator runs", len(screens), problem.model.evaluations
    )
    remaining = list(candidates)
    added = {}
    steps = []
    crit_sep = float(stats.chi2.isf(alpha_separation, 1))
    fresh = False
    screened_at = None
    while remaining and len(steps) < max_steps:
        for e in remaining:
            screener.rescreen(screens[e], outcome, fresh)
        fresh, screened_at = True, outcome
        threshold = alpha / len(remaining)
        ranked = sorted(remaining, key=lambda e: (screens[e].p_adjusted, -screens[e].lr))
        top_lr = max(screens[e].lr for e in ranked[:1])
        promising = [
            e
            for e in ranked[:REFIT_TOP]
            if screens[e].dof
            and screens[e].p_adjusted <= REFIT_SLACK * threshold
            and screens[e].lr >= COMPETITIVE * top_lr
        ]
        if not promising:
            break
        # the linearised screening can misjudge an effect that moves one already in
        # the model (a lag moves the friction spikes): refit the few best, keep the best
        trials = {}
        for e in promising:
            trials[e] = _trial(problem, outcome, screens[e], first[e])
        # a trial that ended worse than its model, whose screening promised more than the
        # best trial realised, could be the step: refitted from the model to convergence.
        # It counts if it realises at least RESCUED_SHARE of that promise (else the screen
        # saw a direction the model does not follow, and a converged fit would credit the
        # candidate with the rest: a common first-order lag for a backlash of another
        # shape); the others are then converged too, so that converged fits are compared
        realised = max(-t[1] for t in trials.values())
        rescued = {}
        for e in promising:
            if trials[e][1] > 0 and screens[e].lr > realised:
                rescue = _trial_from_model(problem, outcome, screens[e])
                if -rescue[1] >= RESCUED_SHARE * screens[e].lr:
                    rescued[e] = rescue
        if rescued:
            for e in promising:
                trials[e] = rescued.get(e) or _converged(problem, outcome, screens[e], trials[e])
        best = min(trials, key=lambda e: trials[e][:2])
        p_adj, neg_lr, new, shapes = trials[best]
        lr = -neg_lr
        sb = screens[best]
        logger.debug(
            "step %d: %s LR %.1f (screen %.1f), p %.3g", len(steps) + 1, best, lr, sb.lr, p_adj
        )
        # the trial's two iterations may leave a shape short of its optimum (a ringing seen
        # only after its onset trades its size for its damping): the likelihood ratio alone
        # decides whether to converge; the Wald test is then taken at the converged fit
        p_lr = min(1.0, float(stats.chi2.sf(lr, sb.dof)) * sb.grid_size)
        if min(p_adj, p_lr) > REFIT_SLACK * threshold:
            break
        new = problem.fit(new.state, new.params)
        gain = max(outcome.rss - new.rss + neg_lr, 0.0)
        lr = outcome.rss - new.rss
        p_adj = _p_adjusted(new, sb, lr)
        if p_adj > threshold:
            break
        # look-alikes: candidates whose own refit explains the gap within crit_sep as well
        for e in remaining:
            if e not in trials and screens[e].dof and screens[e].lr >= lr - crit_sep:
                trials[e] = _trial(problem, outcome, screens[e], first[e])
        # a trial is two iterations short of its optimum, as the best's was: those that
        # its own convergence could bring within crit_sep are refitted to convergence too
        for e in trials:
            if e != best and -trials[e][1] >= lr - crit_sep - gain:
                fit = trials[e][2]
                fit = problem.fit(fit.state, fit.params)
                trials[e] = (trials[e][0], fit.rss - outcome.rss, fit, trials[e][3])
        look = [e for e in trials if e != best and -trials[e][1] >= lr - crit_sep]
        added[best] = (list(sb.informative), sb.grid_size)
        after, dropped = _wald_drop(problem, new, added, threshold)
        steps.append(
            Step(
                effect=best,
                one_of=(best, *look),
                params=tuple(sb.informative + shapes),
                fixed=tuple(sb.fixed),
                before=outcome,
                after=after,
                statistic=float(lr),
                dof=sb.dof,
                p_value=p_adj,
                threshold=threshold,
                # as screened now: later screenings rebind their fields
                alternatives={e: copy.copy(screens[e]) for e in look},
                dropped=tuple(dropped),
            )
        )
        remaining.remove(best)
        remaining += [e for e in dropped if e not in remaining]
        outcome = after
    if screened_at is not outcome:
        for e in remaining:
            screener.rescreen(screens[e], outcome, fresh=bool(steps))
    return steps, outcome, screens
