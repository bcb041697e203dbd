"""A night's diagnostics: the fixed set of effects fitted to its recording, as a history row.

:func:`diagnose_recording` runs after the night's analysis, on every valid
night, and never raises: a fit that fails gives a row whose diagnostics all
carry its one-line reason, and the night's squareness stands without them.
"""

import math
import time
from dataclasses import replace

import numpy as np

from imu_square.log import logger
from imu_square.monitor.history.encoding import first_line
from imu_square.monitor.history.rows import DiagnosticFitRow, DiagnosticRow
from imu_square.simulate.effects import effect_parameters

NOT_IDENTIFIABLE = "not identifiable in this test"
NOT_FINITE = "the diagnostic fit gave no finite value"


def diagnose_recording(settings, recording, program, analysis):
    """Fit the diagnostic set to a valid night's recording.

    Parameters
    ----------
    settings : DiagnosticSettings
        The monitor file's ``[diagnostics]``.
    recording : Recording
        The night's recording, which the analysis accepted.
    program : TestProgram or None
        The program it ran (the recording's own when None); its commanded
        motion is the settings' ``motion``.
    analysis : AnalysisSettings
        The monitor's analysis settings (the segmentation's filter).

    Returns
    -------
    DiagnosticFitRow or None
        Its ``run_id`` left for the store; None when no effect is fitted.
    """
    from imu_square.discrepancy.diagnose import fit_effects
    from imu_square.errors import AnalysisError, step
    from imu_square.simulate.sources import commanded_motion

    if not settings.enabled:
        return None
    start = time.perf_counter()
    try:
        program = program or recording.program
        with step("the diagnostic fit", AnalysisError):
            fit = fit_effects(
                recording,
                program,
                settings.effects,
                settings.held_shapes(),
                analysis=replace(analysis.options(), bootstrap_n=0),
                motion=commanded_motion(program, settings.motion, logger.info),
            )
    except Exception as exc:  # no failure of the fit may lose the night
        logger.debug("the diagnostic fit failed", exc_info=True)
        reason = first_line(exc)
        if not reason.startswith("the diagnostic fit"):
            reason = f"the diagnostic fit failed: {type(exc).__name__}: {reason}"
        logger.warning("%s", reason)
        return DiagnosticFitRow(
            settings=settings.stored(),
            seconds=time.perf_counter() - start,
            failure=reason,
            values=tuple(
                DiagnosticRow(name=d.name, unit=d.si_unit, missing_reason=reason)
                for d in settings.diagnostics()
            ),
        )
    return DiagnosticFitRow(
        settings=settings.stored(),
        seconds=time.perf_counter() - start,
        fit={
            "rss": fit.rss,
            "dof": fit.dof,
            "u_scale": fit.scale,
            "steps": fit.steps,
            "settled": fit.settled,
            "last_step_u": fit.last_step_u,
            "simulator_runs": fit.evaluations,
            "timings_s": fit.timings_s,
            "sizes": {v.name: v.to_json_dict() for v in fit.values},
        },
        values=tuple(_diagnostic(d, fit) for d in settings.diagnostics()),
    )


def _diagnostic(diagnostic, fit):
    """One diagnostic from the fitted sizes: ``sum(c * size)`` and its uncertainty (SI)."""
    declared = {p.name: p for p in effect_parameters(diagnostic.effect)}
    keys = [f"{diagnostic.effect}.{name}" for name, _ in diagnostic.terms]
    index = [next(i for i, v in enumerate(fit.values) if v.name == k) for k in keys]
    coef = np.array([c * declared[name].scale for name, c in diagnostic.terms])
    if not any(fit.values[i].identifiable for i in index):
        return DiagnosticRow(
            name=diagnostic.name, unit=diagnostic.si_unit, missing_reason=NOT_IDENTIFIABLE
        )
    value = float(coef @ np.array([fit.values[i].value for i in index]))
    cov = fit.covariance[np.ix_(index, index)]
    variance = float(coef @ cov @ coef)
    if not (math.isfinite(value) and math.isfinite(variance)):
        return DiagnosticRow(
            name=diagnostic.name, unit=diagnostic.si_unit, missing_reason=NOT_FINITE
        )
    u = math.sqrt(max(variance, 0.0))
    return DiagnosticRow(name=diagnostic.name, unit=diagnostic.si_unit, value=value, u_value=u)
