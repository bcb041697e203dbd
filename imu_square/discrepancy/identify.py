"""Which candidates this test can tell apart, and which extra test would separate the rest.

Everything here is read from the Fisher information at the fitted model: the
fit vector is whitened, so the information of a set of parameters is
``J'J`` with ``J`` their derivatives (:class:`~imu_square.discrepancy.model_fit.Problem`).

Signature correlation
    For two candidates with derivative spaces ``A`` and ``B`` (identifiable
    sizes, base model projected out), the largest canonical correlation
    between them: 1 means some change of one looks exactly like some change
    of the other.

Separation
    For an effect ``e`` with fitted signal ``s = J_e theta_e`` and a
    candidate ``c``, ``sep(e -> c) = min_q |P (s - J_c q)|^2`` with ``P``
    projecting out the base model (and ``c``'s free shapes added to ``J_c``):
    how much worse ``c`` explains what ``e`` explains, as a likelihood-ratio
    statistic. ``e`` and ``c`` can be told apart at this noise level when
    ``sep`` exceeds ``chi2.isf(alpha, 1)`` both ways.

Extra tests
    The same separation computed for this test plus a simulated extra test
    (:data:`EXTRA_TESTS`): the fitted model run with the program or sensor
    changed, its Fisher information added to this one's, the effects'
    parameters shared and each test's base model (squareness, rotation,
    offsets, time anchor) its own. A temperature channel observes the
    parameters the simulator declares ``observed_by`` it (the sensor's
    warm-up time constant); there they are held at their typical value. An
    extra test is suggested for a group when it separates every pair in it.
"""

import math
from dataclasses import dataclass, replace

import numpy as np
from scipy import stats

from imu_square.discrepancy.features import FeatureOperator
from imu_square.discrepancy.forward import LEAD_IN_S, ForwardModel
from imu_square.discrepancy.layout import layout_from_timeline
from imu_square.discrepancy.parameters import base_parameters, effect_model_parameters
from imu_square.discrepancy.views import FeatureSpace
from imu_square.discrepancy.window_noise import NoiseModel
from imu_square.errors import ImuSquareError
from imu_square.program.spec import program_from_mapping
from imu_square.simulate.effects import SHAPE
from imu_square.simulate.signal import model_timeline

TEMPERATURE = "temperature channel"


@dataclass(frozen=True)
class ExtraTest:
    """A test that could be run besides this one.

    Attributes
    ----------
    name : str
        What it is, for people.
    kind : str
        ``"second feed"``, ``"second radius"``, ``"sensor turned 90°"`` or
        ``"temperature channel"``.
    program_changes : dict
        ``[program]`` fields to multiply: ``{"feed_mm_per_min": 0.5}``.
    eps_c_turn_deg : float
        Extra rotation of the sensor. [deg]
    """

    name: str
    kind: str
    program_changes: dict
    eps_c_turn_deg: float = 0.0


EXTRA_TESTS = (
    ExtraTest("the same circle at half the feed", "second feed", {"feed_mm_per_min": 0.5}),
    ExtraTest("the same circle at twice the feed", "second feed", {"feed_mm_per_min": 2.0}),
    ExtraTest("a circle of half the radius", "second radius", {"radius_mm": 0.5}),
    ExtraTest("a circle of twice the radius", "second radius", {"radius_mm": 2.0}),
    ExtraTest("the same test with the sensor turned 90°", "sensor turned 90°", {}, 90.0),
    ExtraTest("the same test with a temperature channel", TEMPERATURE, {}),
)


def _orth(m):
    if m.size == 0 or m.shape[1] == 0:
        return np.zeros((m.shape[0], 0))
    q, r = np.linalg.qr(m)
    d = np.abs(np.diag(r))
    return q[:, d > 1e-10 * max(d.max(), 1e-300)]


def _perp(q, v):
    return v - q @ (q.T @ v) if q.shape[1] else v


def signature_correlations(screens, base_jacobian):
    """Largest canonical correlation between every two candidates' signatures.

    Parameters
    ----------
    screens : dict of str to Screen
        Candidates screened at the fitted model.
    base_jacobian : ndarray, shape (n, p)
        The base model's derivatives (projected out of each signature).

    Returns
    -------
    names : list of str
    matrix : ndarray, shape (len(names), len(names))
        NaN where a candidate has no identifiable size.
    """
    q = _orth(base_jacobian)
    names = sorted(screens)
    bases = {e: _orth(_perp(q, screens[e].vectors)) if screens[e].dof else None for e in names}
    n = len(names)
    out = np.full((n, n), np.nan)
    for i, a in enumerate(names):
        for j, b in enumerate(names):
            if (
                bases[a] is not None
                and bases[b] is not None
                and bases[a].shape[1]
                and bases[b].shape[1]
            ):
                s = np.linalg.svd(bases[a].T @ bases[b], compute_uv=False)
                out[i, j] = float(min(1.0, s.max())) if s.size else 0.0
    return names, out


def separation(signal, others, base):
    """``min_q |P (signal - others q)|^2``, ``P`` projecting out ``base``.

    Parameters
    ----------
    signal : ndarray, shape (n,)
        Fit-vector signal of one effect.
    others : ndarray, shape (n, q)
        Derivatives of the candidate that might mimic it.
    base : ndarray, shape (n, p)
        Derivatives of the nuisance parameters.

    Returns
    -------
    float
        Likelihood-ratio statistic by which the candidate explains the signal worse.
    """
    q = _orth(base)
    s = _perp(q, signal)
    m = _orth(_perp(q, others))
    return float(np.sum(_perp(m, s) ** 2))


@dataclass
class Member:
    """One effect of a "one of" group, as fitted (or as its linearised alternative).

    Attributes
    ----------
    effect : str
        Its name.
    state : ModelState
        The fitted model with this effect's shape (and, for the effect in the
        model, its sizes).
    sizes : list of Parameter
        Its identifiable sizes.
    values : ndarray
        Their values explaining the gap. [display units]
    """

    effect: str
    state: object
    sizes: list
    values: np.ndarray

    def shapes(self, pinned=()):
        """Its free shapes, less those observed by the channels in ``pinned``."""
        return [
            p
            for p in effect_model_parameters(self.effect)
            if p.role == SHAPE
            and not p.declared.is_flag
            and not set(p.declared.observed_by) & set(pinned)
        ]


class _Experiment:
    """Derivatives of one test (real or simulated) at the fitted model."""

    def __init__(self, problem, base):
        self.problem = problem
        self.base = base
        self._base_cols = None

    def base_jacobian(self, state):
        if self._base_cols is None:
            cols = self.problem.columns(state, self.base)
            self._base_cols = np.column_stack([self.problem.space.fit_vector(c) for c in cols])
        return self._base_cols

    def derivatives(self, member, pinned=(), typical=False):
        """Columns of a member's sizes and free shapes, and its signal (sizes at their values)."""
        state = member.state
        if typical:
            for p in effect_model_parameters(member.effect):
                if set(p.declared.observed_by) & set(pinned):
                    state = p.set(state, p.declared.typical)
        params = member.sizes + member.shapes(pinned)
        on = state
        for p, v in zip(member.sizes, member.values, strict=True):
            on = p.set(on, float(v))
        cols = self.problem.columns(on, params)
        jac = np.column_stack([self.problem.space.fit_vector(c) for c in cols])
        signal = jac[:, : len(member.sizes)] @ member.values
        return jac, signal


def _simulated_problem(problem, state, test):
    """The Problem of an extra test, simulated noise-free from the fitted model."""
    from imu_square.discrepancy.model_fit import Problem

    layout = problem.model.layout
    program = layout.program
    if test.program_changes:
        table = program.to_mapping()
        for key, factor in test.program_changes.items():
            table[key] = table[key] * factor
        program = program_from_mapping(table, "extra test")
    sensor = state.sensor
    if test.eps_c_turn_deg:
        sensor = replace(sensor, eps_c_rad=sensor.eps_c_rad + math.radians(test.eps_c_turn_deg))
    state = replace(state, sensor=sensor, anchors_s=(0.0,) * program.n_blocks)
    timeline = model_timeline(program, state.machine, LEAD_IN_S)
    noise = problem.space.noise
    u_mid = float(np.mean([b.u_t_mid_s for b in problem.model.layout.blocks]))
    sim_layout = layout_from_timeline(program, timeline, noise.sample_rate_hz, u_mid)
    operator = FeatureOperator(sim_layout)
    f_circle = sim_layout.frequency_hz
    sim_noise = NoiseModel(
        noise.sigma2,
        noise.flicker_corner_hz / f_circle,
        noise.dof,
        noise.sample_rate_hz,
        f_circle,
        timeline.duration_s * f_circle,
    )
    model = ForwardModel(sim_layout, operator)
    reference = model.features(state)
    space = FeatureSpace(sim_layout, operator, sim_noise, reference)
    return Problem(model, space, model.samples(state)), state


def suggest_tests(problem, final, members_by_group, alpha_separation, tests=EXTRA_TESTS):
    """Separation of each "one of" group in this test and with each extra test.

    Parameters
    ----------
    problem : Problem
        This recording's problem.
    final : FitOutcome
        The fitted model.
    members_by_group : list of list of Member
        The groups.
    alpha_separation : float
        Level at which two effects count as told apart.
    tests : sequence of ExtraTest
        Extra tests to consider.

    Returns
    -------
    list of dict
        Per group: ``group`` (names); ``pairs``: for every two members their
        ``separation`` in this test alone (the smaller of both ways) and the
        extra tests that separate them (``separated_by``, best first); and
        ``tests``: every extra test with the pairs' smallest separation and
        whether it separates them all (``separates``).
    """
    crit = float(stats.chi2.isf(alpha_separation, 1))
    here = _Experiment(problem, [p for p in final.params if p.effect == "base"])
    base_here = here.base_jacobian(final.state)
    out = []
    for members in members_by_group:
        own = {m.effect: here.derivatives(m) for m in members}
        pairs = [(a, b) for i, a in enumerate(members) for b in members[i + 1 :]]
        alone = {
            (a.effect, b.effect): min(
                separation(own[a.effect][1], own[b.effect][0], base_here),
                separation(own[b.effect][1], own[a.effect][0], base_here),
            )
            for a, b in pairs
        }
        per_test = []
        for test in tests:
            try:
                seps = _test_separations(problem, final, test, members, pairs, own, base_here)
            except ImuSquareError:
                continue  # the program cannot be run that way (feed or radius out of range)
            per_test.append((test, seps))
        pair_rows = []
        for a, b in pairs:
            key = (a.effect, b.effect)
            good = sorted(
                ((seps[key], t) for t, seps in per_test if seps[key] >= crit),
                key=lambda x: -x[0],
            )
            pair_rows.append(
                {
                    "effects": [a.effect, b.effect],
                    "separation": alone[key],
                    "separated_by": [t.name for _, t in good],
                }
            )
        test_rows = sorted(
            (
                {
                    "test": t.name,
                    "kind": t.kind,
                    "separation": min(seps.values()),
                    "separates": bool(min(seps.values()) >= crit),
                }
                for t, seps in per_test
            ),
            key=lambda r: -r["separation"],
        )
        out.append(
            {
                "group": [m.effect for m in members],
                "critical": crit,
                "pairs": pair_rows,
                "tests": test_rows,
            }
        )
    return out


def _stacked_separation(signals, others, bases):
    """Separation over several tests: shared effect parameters, own base models."""
    n = [s.size for s in signals]
    signal = np.concatenate(signals)
    other = np.vstack(others)
    base = np.zeros((sum(n), sum(b.shape[1] for b in bases)))
    r = c = 0
    for b, k in zip(bases, n, strict=True):
        base[r : r + k, c : c + b.shape[1]] = b
        r += k
        c += b.shape[1]
    return separation(signal, other, base)


def _test_separations(problem, final, test, members, pairs, own, base_here):
    """Separation of every pair (the smaller of both ways) with one extra test."""
    if test.kind == TEMPERATURE:
        # the same recording, with the shapes a temperature channel observes known
        pinned = (TEMPERATURE,)
        here = _Experiment(problem, [p for p in final.params if p.effect == "base"])
        mimic = {m.effect: here.derivatives(m, pinned, typical=True)[0] for m in members}
        return {
            (a.effect, b.effect): min(
                separation(own[a.effect][1], mimic[b.effect], base_here),
                separation(own[b.effect][1], mimic[a.effect], base_here),
            )
            for a, b in pairs
        }
    sim, state = _simulated_problem(problem, final.state, test)
    exp = _Experiment(sim, base_parameters(sim.model.n_blocks))
    turn = math.radians(test.eps_c_turn_deg)
    derivs = {}
    for m in members:
        sensor = replace(m.state.sensor, eps_c_rad=m.state.sensor.eps_c_rad + turn)
        moved = Member(
            m.effect, replace(m.state, sensor=sensor, anchors_s=state.anchors_s), m.sizes, m.values
        )
        derivs[m.effect] = exp.derivatives(moved)
    base_x = exp.base_jacobian(state)

    def both(a, b):
        return min(
            _stacked_separation(
                [own[x.effect][1], derivs[x.effect][1]],
                [own[y.effect][0], derivs[y.effect][0]],
                [base_here, base_x],
            )
            for x, y in ((a, b), (b, a))
        )

    return {(a.effect, b.effect): both(a, b) for a, b in pairs}
