"""A diagnostic's own designed alarm: the squareness's chart design on its change.

The same scheme as the squareness's (:func:`~imu_square.monitor.stats.alarms.design_alarms`):
Shewhart, EWMA and CUSUM on ``z = change / u`` together meet the false-alarm
rate of the monitor file's ``[alarms]``, the CUSUM tuned to the diagnostic's
step (``[diagnostics.alarms]``), the baseline's own error allowed for. Here
``change`` is the night's value less the diagnostic's baseline value and
``u`` the night's uncertainty with the baseline nights' scatter
(:mod:`.baseline`); ``z`` is taken as normal (the fit's uncertainty rests on
a noise floor estimated from thousands of numbers).

The design needs only ``step / sigma`` and the baseline's relative error;
it is computed with the diagnostic's numbers scaled so that the design's
angle fields (``sigma_urad``, ``step_urad``, ``ramp_urad``) read in the
diagnostic's shown unit. A design is made once per baseline and kept with
it, keyed by what it was made from.
"""

from imu_square.errors import MonitorError, step
from imu_square.monitor.history.encoding import settings_hash
from imu_square.units import URAD

# The ramp whose detection delay the design reports: the step over this many nights.
RAMP_NIGHTS = 90


def design_inputs(diagnostic, baseline, step_si, alarms):
    """What a diagnostic's design is made from (JSON values; their hash keys it).

    Parameters
    ----------
    diagnostic : Diagnostic
        The diagnostic.
    baseline : DiagnosticBaseline
        Its baseline.
    step_si : float
        The change its alarm should find quickly. [SI]
    alarms : AlarmSettings
        The monitor file's ``[alarms]``.

    Returns
    -------
    dict
    """
    sigma = baseline.sigma / diagnostic.scale
    return {
        "unit": diagnostic.unit,
        "sigma": sigma,
        "step": step_si / diagnostic.scale,
        "baseline_sd_ratio": min(baseline.u_value / diagnostic.scale / sigma, 2.0)
        if sigma > 0
        else 0.0,
        "nu": baseline.nu,
        "false_alarm_nights": alarms.false_alarm_nights,
        "monte_carlo_nights": alarms.monte_carlo_nights,
    }


def design_diagnostic_alarm(inputs):
    """Design a diagnostic's charts from :func:`design_inputs`.

    Returns
    -------
    AlarmDesign
        Its angle fields in the diagnostic's shown unit times 1e-6.

    Raises
    ------
    MonitorError
        When the baseline's nights give no scatter (a zero sigma), or the
        design fails.
    """
    from imu_square.monitor.stats.alarms import design_alarms

    if not inputs["sigma"] > 0:
        raise MonitorError("its baseline's nights give no uncertainty to design on")
    with step("designing its alarm", MonitorError):
        return design_alarms(
            inputs["false_alarm_nights"],
            inputs["sigma"] * URAD,
            step_rad=inputs["step"] * URAD,
            nu=inputs["nu"],
            baseline_sd_ratio=inputs["baseline_sd_ratio"],
            ramp_rad=inputs["step"] * URAD,
            ramp_nights=RAMP_NIGHTS,
            mc_nights=inputs["monte_carlo_nights"],
        )


def stored_design(history, baseline_row, name, inputs):
    """A diagnostic's design for a baseline, made once and kept with it.

    Parameters
    ----------
    history : History
        The open history.
    baseline_row : BaselineRow
        The baseline.
    name : str
        The diagnostic.
    inputs : dict
        :func:`design_inputs`.

    Returns
    -------
    AlarmDesign
    """
    design = kept_design(baseline_row, name, inputs)
    if design is not None:
        return design
    design = design_diagnostic_alarm(inputs)
    designs = dict(baseline_row.diagnostic_designs or {})
    designs[name] = {
        "key": settings_hash(inputs),
        "inputs": inputs,
        "design": design.to_json_dict(),
    }
    history.set_diagnostic_designs(baseline_row.id, designs)
    return design


def kept_design(baseline_row, name, inputs):
    """A diagnostic's design kept with a baseline for these inputs, or None.

    Parameters
    ----------
    baseline_row : BaselineRow
        The baseline.
    name : str
        The diagnostic.
    inputs : dict
        :func:`design_inputs`.

    Returns
    -------
    AlarmDesign or None
    """
    from imu_square.monitor.stats.alarms import AlarmDesign

    kept = (baseline_row.diagnostic_designs or {}).get(name)
    if kept and kept.get("key") == settings_hash(inputs):
        return AlarmDesign.from_json_dict(kept["design"])
    return None


def describe(design, diagnostic):
    """One line for people: the limits and how soon the step is found.

    Parameters
    ----------
    design : AlarmDesign
        The diagnostic's design.
    diagnostic : Diagnostic
        The diagnostic.

    Returns
    -------
    str
    """
    unit = diagnostic.unit
    c = design.check
    return (
        f"{diagnostic.name}: Shewhart |z| > {design.shewhart.limit:.2f}, EWMA (lambda "
        f"{design.ewma.parameter:.2f}) > {design.ewma.limit:.3f}, CUSUM (k "
        f"{design.cusum.parameter:.2f}) > {design.cusum.limit:.2f} on z = change / "
        f"{design.sigma_rad / URAD:.3g} {unit} a night; one false alarm in "
        f"{design.arl0_nights:g} nights; a step of {design.step_rad / URAD:g} {unit} found after "
        f"{c.step_median:.0f} nights (median; 90 % within {c.step_p90:.0f})"
    )
