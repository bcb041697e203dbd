"""The discrepancy workflow: fit the simulator, find the gap, name and add effects, repeat.

:func:`find_discrepancy` runs, on one recording:

1. the pipeline (:func:`imu_square.pipeline.analyze`), which refuses what it
   cannot analyse and gives the starting squareness, rotation and offsets;
2. the layout of the analysed cycles and their features, and the noise floor
   from the cycle-to-cycle scatter;
3. the base model's fit: the simulator with the program of the recording (at
   the speed its circles ran, when a controller ran them at another), an
   ideal machine but for its squareness, the sensor's rotation and tilt, and
   a time anchor per block (started where the two directions' rotations agree);
4. the model's growth (:mod:`imu_square.discrepancy.selection`);
5. identifiability: signature correlations, "one of" groups and the extra
   tests that would separate them (:mod:`imu_square.discrepancy.identify`).
"""

import math
import time
from dataclasses import dataclass, field, replace

import numpy as np
from scipy.optimize import minimize

from imu_square.blas import one_blas_thread
from imu_square.discrepancy.features import FeatureOperator
from imu_square.discrepancy.forward import ForwardModel
from imu_square.discrepancy.identify import Member, signature_correlations, suggest_tests
from imu_square.discrepancy.layout import layout_from_recording, with_transients
from imu_square.discrepancy.localise import gaps_left, locate_gaps
from imu_square.discrepancy.model_fit import Problem
from imu_square.discrepancy.parameters import (
    BASE,
    ModelState,
    base_parameters,
    effect_model_parameters,
)
from imu_square.discrepancy.result import DiscrepancyResult, FittedValue, StepReport
from imu_square.discrepancy.selection import grow
from imu_square.discrepancy.transients import transient_windows
from imu_square.discrepancy.views import FeatureSpace
from imu_square.discrepancy.window_noise import estimate_noise
from imu_square.errors import AnalysisError, ConfigError
from imu_square.log import logger
from imu_square.pipeline.quality import PERIOD_LIMIT
from imu_square.pipeline.squareness import AnalysisOptions, analyze
from imu_square.simulate.effects import SIZE
from imu_square.simulate.machine import MachineModel
from imu_square.simulate.presets import EFFECTS, parse_effects
from imu_square.simulate.sensor import SensorModel
from imu_square.units import G

# The noise floor is estimated again from the residual when its variance moved more.
NOISE_CHANGE = 0.05


@dataclass(frozen=True)
class DiscrepancyOptions:
    """Choices of the discrepancy workflow.

    Attributes
    ----------
    significance : float
        Family-wise significance level of each step (Bonferroni over the
        candidates still out and the shapes tried).
    separation : float
        Level at which two candidates count as told apart.
    effects : tuple of str or None
        Candidates allowed; every effect of the vocabulary if None.
    max_steps : int
        Most effects added.
    suggest : bool
        Whether to simulate extra tests for the "one of" groups.
    analysis : AnalysisOptions
        The pipeline's options (filter of the segmentation).
    """

    significance: float = 0.01
    separation: float = 0.01
    effects: tuple | None = None
    max_steps: int = 6
    suggest: bool = True
    analysis: AnalysisOptions = field(default_factory=lambda: AnalysisOptions(bootstrap_n=0))

    def candidates(self):
        """The allowed effects, checked against the vocabulary.

        Returns
        -------
        tuple of str
            The names of the effects, all of them when ``effects`` is None.
        """
        if self.effects is None:
            return tuple(EFFECTS)
        names = tuple(dict.fromkeys(parse_effects(self.effects)))
        if not names:
            raise ConfigError(f"effects allowed: give at least one of {list(EFFECTS)}")
        return names


def _check(options):
    for name in ("significance", "separation"):
        v = getattr(options, name)
        if not (isinstance(v, float | int) and 0 < v < 1):
            raise ConfigError(f"{name} must be a probability in (0, 1), got {v!r}")


def _initial_state(recording, run, noise, n_blocks):
    cos2 = math.cos(2 * run.eps_c_rad)
    info = recording.sensor
    density = float(np.mean(noise.density_m_s2_rthz))
    geometry = replace(MachineModel().geometry, machine_squareness_rad=run.squareness_rad / cos2)
    machine = MachineModel(name=recording.machine_id or "fitted", geometry=geometry)
    offsets = [
        0.5 * (run.traces[f"ccw_{a}_params"][0] + run.traces[f"cw_{a}_params"][0]) / G
        for a in ("x", "y")
    ]
    sensor = SensorModel(
        model=info.model if info.model != "unknown" else "fitted",
        sample_rate_hz=recording.sample_rate_hz,
        noise_density_m_s2_rthz=density,
        flicker_corner_hz=float(np.mean(noise.flicker_corner_hz)),
        range_m_s2=info.range_m_s2 if math.isfinite(info.range_m_s2) else math.inf,
        resolution_m_s2=info.resolution_m_s2 if math.isfinite(info.resolution_m_s2) else 0.0,
        eps_c_rad=run.eps_c_rad + 0.5 * run.squareness_rad,
        tilt_rad=tuple(offsets),
    )
    return ModelState(machine, sensor, (_start_anchor(run),) * n_blocks)


def _rotation(direction):
    """The rotation a direction's fit reads: the circular mean of its theta_x and theta_y."""
    tx, ty = direction.theta_x_rad, direction.theta_y_rad
    return math.atan2(math.sin(tx) + math.sin(ty), math.cos(tx) + math.cos(ty))


def _start_anchor(run):
    """Where the blocks' time anchors start: where the two directions' rotations agree. [s]

    The pipeline anchors each block's position angle at the middle of its
    detected motion, which is the middle of its arc when the feed ramps
    mirror each other (our own trajectory's). A controller's need not:
    LinuxCNC's ramps down at half the acceleration it ramps up with, so on
    the fast test the tool is 37 deg short of the middle of the arc at the
    detected midpoint. That reads as a rotation of ``+delta`` in the CCW
    fit and ``-delta`` in the flipped CW fit (the mean, ``eps_c``, is
    unharmed), the signature of a time shift ``delta / omega`` of both
    blocks, which the anchors are. Started at 0, they would have to cross
    ``delta``: residuals beyond a few noise sigmas are clipped
    (:class:`~imu_square.discrepancy.model_fit.Problem`), so the fit cannot
    see the way. A common servo lag of both axes reads the same, and starts
    the anchors the same way.
    """
    delta = math.remainder(_rotation(run.ccw) - _rotation(run.cw), 2 * math.pi) / 2
    return -delta / abs(run.omega_rad_s)


def _values(outcome, params, state=None):
    state = outcome.state if state is None else state
    return tuple(FittedValue(p.name, p.get(state), outcome.uncertainty(p), p.unit) for p in params)


def _step_values(step, state):
    out = list(_values(step.after, step.params, state))
    out += [
        FittedValue(p.name, p.get(state), math.nan, p.unit, identifiable=False) for p in step.fixed
    ]
    # a choice of two (first-order servo, associated yaw): the scan's pick, held in the fit
    out += [
        FittedValue(p.name, p.get(state), math.nan, p.unit)
        for p in effect_model_parameters(step.effect)
        if p.declared.is_flag
    ]
    return tuple(out)


def _gauge(problem, outcome, steps):
    """Move non-identifiable sizes so every size lies in its physical range, model unchanged.

    A size that is not identifiable changes the fit vector only as the other
    parameters can (its derivative is theirs, combined): moving it by ``d``
    and them by ``-B d`` leaves the model as it was, to first order. The
    smallest such move that brings every size into its declared range is
    found (SLSQP) and kept if the residual sum of squares stays within 0.1.
    """
    fixed = [p for s in steps for p in s.fixed]
    sizes = [p for s in steps for p in s.params if p.role == SIZE] + fixed
    if not fixed:
        return outcome.state
    state = outcome.state
    lo = np.array([p.declared.low for p in sizes])
    hi = np.array([p.declared.high for p in sizes])
    now = np.array([p.get(state) for p in sizes])
    if np.all((now >= lo) & (now <= hi)):
        return state
    cols = problem.columns(state, fixed)
    fv = np.column_stack([problem.space.fit_vector(c) for c in cols])
    coef, *_ = np.linalg.lstsq(outcome.jacobian, fv, rcond=None)
    keys = [p.key for p in outcome.params]

    def moved(d):
        out = now.copy()
        for i, p in enumerate(sizes):
            if p.key in keys:
                out[i] -= coef[keys.index(p.key)] @ d
        out[len(sizes) - len(fixed) :] += d
        return out

    cons = [
        {"type": "ineq", "fun": lambda d: moved(d) - lo},
        {"type": "ineq", "fun": lambda d: hi - moved(d)},
    ]
    sol = minimize(lambda d: float(d @ d), np.zeros(len(fixed)), constraints=cons, method="SLSQP")
    if not sol.success:
        return state
    d = sol.x
    new = state
    shift = -(coef @ d)
    for p, dv in zip(outcome.params, shift, strict=True):
        new = p.set(new, p.get(new) + float(dv))
    for p, dv in zip(fixed, d, strict=True):
        new = p.set(new, p.get(new) + float(dv))
    for p in sizes:  # what SLSQP leaves a hair off a bound is on it
        v, span = p.get(new), p.declared.high - p.declared.low
        for bound in (p.declared.low, p.declared.high):
            if abs(v - bound) < 1e-7 * span:
                new = p.set(new, bound)
    if problem.rss(new) - outcome.rss > 0.1:
        return state
    return new


def _clip_to_range(state, steps, notes):
    """Sizes and shapes within their physical range, saying what was clipped."""
    for step in steps:
        for p in (*step.params, *step.fixed):
            v = p.get(state)
            lo, hi = p.declared.low, p.declared.high
            if not lo <= v <= hi:
                c = min(max(v, lo), hi)
                notes.append(
                    f"{p.key} fitted {v:.4g} {p.unit}, outside its physical range "
                    f"[{lo:g}, {hi:g}]; the model files hold {c:.4g}"
                )
                state = p.set(state, c)
    return state


def _members(step, state):
    """The effect added at a step and its look-alikes, each with its fit of the gap."""
    sizes = [p for p in step.params if p.role == SIZE]
    out = [Member(step.effect, state, sizes, np.array([p.get(state) for p in sizes]))]
    for e, screen in step.alternatives.items():
        s = state
        for p in effect_model_parameters(e):
            if p.name in screen.shape:
                s = p.set(s, screen.shape[p.name])
        out.append(Member(e, s, list(screen.informative), np.asarray(screen.coef, dtype=float)))
    return out


def fit_base(recording, program, analysis=None, lap=None, motion=None):
    """The recording's features, noise floor and the base model fitted to them.

    Parameters
    ----------
    recording : Recording
        The test as recorded.
    program : TestProgram
        The program it ran.
    analysis : AnalysisOptions, optional
        The pipeline's options (no bootstrap by default).
    lap : callable, optional
        Called with a stage name when the pipeline and the features are done.
    motion : SampledMotion, optional
        The commanded motion the model takes (a controller's); our own
        trajectory if None.

    Returns
    -------
    problem : Problem
        Recording, noise floor and forward model.
    base : FitOutcome
        The base model's fit.
    params : list of Parameter
        The base model's parameters.

    Raises
    ------
    AnalysisError
        Where the pipeline refuses the recording.
    """
    analysis = analysis or AnalysisOptions(bootstrap_n=0)
    lap = lap or (lambda name: None)
    run = analyze(recording, analysis, program=program)
    program = _as_run(program, run)
    layout = layout_from_recording(recording, program, analysis)
    lap("pipeline")
    problem = _problem(recording, layout, motion)
    params = base_parameters(problem.model.n_blocks)
    start = _initial_state(recording, run, problem.space.noise, problem.model.n_blocks)
    start = _align_anchors(problem, start)
    # the transient windows start after the recording's own feed ramps
    windows = transient_windows(
        problem.model,
        start,
        recording.time_s,
        recording.accel[:, :2].astype(np.float64),
        np.sqrt(problem.space.noise.sigma2),
    )
    problem = _problem(recording, with_transients(layout, recording.time_s, windows), motion)
    lap("features")
    base = problem.fit(start, params)
    return problem, base, params


def steps_in_model(steps, active):
    """The steps whose effect the final model holds, each effect's last step once.

    An effect dropped by the Wald test can be added again at a later step;
    only that step stands for it.

    Parameters
    ----------
    steps : sequence of Step
        Every step, in order.
    active : set of str
        The effects in the final model.

    Returns
    -------
    list of Step
    """
    last = {s.effect: s for s in steps}
    return [s for s in steps if s.effect in active and last[s.effect] is s]


def _problem(recording, layout, motion):
    """The recording's features at a layout, their noise floor and the forward model."""
    operator = FeatureOperator(layout)
    xy = recording.accel[layout.index, :2].astype(np.float64)
    data = operator.transform(xy)
    noise = estimate_noise(
        operator.cycle_spectra(xy), layout, recording.sample_rate_hz, recording.duration_s
    )
    space = FeatureSpace(layout, operator, noise, data)
    return Problem(ForwardModel(layout, operator, motion), space, xy)


def _align_anchors(problem, state, iterations=3, step_s=1e-5):
    """Shift all blocks' anchors together onto the recording, on the unclipped residual.

    The anchors' start (:func:`_start_anchor`) comes from the pipeline's
    phases, which are off by a fraction of a millisecond where the model's
    motion differs from the recording's ramps; on a quiet sensor that is many
    noise sigmas, where the fit's clipped residual is flat. A few Gauss-Newton
    steps of the one common shift on the plain residual close it: a common
    time shift is orthogonal to the sensor's rotation, which moves both
    directions' phases the same way.
    """
    model = problem.model
    shift = 0.0
    for _ in range(iterations):
        here = replace(state, anchors_s=tuple(a + shift for a in state.anchors_s))
        there = replace(here, anchors_s=tuple(a + step_s for a in here.anchors_s))
        now = model.samples(here)
        slope = (model.samples(there) - now) / step_s
        shift += float(np.sum(slope * (problem.data_xy - now)) / np.sum(slope * slope))
    return replace(state, anchors_s=tuple(a + shift for a in state.anchors_s))


def _as_run(program, run):
    """The program at the speed its circles ran, when the pipeline took that speed.

    A controller may run the arcs slower than programmed (LinuxCNC at its arc
    acceleration limit); the pipeline then analyses them at their measured
    period (:mod:`imu_square.pipeline.circle_speed`), and so does the model.
    """
    if abs(run.period_s / program.period_s - 1) <= PERIOD_LIMIT:
        return program
    return replace(program, feed_m_per_s=abs(run.omega_rad_s) * program.radius_m)


def _residual_noise(problem, recording, outcome):
    """The noise floor from the scatter of recording minus model, if it differs significantly.

    Returns
    -------
    NoiseModel or None
        None when its variance agrees with the current estimate within five
        standard deviations of the scatter or :data:`NOISE_CHANGE`.
    """
    model = problem.model
    layout = model.layout
    residual = problem.data_xy - model.samples(outcome.state)
    np.clip(residual, -problem.clip, problem.clip, out=residual)
    spectra = model.operator.cycle_spectra(residual)
    new = estimate_noise(spectra, layout, recording.sample_rate_hz, recording.duration_s)
    old = problem.space.noise
    tol = max(5 * math.sqrt(2 / max(new.dof, 1)), NOISE_CHANGE)
    if np.all(np.abs(new.sigma2 / old.sigma2 - 1) <= tol):
        return None
    return new


@one_blas_thread()  # many small least-squares problems (imu_square.blas)
def find_discrepancy(recording, options=None, program=None, motion=None):
    """Compare a recording with the simulator, name the missing effects, add them.

    Parameters
    ----------
    recording : Recording
        The test as recorded.
    options : DiscrepancyOptions, optional
        Defaults if None.
    program : TestProgram, optional
        Overrides ``recording.program``.
    motion : SampledMotion, optional
        The commanded motion the model takes: the controller's that ran the
        test (:mod:`imu_square.linuxcnc`); our own trajectory if None.

    Returns
    -------
    DiscrepancyResult

    Raises
    ------
    AnalysisError
        Where the pipeline refuses the recording; the message does not name
        the recording (the caller does).
    ConfigError
        For options out of range or an unknown effect.
    """
    opts = options or DiscrepancyOptions()
    _check(opts)
    candidates = opts.candidates()
    prog = program or recording.program
    if prog is None:
        raise AnalysisError("the recording has no test program: give one (--program)")
    timings = {}
    t = time.perf_counter()

    def lap(name):
        nonlocal t
        now = time.perf_counter()
        timings[name] = now - t
        t = now

    problem, base, base_params = fit_base(recording, prog, opts.analysis, lap, motion)
    base_gap = problem.gaps(base)
    lap("base_fit")
    model = problem.model
    noise = problem.space.noise
    steps, final, screens = grow(
        problem,
        base,
        candidates,
        alpha=opts.significance,
        alpha_separation=opts.separation,
        max_steps=opts.max_steps,
    )
    again = _residual_noise(problem, recording, final) if steps else None
    if again is not None:
        # effects with detail below a sample (a backlash take-up of a few samples) change
        # from cycle to cycle with the sample phase: the recording's scatter counted them
        # as noise, the model's residual does not
        logger.debug("noise floor re-estimated from the residual: %s", again.density_m_s2_rthz)
        reference = problem.model.operator.transform(problem.data_xy)
        problem = Problem(
            problem.model,
            FeatureSpace(problem.model.layout, problem.model.operator, again, reference),
            problem.data_xy,
        )
        noise = again
        base = problem.fit(base.state, base_params)
        base_gap = problem.gaps(base)
        steps, final, screens = grow(
            problem,
            base,
            candidates,
            alpha=opts.significance,
            alpha_separation=opts.separation,
            max_steps=opts.max_steps,
        )
    lap("growth")
    steps_in = steps_in_model(steps, {p.effect for p in final.params} - {BASE})
    final_gap = problem.gaps(final)
    notes = []
    state = _gauge(problem, final, steps_in)
    reports = []
    for k, s in enumerate(steps):
        upto = steps[: k + 1]
        s_state = _gauge(
            problem, s.after, [u for u in upto if any(p.effect == u.effect for p in s.after.params)]
        )
        reports.append(
            StepReport(
                effect=s.effect,
                one_of=s.one_of,
                parameters=_step_values(s, s_state),
                alternatives={
                    e: tuple(
                        FittedValue(p.name, float(v), float(np.sqrt(max(c, 0.0))), p.unit)
                        for p, v, c in zip(sc.informative, sc.coef, np.diag(sc.cov), strict=True)
                    )
                    for e, sc in s.alternatives.items()
                },
                gap_before=problem.gaps(s.before),
                gap_after=problem.gaps(s.after),
                statistic=s.statistic,
                dof=s.dof,
                p_value=s.p_value,
                threshold=s.threshold,
                dropped=s.dropped,
            )
        )
    names, corr = signature_correlations(
        screens, final.jacobian[:, [i for i, p in enumerate(final.params) if p.effect == BASE]]
    )
    groups = [s for s in steps_in if len(s.one_of) > 1]
    suggestions = ()
    if groups and opts.suggest:
        suggestions = tuple(
            suggest_tests(
                problem, final, [_members(s, final.state) for s in groups], opts.separation
            )
        )
    lap("identifiability")
    model_values = tuple(
        FittedValue(p.key, p.get(state), final.uncertainty(p), p.unit) for p in final.params
    ) + tuple(
        FittedValue(p.key, p.get(state), math.nan, p.unit, identifiable=False)
        for s in steps_in
        for p in s.fixed
    )
    state = _clip_to_range(state, steps_in, notes)
    left = [v.name for v in gaps_left(final_gap)]
    if left:
        notes.append(
            "a gap above the noise floor is left in "
            + ", ".join(f"{k} ({final_gap[k].gap:.2f})" for k in left)
            + ": an effect outside the candidates, or one too weak to name alone"
        )
    locations, curves = locate_gaps(problem.space, final.residual, final_gap)
    logger.debug("discrepancy: %d simulator runs, %s", model.evaluations, timings)
    return DiscrepancyResult(
        base=_values(base, base_params),
        base_gap=base_gap,
        steps=tuple(reports),
        final_gap=final_gap,
        model=model_values,
        named_effects=tuple(s.effect for s in steps_in if len(s.one_of) == 1),
        ambiguous=tuple(s.one_of for s in groups),
        suggested_tests=suggestions,
        correlations={"names": names, "matrix": corr.tolist()},
        noise={
            "density_m_s2_rthz": noise.density_m_s2_rthz.tolist(),
            "flicker_corner_hz": noise.flicker_corner_hz.tolist(),
            "dof": noise.dof,
        },
        significance=opts.significance,
        candidates=candidates,
        machine=state.machine,
        sensor=state.sensor,
        program=model.layout.program,  # at the speed the circles ran
        notes=tuple(notes),
        timings_s=timings,
        evaluations=model.evaluations,
        gap_left=locations,
        curves=curves,
    )
