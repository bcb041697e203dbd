"""The fitted model's parameters: the base model's and every candidate effect's.

A model is a :class:`ModelState`: the simulator's :class:`MachineModel` and
:class:`SensorModel`, plus the time anchor of each block (how the
simulator's timeline sits on the recording's clock). A :class:`Parameter` reads and
writes one number of it in display units.

The base model is the paper's (docs/model.md): the squareness, the sensor's
rotation ``eps_c`` and static tilt (the offsets), and per block a time
anchor that absorbs a common servo lag and where the motion-midpoint
detection placed the block. The sensor's non-orthogonality ``beta`` adds to the
squareness and cannot be told from it in one circle test (paper, Eq. 4); the
base model carries their sum as the machine's squareness.

Candidate parameters come from the simulator's own declarations
(:data:`imu_square.simulate.effects.EFFECT_PARAMETERS`): a new effect there is
a new candidate here.
"""

import math
from dataclasses import dataclass, replace

from imu_square.simulate.effects import SHAPE, SIZE, effect_parameters
from imu_square.units import MS, UM, URAD

BASE = "base"
# Difference step of a time anchor: the servo lag's (a tenth of its typical 2 ms). [ms]
ANCHOR_STEP_MS = 0.2


@dataclass(frozen=True)
class ModelState:
    """A complete model: machine, sensor and the time anchor of each block.

    Attributes
    ----------
    machine : MachineModel
    sensor : SensorModel
    anchors_s : tuple of float
        Time anchor of each block: the simulator's block midpoint is placed
        this long after the recording's detected motion midpoint. [s]
    """

    machine: object
    sensor: object
    anchors_s: tuple


@dataclass(frozen=True)
class Parameter:
    """One fitted number of a :class:`ModelState`, in display units.

    Attributes
    ----------
    effect : str
        ``"base"`` or the name of an effect of the vocabulary.
    name : str
        Name within the effect (the file field for effects).
    unit : str
        Display unit.
    role : str
        ``"base"``, ``"size"`` or ``"shape"``.
    step : float
        Finite-difference step, display units.
    low, high : float
        Range allowed in a fit, display units.
    declared : EffectParameter or None
        The simulator's declaration, for effect parameters.
    block : int
        For a time anchor, its block; else -1.
    """

    effect: str
    name: str
    unit: str
    role: str
    step: float
    low: float = -math.inf
    high: float = math.inf
    declared: object = None
    block: int = -1

    @property
    def key(self):
        """``effect.name``."""
        return f"{self.effect}.{self.name}"

    def get(self, state):
        """The value in display units."""
        if self.declared is not None:
            return self.declared.get(state.machine, state.sensor) / self.declared.scale
        return _BASE_GET[self.name.split("_block")[0]](state, self) / _BASE_SCALE[self.unit]

    def set(self, state, value):
        """A new state with this parameter at ``value`` (display units)."""
        if self.declared is not None:
            m, s = self.declared.set(state.machine, state.sensor, value * self.declared.scale)
            return replace(state, machine=m, sensor=s)
        return _BASE_SET[self.name.split("_block")[0]](state, self, value * _BASE_SCALE[self.unit])


_BASE_SCALE = {"µm/m": UM, "deg": math.pi / 180, "µrad": URAD, "ms": MS}


def _set_alpha(state, p, v):
    g = replace(state.machine.geometry, machine_squareness_rad=v)
    return replace(state, machine=replace(state.machine, geometry=g))


def _set_tilt(state, p, v, i):
    tilt = list(state.sensor.tilt_rad)
    tilt[i] = v
    return replace(state, sensor=replace(state.sensor, tilt_rad=tuple(tilt)))


def _set_anchor(state, p, v):
    anchors = list(state.anchors_s)
    anchors[p.block] = v
    return replace(state, anchors_s=tuple(anchors))


_BASE_GET = {
    "machine_squareness_um_per_m": lambda s, p: s.machine.geometry.machine_squareness_rad,
    "eps_c_deg": lambda s, p: s.sensor.eps_c_rad,
    "tilt_x_urad": lambda s, p: s.sensor.tilt_rad[0],
    "tilt_y_urad": lambda s, p: s.sensor.tilt_rad[1],
    "anchor": lambda s, p: s.anchors_s[p.block],
}
_BASE_SET = {
    "machine_squareness_um_per_m": _set_alpha,
    "eps_c_deg": lambda s, p, v: replace(s, sensor=replace(s.sensor, eps_c_rad=v)),
    "tilt_x_urad": lambda s, p, v: _set_tilt(s, p, v, 0),
    "tilt_y_urad": lambda s, p, v: _set_tilt(s, p, v, 1),
    "anchor": _set_anchor,
}


def base_parameters(n_blocks):
    """The base model's parameters.

    Parameters
    ----------
    n_blocks : int
        Blocks in the recording (one time anchor each).

    Returns
    -------
    list of Parameter
    """
    params = [
        Parameter(BASE, "machine_squareness_um_per_m", "µm/m", BASE, 1.0),
        Parameter(BASE, "eps_c_deg", "deg", BASE, 1e-3),
        Parameter(BASE, "tilt_x_urad", "µrad", BASE, 10.0),
        Parameter(BASE, "tilt_y_urad", "µrad", BASE, 10.0),
    ]
    params += [
        Parameter(BASE, f"anchor_block{b}_ms", "ms", BASE, ANCHOR_STEP_MS, block=b)
        for b in range(n_blocks)
    ]
    return params


def effect_model_parameters(effect):
    """An effect's parameters as fit parameters, from the simulator's declaration.

    Size parameters take a step of a tenth of their typical value (a
    thousandth of their range when the typical value is zero). The effects
    are linear in their sizes but for the time lags, and a lag moves the
    onsets of the friction spike and of the vibration, which are steps in
    acceleration: below one sample period the model's dependence on a lag
    is a staircase, so its difference steps must span several samples (the
    time anchor's step matches the lag's, so that a common lag of both
    axes stays exactly the anchor's derivative). Shapes take a hundredth of
    their typical value and the declared range as bounds.

    Parameters
    ----------
    effect : str
        A name of the vocabulary.

    Returns
    -------
    list of Parameter
    """
    out = []
    for d in effect_parameters(effect):
        if d.role == SIZE:
            step = 0.1 * abs(d.typical) if d.typical else 1e-3 * (d.high - d.low)
            out.append(Parameter(effect, d.name, d.unit, SIZE, step, declared=d))
        else:
            step = 0.01 * abs(d.typical) if d.typical else 1e-3 * (d.high - d.low)
            out.append(Parameter(effect, d.name, d.unit, SHAPE, step, d.low, d.high, declared=d))
    return out
