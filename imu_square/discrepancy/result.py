"""What the discrepancy workflow returns: :class:`DiscrepancyResult`, its text and JSON."""

import math
from dataclasses import dataclass, field

import numpy as np

from imu_square.discrepancy.views import VIEWS
from imu_square.json_values import json_safe
from imu_square.units import UG


@dataclass(frozen=True)
class FittedValue:
    """One fitted parameter.

    Attributes
    ----------
    name : str
        Parameter name (the machine or sensor file's field for an effect).
    value : float
        Fitted value. [unit]
    u_value : float
        Standard uncertainty from the Fisher information; NaN when the
        parameter is not identifiable in this test (held). [unit]
    unit : str
        Display unit.
    identifiable : bool
        Whether this test determines it.
    """

    name: str
    value: float
    u_value: float
    unit: str
    identifiable: bool = True

    def to_json_dict(self):
        """``{"value", "u_value", "unit"}`` (and ``"identifiable": false`` when held)."""
        out = {"value": _num(self.value), "u_value": _num(self.u_value), "unit": self.unit}
        if not self.identifiable:
            out["identifiable"] = False
        return out

    def text(self):
        """``name = value ± u unit``."""
        if self.unit == "flag":
            return f"{self.name}: {'yes' if self.value >= 0.5 else 'no'} (the scan's choice)"
        if not self.identifiable:
            return f"{self.name} = {self.value:.4g} {self.unit} (not identifiable here, held)"
        return f"{self.name} = {self.value:.4g} ± {self.u_value:.2g} {self.unit}".rstrip()


@dataclass(frozen=True)
class StepReport:
    """One effect added to the model.

    Attributes
    ----------
    effect : str
        The effect added.
    one_of : tuple of str
        It and the effects that explain the gap as well in this test.
    parameters : tuple of FittedValue
        Its fitted parameters after the step.
    alternatives : dict of str to tuple of FittedValue
        Each look-alike's own (linearised) fit of the same gap.
    gap_before, gap_after : dict of str to ViewGap
        Every view before and after the step.
    statistic : float
        Likelihood-ratio statistic of adding it.
    dof : int
        Its degrees of freedom.
    p_value : float
        Its p-value, Bonferroni-adjusted over the shapes tried.
    threshold : float
        The level it had to pass: significance / candidates still out.
    dropped : tuple of str
        Effects added earlier that this one made redundant: removed from the
        model (a Wald test on their sizes no longer passes the level).
    """

    effect: str
    one_of: tuple
    parameters: tuple
    alternatives: dict
    gap_before: dict
    gap_after: dict
    statistic: float
    dof: int
    p_value: float
    threshold: float
    dropped: tuple = ()

    def to_json_dict(self):
        """The step as JSON-ready values."""
        return {
            "effect": self.effect,
            "one_of": list(self.one_of),
            "parameters": {p.name: p.to_json_dict() for p in self.parameters},
            "alternatives": {
                e: {p.name: p.to_json_dict() for p in ps} for e, ps in self.alternatives.items()
            },
            "gap_before": _gap_dict(self.gap_before),
            "gap_after": _gap_dict(self.gap_after),
            "statistic": self.statistic,
            "dof": self.dof,
            "p_value": self.p_value,
            "threshold": self.threshold,
            "dropped": list(self.dropped),
        }


@dataclass(frozen=True)
class DiscrepancyResult:
    """Where the simulator and a recording disagree, and the effects that close the gap.

    Attributes
    ----------
    base : tuple of FittedValue
        The base model's parameters (squareness, sensor rotation and tilt,
        time anchors) as fitted alone.
    base_gap : dict of str to ViewGap
        Every view with the base model.
    steps : tuple of StepReport
        The effects added, in order.
    final_gap : dict of str to ViewGap
        Every view with the final model.
    model : tuple of FittedValue
        Every parameter of the final model, ``effect.name``.
    named_effects : tuple of str
        Effects added that this test identifies alone.
    ambiguous : tuple of tuple of str
        "One of" groups: effects this test cannot tell apart, the one modelled first.
    suggested_tests : tuple of dict
        Per group, the extra tests that would separate it (``identify.suggest_tests``).
    correlations : dict
        ``{"names": [...], "matrix": [[...]]}``: signature correlations (NaN: nothing identifiable).
    noise : dict
        The noise floor: density per axis [m/s^2/sqrt(Hz)], 1/f corner [Hz], degrees of freedom.
    significance : float
        The family-wise level of each step.
    candidates : tuple of str
        The effects that were allowed.
    machine, sensor : MachineModel, SensorModel
        The final model as the simulator's objects (values within their
        physical ranges, as written by ``--model-out``).
    program : TestProgram
        The program of the recording.
    notes : tuple of str
        What the user should know (unexplained gap left, values clipped, ...).
    timings_s : dict of str to float
        Time per stage. [s]
    evaluations : int
        Simulator runs.
    gap_left : tuple of GapLocation
        The views whose gap stays above their null with the final model, worst
        first, each with where its residual lies
        (:mod:`imu_square.discrepancy.localise`).
    curves : ResidualCurves or None
        The final residual's curves, for the ``--plot`` figure.
    """

    base: tuple
    base_gap: dict
    steps: tuple
    final_gap: dict
    model: tuple
    named_effects: tuple
    ambiguous: tuple
    suggested_tests: tuple
    correlations: dict
    noise: dict
    significance: float
    candidates: tuple
    machine: object = field(repr=False)
    sensor: object = field(repr=False)
    program: object = field(repr=False)
    notes: tuple = ()
    timings_s: dict = field(default_factory=dict)
    evaluations: int = 0
    gap_left: tuple = ()
    curves: object = field(default=None, repr=False)

    @property
    def explained(self):
        """Whether the final model leaves no view's gap above its null."""
        return not self.gap_left

    def headline(self):
        """The outcome in one line: what was named, and whether a gap is left.

        It never says the model explains the recording while a view's gap stays
        above its null after the last step.

        Returns
        -------
        str
            The line ``discrepancy`` prints first.
        """
        named = list(self.named_effects) + ["one of " + " | ".join(g) for g in self.ambiguous]
        if not self.gap_left:
            if not named:
                return "the base model explains the recording down to the noise: no effect named"
            return "the model explains the recording down to the noise with " + ", ".join(named)
        views = ", ".join(f"{g.view} ({g.gap:.2f})" for g in self.gap_left)
        if not named:
            return (
                f"a gap is left that none of the candidates closes, in {views}: "
                "no effect named, the recording is NOT explained"
            )
        return (
            f"named {', '.join(named)}, but a gap is left in {views}: "
            "the recording is NOT fully explained"
        )

    @property
    def exit_code(self):
        """0 when the base model explains the recording, 1 when effects were named."""
        return 1 if self.named_effects or self.ambiguous else 0

    def to_json_dict(self):
        """The result as JSON-ready values (the keys of docs/discrepancy.md).

        Returns
        -------
        dict of str to object
            What ``discrepancy --json`` prints.
        """
        return {
            "headline": self.headline(),
            "explained": self.explained,
            "gap_left": [g.to_json_dict() for g in self.gap_left],
            "base_gap": _gap_dict(self.base_gap),
            "steps": [s.to_json_dict() for s in self.steps],
            "final_gap": _gap_dict(self.final_gap),
            "named_effects": list(self.named_effects),
            "ambiguous": [list(g) for g in self.ambiguous],
            "suggested_tests": [json_safe(s) for s in self.suggested_tests],
            "base_parameters": {p.name: p.to_json_dict() for p in self.base},
            "model": {p.name: p.to_json_dict() for p in self.model},
            "views": {
                "base": {k: v.to_json_dict() for k, v in self.base_gap.items()},
                "final": {k: v.to_json_dict() for k, v in self.final_gap.items()},
            },
            "correlations": json_safe(self.correlations),
            "noise_floor": json_safe(self.noise),
            "significance": self.significance,
            "candidates": list(self.candidates),
            "notes": list(self.notes),
            "timings_s": dict(self.timings_s),
            "simulator_runs": self.evaluations,
        }

    def summary(self):
        """Human-readable lines: headline, noise floor, steps, gaps per view, gaps left.

        Returns
        -------
        str
            The lines, joined by newlines.
        """
        d = np.asarray(self.noise["density_m_s2_rthz"]) / UG
        lines = [
            self.headline(),
            f"noise floor {d[0]:.2f} (x), {d[1]:.2f} (y) µg/√Hz"
            + (
                f", 1/f corner {max(self.noise['flicker_corner_hz']):.3g} Hz"
                if max(self.noise["flicker_corner_hz"]) > 0
                else ""
            )
            + f"; significance {self.significance:g} per step",
        ]
        base = ", ".join(p.text() for p in self.base if not p.name.startswith("anchor"))
        lines.append(f"base model: {base}")
        for i, s in enumerate(self.steps, 1):
            head = s.effect if len(s.one_of) == 1 else "one of " + " | ".join(s.one_of)
            lines.append(
                f"step {i}: {head} (likelihood ratio {s.statistic:.1f}, {s.dof} dof, "
                f"p {_p_text(s.p_value)} < {s.threshold:.2g})"
            )
            lines += [f"    {p.text()}" for p in s.parameters]
            if s.dropped:
                lines.append(f"    (makes {', '.join(s.dropped)} redundant: removed)")
            for e, ps in s.alternatives.items():
                lines.append(f"    or {e}: " + ", ".join(p.text() for p in ps))
        header = "gap per view (1.0 = noise floor)"
        cols = ["base"] + [f"+{s.effect}" for s in self.steps]
        width = max(12, *(len(c) for c in cols))
        lines.append(f"{header:<34}" + "".join(f"{c:>{width + 1}}" for c in cols))
        for view in VIEWS:
            row = [self.base_gap[view]] + [s.gap_after[view] for s in self.steps]
            lines.append(f"  {view:<32}" + "".join(f"{_g(v.gap):>{width + 1}}" for v in row))
        for group in self.suggested_tests:
            for pair in group["pairs"]:
                names = " | ".join(pair["effects"])
                tests = pair["separated_by"]
                lines.append(
                    f"to tell {names} apart: {tests[0]}"
                    + (f" (or {'; '.join(tests[1:])})" if tests[1:] else "")
                    if tests
                    else f"to tell {names} apart: none of the extra tests considered suffices"
                )
        for g in self.gap_left:
            lines.append(f"gap left in {g.view} ({g.gap:.2f}): {g.where}")
        lines += [f"note: {n}" for n in self.notes]
        return "\n".join(lines)


def headline_is_honest(doc, level=None):
    """Whether a result's JSON headline tells the truth about the gap left.

    The rule of the first line: while any view's p-value with the final model
    is below the level, the headline must not say the recording is explained,
    and ``explained`` must be false; with no such view, it must not say a gap
    is left. The acceptance benchmarks apply it to every case.

    Parameters
    ----------
    doc : dict
        :meth:`DiscrepancyResult.to_json_dict`.
    level : float, optional
        :data:`~imu_square.discrepancy.localise.GAP_LEFT_P` if None.

    Returns
    -------
    bool
    """
    from imu_square.discrepancy.localise import GAP_LEFT_P

    level = GAP_LEFT_P if level is None else level
    final = doc["views"]["final"]
    left = [
        k
        for k, v in final.items()
        if v["p_value"] is not None and v["gap"] is not None and v["p_value"] < level
    ]
    head = doc["headline"]
    if left:
        return (
            not doc["explained"]
            and "gap is left" in head
            and "explains" not in head
            and all(k in head for k in left)
        )
    return doc["explained"] and "explains" in head and "gap" not in head


def _g(x):
    return "-" if x is None or not math.isfinite(x) else f"{x:.2f}"


def _p_text(p):
    return "< 1e-16" if p < 1e-16 else f"{p:.2g}"


def _num(x):
    x = float(x)
    return x if math.isfinite(x) else None


def _gap_dict(gaps):
    return {k: _num(v.gap) for k, v in gaps.items()}
