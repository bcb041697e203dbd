"""The diagnostics the monitor can trend: one table, each a number a ballbar test reports.

Each :class:`Diagnostic` is a linear combination of the sizes of one effect of
the simulator's vocabulary (:mod:`imu_square.simulate.effects`), the fit's
names for them (``imu-square discrepancy`` prints the same). This table is
the only place that ties the two: an effect renamed or a parameter added
there is changed here, and ``tests/test_monitor_diagnostics.py`` checks every term
against the declarations.

The values are stored in SI (``si_unit``) and shown in ``unit``; the monitor
file names a diagnostic's alarm by its name and that unit's suffix
(``backlash_x_um = 3.0``). Two notes on what one circle test sees:

- a common servo lag of both axes is the fit's time anchor, so the servo
  diagnostic is the mismatch ``tau_y - tau_x``, as the ballbar's is;
- a scale error of an axis reads the same as the sensor's gain on it (one
  circle cannot tell them apart: ``imu-square discrepancy`` names them
  together). The sensor's gain does not change while it stays mounted, so
  the scale's *change* is the machine's, like the squareness's.

Ballbar diagnostics without an effect in the vocabulary (cyclic error,
lateral play, stick-slip) are not here, and neither is the vibration rung by
the feed ramps: its in-phase and quadrature sizes split its amplitude by a
phase the controller's ramp sets, and the amplitude, ``hypot`` of the two, is
not a linear combination (the nightly fit still fits both).
"""

from dataclasses import dataclass

from imu_square.units import MM, MS, UM, URAD


@dataclass(frozen=True)
class Diagnostic:
    """One trended number.

    Attributes
    ----------
    name : str
        Its name in the history, the record and the monitor file.
    effect : str
        The effect of the vocabulary it belongs to.
    terms : tuple of (str, float)
        The effect's size parameters and their coefficients: the diagnostic
        is ``sum(c * size)`` in SI.
    si_unit : str
        The unit stored.
    unit : str
        The unit shown.
    scale : float
        SI value of one shown unit.
    suffix : str
        The shown unit in a field name (``um`` for µm).
    meaning : str
        What it is, for people.
    """

    name: str
    effect: str
    terms: tuple
    si_unit: str
    unit: str
    scale: float
    suffix: str
    meaning: str

    @property
    def alarm_field(self):
        """The field of the monitor file's ``[diagnostics.alarms]`` that sets its alarm."""
        return f"{self.name}_{self.suffix}"


def _per_axis(name, effect, param, si_unit, unit, scale, suffix, meaning):
    return tuple(
        Diagnostic(
            f"{name}_{axis}",
            effect,
            ((param.format(axis=axis), 1.0),),
            si_unit,
            unit,
            scale,
            suffix,
            meaning.format(axis=axis.upper()),
        )
        for axis in ("x", "y")
    )


#: Every diagnostic by effect, in the order the monitor shows them.
CATALOG = {
    "servo_mismatch": (
        Diagnostic(
            "servo_mismatch",
            "servo_mismatch",
            (("tau_y_ms", 1.0), ("tau_x_ms", -1.0)),
            "s",
            "ms",
            MS,
            "ms",
            "the Y drive's lag behind the X drive's (servo mismatch)",
        ),
    ),
    "backlash": _per_axis(
        "backlash",
        "backlash",
        "{axis}_um",
        "m",
        "µm",
        UM,
        "um",
        "lost motion of {axis} at its reversals (backlash)",
    ),
    "reversal_spikes": _per_axis(
        "reversal_spike",
        "reversal_spikes",
        "peak_{axis}_m_s2",
        "m/s²",
        "mm/s²",
        MM,
        "mm_s2",
        "peak acceleration of {axis}'s friction spike after its reversals (reversal spikes)",
    ),
    "scale_mismatch": _per_axis(
        "scale",
        "scale_mismatch",
        "{axis}_um_per_m",
        "1",
        "µm/m",
        URAD,
        "um_per_m",
        "scale error of {axis}, with the sensor's gain on it (scale mismatch)",
    ),
    "straightness_yaw": _per_axis(
        "straightness",
        "straightness_yaw",
        "{axis}_um",
        "m",
        "µm",
        UM,
        "um",
        "straightness of {axis} over its travel (straightness)",
    ),
    "structural_vibration": _per_axis(
        "vibration",
        "structural_vibration",
        "accel_{axis}_m_s2",
        "m/s²",
        "mm/s²",
        MM,
        "mm_s2",
        "acceleration of {axis}'s ringing excited at its reversals (vibration)",
    ),
}

#: The effects fitted every night unless the monitor file says otherwise.
DEFAULT_EFFECTS = tuple(CATALOG)


def diagnostics_of(effects):
    """The diagnostics of some effects, in the catalog's order.

    Parameters
    ----------
    effects : iterable of str
        Effects of :data:`CATALOG`.

    Returns
    -------
    tuple of Diagnostic
    """
    chosen = set(effects)
    return tuple(d for effect, ds in CATALOG.items() if effect in chosen for d in ds)
