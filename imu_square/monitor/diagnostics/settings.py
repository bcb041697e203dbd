"""The monitor file's ``[diagnostics]`` table: which effects are fitted every night, their
shapes, and the diagnostics that have an alarm of their own.

::

    [diagnostics]
    # the effects fitted after every valid night; [] fits none. Default: all six
    effects = ["servo_mismatch", "backlash", "reversal_spikes", "scale_mismatch",
               "straightness_yaw", "structural_vibration"]

    [diagnostics.backlash]          # the shapes the fit holds: the machine file's fields
    take_up_ms = 5.0                # (default: each shape's typical value)

    [diagnostics.structural_vibration]
    frequency_hz = 40.0
    damping_ratio = 0.05

    [diagnostics.alarms]            # off by default: a diagnostic's name and unit, and
    backlash_x_um = 3.0             # the change its charts should find quickly

The fit's model runs the program's commanded motion as the night ran it: the
monitor file's ``[program] motion`` (our own trajectory, or LinuxCNC's
planner's, :mod:`imu_square.simulate.sources`).

An alarm is designed like the squareness's (``[alarms]`` false_alarm_nights
and monte_carlo_nights) on the diagnostic's change against its value over
the baseline's nights (:mod:`.trend`).
"""

from dataclasses import dataclass, field

from imu_square import __version__
from imu_square.errors import MonitorConfigError
from imu_square.monitor.diagnostics.catalog import CATALOG, DEFAULT_EFFECTS, diagnostics_of
from imu_square.monitor.history.encoding import settings_hash
from imu_square.simulate.effects import SHAPE, effect_parameters
from imu_square.validation import TomlTable


@dataclass(frozen=True)
class DiagnosticSettings:
    """What the monitor fits after every valid night, and which diagnostics have alarms.

    Attributes
    ----------
    effects : tuple of str
        Effects of :data:`~.catalog.CATALOG` fitted every night; empty for none.
    shapes : dict of str to dict of str to float
        Shape values held, by effect and parameter (display units); the rest
        take their declared typical values.
    alarm_steps : dict of str to float
        Diagnostic name to the change its alarm should find quickly, in SI;
        a diagnostic not named has no alarm.
    motion : str
        The commanded motion the fit's model runs, one of
        :data:`~imu_square.simulate.sources.MOTION_SOURCES`: the night's own
        (a controller's ramps read through our trajectory's look like a
        servo mismatch and spikes).
    """

    effects: tuple = DEFAULT_EFFECTS
    shapes: dict = field(default_factory=dict)
    alarm_steps: dict = field(default_factory=dict)
    motion: str = "trajectory"

    @property
    def enabled(self):
        """Whether any effect is fitted."""
        return bool(self.effects)

    def diagnostics(self):
        """The :class:`~.catalog.Diagnostic` of the set, in the catalog's order."""
        return diagnostics_of(self.effects)

    def held_shapes(self):
        """Every shape the fit holds: ``{effect: {parameter: value}}``. [display units]"""
        out = {}
        for effect in self.effects:
            given = self.shapes.get(effect, {})
            out[effect] = {
                p.name: float(given.get(p.name, p.typical))
                for p in effect_parameters(effect)
                if p.role == SHAPE
            }
        return out

    def stored(self):
        """What a night's fit is keyed by in the history (its hash): effects, shapes,
        software, and the motion unless our own trajectory.

        Returns
        -------
        dict
            JSON values.
        """
        stored = {
            "effects": list(self.effects),
            "shapes": self.held_shapes(),
            "software": __version__,
        }
        if self.motion != "trajectory":  # the fits stored before the choice keep their key
            stored["motion"] = self.motion
        return stored

    def key(self):
        """:func:`~imu_square.monitor.history.encoding.settings_hash` of :meth:`stored`."""
        return settings_hash(self.stored())


def diagnostics_from_mapping(table, source):
    """Validate the ``[diagnostics]`` table of a monitor file.

    Parameters
    ----------
    table : object
        The parsed table (absent: the defaults).
    source : str
        The file, for messages.

    Returns
    -------
    DiagnosticSettings

    Raises
    ------
    MonitorConfigError
        One line naming the field, what is allowed and what came.
    """
    if table is None:
        return DiagnosticSettings()
    top = TomlTable(
        table, "[diagnostics]", ("effects", "alarms", *CATALOG), source, error=MonitorConfigError
    )
    effects = top.choices("effects", tuple(CATALOG), default=list(DEFAULT_EFFECTS))
    shapes = {}
    for effect in CATALOG:
        if not top.has(effect):
            continue
        if effect not in effects:
            top.fail(
                effect, f"a table only for an effect of [diagnostics] effects {effects!r}", effect
            )
        declared = {p.name: p for p in effect_parameters(effect) if p.role == SHAPE}
        sub = TomlTable(
            top.get(effect),
            f"[diagnostics.{effect}]",
            tuple(declared),
            source,
            error=MonitorConfigError,
        )
        shapes[effect] = {name: _shape(sub, p) for name, p in declared.items() if sub.has(name)}
    chosen = diagnostics_of(effects)
    fields = {d.alarm_field: d for d in chosen}
    alarms = TomlTable(
        top.get("alarms", {}),
        "[diagnostics.alarms]",
        tuple(fields),
        source,
        error=MonitorConfigError,
    )
    steps = {
        d.name: alarms.number(name, 0.0, _largest_change(d), lo_open=True) * d.scale
        for name, d in fields.items()
        if alarms.has(name)
    }
    return DiagnosticSettings(effects=effects, shapes=shapes, alarm_steps=steps)


def _shape(table, p):
    """A shape's value: a number within its declared range, or true/false for a flag."""
    if p.is_flag:
        return 1.0 if table.flag(p.name) else 0.0
    return table.number(p.name, p.low, p.high)


def _largest_change(diagnostic):
    """The largest change a diagnostic can make within its effect's physical ranges. [shown]"""
    declared = {p.name: p for p in effect_parameters(diagnostic.effect)}
    reach = sum(
        abs(c) * max(abs(declared[name].low), abs(declared[name].high)) * declared[name].scale
        for name, c in diagnostic.terms
    )
    return float(f"{2 * reach / diagnostic.scale:.6g}")
