"""The simulator's effect declarations, its model-file writer and its stage-by-stage signal."""

import math
import tomllib
from dataclasses import replace

import numpy as np
import pytest
from numpy.testing import assert_allclose

from imu_square.errors import ConfigError
from imu_square.program import TestProgram
from imu_square.simulate import (
    EFFECTS,
    MachineModel,
    SensorModel,
    data_path,
    read_machine,
    read_sensor,
    simulate_run,
    with_effects,
)
from imu_square.simulate.effects import (
    EFFECT_PARAMETERS,
    SHAPE,
    SIZE,
    effect_parameters,
    with_effect_values,
)
from imu_square.simulate.machine import machine_from_mapping
from imu_square.simulate.sensor import sensor_from_mapping
from imu_square.simulate.signal import axis_motion, model_timeline, sense_motion
from imu_square.simulate.writer import machine_to_toml, sensor_to_toml, write_model_files


def effect_values(name, machine, sensor):
    """An effect's parameters on a machine and sensor, in display units (as the tests read them).

    Parameters
    ----------
    name : str
        One of :data:`EFFECTS`.
    machine : MachineModel
    sensor : SensorModel

    Returns
    -------
    dict of str to float
        By parameter name (flags as 0.0 or 1.0).
    """
    return {p.name: p.get(machine, sensor) / p.scale for p in effect_parameters(name)}


def sensed_signal(timeline, machine, sensor, t_s, power_on_s=0.0):
    """Noise-free specific force in the sensor frame at true times ``t_s``.

    Parameters
    ----------
    timeline : Timeline
        The commanded path (:func:`model_timeline`).
    machine : MachineModel
        The machine.
    sensor : SensorModel
        The sensor; its noise, ADC steps and clipping are not applied.
    t_s : ndarray, shape (n,)
        True times on the timeline, increasing. [s]
    power_on_s : float
        The sensor's time since power-on at ``t = 0`` (its warm-up). [s]

    Returns
    -------
    ndarray, shape (n, 3)
        Specific force along the sensor's x, y, z after gain and bias. [m/s^2]
    """
    t_s = np.asarray(t_s, dtype=np.float64)
    paths = [axis_motion(timeline, machine, t_s, axis) for axis in (0, 1)]
    pos, _, acc = machine.geometry.apply(paths[0], paths[1], t_s)
    return sense_motion(machine, sensor, pos, acc, t_s, power_on_s)


def test_every_effect_declares_its_parameters():
    assert set(EFFECT_PARAMETERS) == set(EFFECTS)
    for name in EFFECTS:
        params = effect_parameters(name)
        assert any(p.role == SIZE for p in params), name
        for p in params:
            assert p.effect == name and p.role in (SIZE, SHAPE)
            assert p.low <= p.typical <= p.high, p.key
            assert p.scale > 0 and math.isfinite(p.scale)
            if p.role == SHAPE:
                assert p.scan and all(p.low <= v <= p.high for v in p.scan), p.key


@pytest.mark.parametrize("name", EFFECTS)
def test_declared_typical_values_are_the_presets(name):
    machine, sensor = with_effects([name])
    values = effect_values(name, machine, sensor)
    for p in effect_parameters(name):
        assert values[p.name] == pytest.approx(p.typical, rel=1e-12, abs=1e-12), p.key
    # switching every size off gives back an ideal machine and sensor
    off = {p.name: 0.0 for p in effect_parameters(name) if p.role == SIZE}
    m, s = with_effect_values(name, machine, sensor, off)
    assert name not in {**m.effects(), **s.effects()}


def test_set_and_get_round_trip_every_parameter():
    machine, sensor = MachineModel(), SensorModel()
    for name in EFFECTS:
        for p in effect_parameters(name):
            value = 1.0 if p.is_flag else 0.5 * (p.low + p.high) + 0.1 * (p.high - p.low)
            m, s = p.set(machine, sensor, value * p.scale)
            assert p.get(m, s) / p.scale == pytest.approx(value, rel=1e-12), p.key


def test_unknown_effect_or_parameter_is_refused():
    with pytest.raises(ConfigError, match="'wobble' is not in the vocabulary"):
        effect_parameters("wobble")
    with pytest.raises(ConfigError, match="unknown parameter 'tau_z_ms'"):
        with_effect_values("servo_mismatch", MachineModel(), SensorModel(), {"tau_z_ms": 1.0})


def _everything():
    machine, sensor = with_effects(
        EFFECTS,
        read_machine(data_path("machine_typical.toml")),
        read_sensor(data_path("sensor_paper.toml")),
    )
    sensor = replace(sensor, temperature_c=21.5, temperature_rise_c=3.0, beta_rad=-12e-6)
    return machine, sensor


def test_written_model_files_read_back_to_the_same_model(tmp_path):
    machine, sensor = _everything()
    assert machine_from_mapping(tomllib.loads(machine_to_toml(machine, "a\nheader"))) == machine
    stick = replace(machine, spike_symmetric=True)
    assert machine_from_mapping(tomllib.loads(machine_to_toml(stick))) == stick
    assert sensor_from_mapping(tomllib.loads(sensor_to_toml(sensor))) == sensor
    ideal = SensorModel()  # no drift section, no temperature channel, infinite range
    assert sensor_from_mapping(tomllib.loads(sensor_to_toml(ideal))) == ideal
    paths = write_model_files(tmp_path / "m", TestProgram(), machine, sensor, "fitted")
    assert read_machine(paths["machine"]) == machine
    assert read_sensor(paths["sensor"]) == sensor
    assert paths["machine"].read_text().startswith("# fitted\n")


def test_sensed_signal_is_simulate_runs_reading_sample_for_sample():
    machine, sensor = _everything()
    machine = replace(machine, tilt_per_m=(2e-4, -1e-4, 3e-4, 1e-4))  # all four couplings
    noiseless = replace(
        sensor, noise_density_m_s2_rthz=0.0, resolution_m_s2=0.0, range_m_s2=math.inf
    )
    program = TestProgram(radius_m=0.05, feed_m_per_s=0.05, cycles_per_direction=2, dwell_s=0.5)
    recording, _ = simulate_run(program, machine, noiseless, seed=1)
    t_true = recording.time_s / (1 + sensor.clock_ppm * 1e-6)
    mine = sensed_signal(model_timeline(program, machine), machine, noiseless, t_true)
    # the recording holds float32: equal to its rounding
    assert_allclose(recording.accel, mine, rtol=0, atol=2e-6)
    assert np.max(np.abs(recording.accel[:, :2] - mine[:, :2])) < 1e-6


def test_chapman_s_machine_7_written_keeps_its_quartic_form():
    from imu_square.simulate.geometry import chapman_machine
    from imu_square.simulate.machine import MachineModel

    machine = MachineModel(geometry=chapman_machine(7, yaw=True))
    assert machine.geometry.straightness_x_quartic_m != 0
    assert machine_from_mapping(tomllib.loads(machine_to_toml(machine, "machine 7"))) == machine
