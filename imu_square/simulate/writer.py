"""Write a machine and a sensor as the simulator's own description files (TOML).

The inverse of :func:`imu_square.simulate.read_machine` and
:func:`imu_square.simulate.read_sensor`: every field is written in the file's
unit, so that reading the text back gives the same model (to the last digit
of a float's ``repr``). A fitted model written this way runs in
``imu-square simulate --machine ... --sensor ...`` like a hand-written one.
"""

import math
from pathlib import Path

from imu_square.units import HOUR, MS, UG, UM, URAD, G


def _value(v):
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, str):
        return '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(v, list | tuple):
        return "[" + ", ".join(_value(x) for x in v) + "]"
    v = float(v) + 0.0  # no "-0.0"
    return repr(v) if math.isfinite(v) else ("inf" if v > 0 else "-inf" if v < 0 else "nan")


def _toml(sections, header=""):
    lines = [f"# {line}" if line else "#" for line in header.splitlines()]
    for name, fields in sections:
        lines += ["", f"[{name}]"] if lines else [f"[{name}]"]
        lines += [f"{key} = {_value(value)}" for key, value in fields.items()]
    return "\n".join(lines) + "\n"


def machine_to_toml(machine, header=""):
    """A machine as the text of a machine file.

    Parameters
    ----------
    machine : MachineModel
        The machine.
    header : str
        Comment lines to put first.

    Returns
    -------
    str
        TOML that :func:`imu_square.simulate.read_machine` reads back to ``machine``.
    """
    g = machine.geometry
    m = machine
    sections = [
        ("machine", {"name": m.name, "ramp_s": m.ramp_s, "ramp_profile": m.ramp_profile}),
        (
            "geometry",
            {
                "machine_squareness_um_per_m": g.machine_squareness_rad / UM,
                "axis_length_mm": [g.length_x_m * 1e3, g.length_y_m * 1e3],
                "axis_centre_mm": [g.axis_centre_m[0] * 1e3, g.axis_centre_m[1] * 1e3],
            },
        ),
        (
            "squareness_drift",
            {"rate_um_per_m_per_h": g.machine_squareness_rate_rad_s / (UM / HOUR)},
        ),
        ("scale_mismatch", {"x_um_per_m": g.scale_x / UM, "y_um_per_m": g.scale_y / UM}),
        (
            "straightness_yaw",
            {
                "x_um": g.straightness_x_m / UM,
                "y_um": g.straightness_y_m / UM,
                "x_quartic_um": g.straightness_x_quartic_m / UM,
                "yaw_x": bool(g.yaw_x),
                "yaw_y": bool(g.yaw_y),
            },
        ),
        ("servo_mismatch", {"tau_x_ms": m.tau_x_s / MS, "tau_y_ms": m.tau_y_s / MS}),
        (
            "backlash",
            {
                "x_um": m.backlash_x_m / UM,
                "y_um": m.backlash_y_m / UM,
                "take_up_ms": m.backlash_take_up_s / MS,
                "onset": m.backlash_onset,
            },
        ),
        (
            "reversal_spikes",
            {
                "peak_x_m_s2": m.spike_x_m_s2,
                "peak_y_m_s2": m.spike_y_m_s2,
                "tau_ms": m.spike_tau_s / MS,
                "onset_tau": m.spike_onset,
                "symmetric": bool(m.spike_symmetric),
            },
        ),
        (
            "structural_vibration",
            {
                "accel_x_m_s2": m.vibration_x_m_s2,
                "accel_y_m_s2": m.vibration_y_m_s2,
                "start_stop_m_s2": m.vibration_start_stop_m_s2,
                "start_stop_quadrature_m_s2": m.vibration_start_stop_quadrature_m_s2,
                "frequency_hz": m.vibration_hz,
                "damping_ratio": m.vibration_damping,
            },
        ),
        (
            "gravity_coupling",
            dict(
                zip(
                    (
                        "x_per_x_urad_per_m",
                        "x_per_y_urad_per_m",
                        "y_per_x_urad_per_m",
                        "y_per_y_urad_per_m",
                    ),
                    (k / URAD for k in m.tilt_per_m),
                    strict=True,
                )
            ),
        ),
    ]
    return _toml(sections, header)


def sensor_to_toml(sensor, header=""):
    """A sensor as the text of a sensor file.

    Parameters
    ----------
    sensor : SensorModel
        The sensor.
    header : str
        Comment lines to put first.

    Returns
    -------
    str
        TOML that :func:`imu_square.simulate.read_sensor` reads back to ``sensor``.
    """
    s = sensor
    main = {
        "model": s.model,
        "sample_rate_hz": s.sample_rate_hz,
        "noise_density_ug_rthz": s.noise_density_m_s2_rthz / UG,
        "flicker_corner_hz": s.flicker_corner_hz,
        "range_g": s.range_m_s2 / G,
        "resolution_ug": s.resolution_m_s2 / UG,
        "eps_c_deg": math.degrees(s.eps_c_rad),
        "beta_urad": s.beta_rad / URAD,
        "tilt_x_urad": s.tilt_rad[0] / URAD,
        "tilt_y_urad": s.tilt_rad[1] / URAD,
    }
    if math.isfinite(s.temperature_c):
        main["temperature_c"] = s.temperature_c
    sections = [("sensor", main)]
    if s.beta_0_rad is not None:
        drift = {
            "beta_0_urad": s.beta_0_rad / URAD,
            "tau_warm_s": s.tau_warm_s,
            "temperature_rise_c": s.temperature_rise_c,
        }
        sections.append(("sensor_thermal_drift", drift))
    sections.append(
        (
            "sensor_gain_mismatch",
            {
                "gain_percent": [g / 1e-2 for g in s.gain],
                "bias_mg": [b / (1e-3 * G) for b in s.bias_m_s2],
            },
        )
    )
    sections.append(("sample_clock_error", {"ppm": s.clock_ppm}))
    return _toml(sections, header)


def write_model_files(directory, program, machine, sensor, header=""):
    """Write ``program.toml``, ``machine.toml`` and ``sensor.toml`` into a directory.

    Parameters
    ----------
    directory : str or Path
        Created if missing.
    program : TestProgram
        The test program.
    machine : MachineModel
        The machine.
    sensor : SensorModel
        The sensor.
    header : str
        Comment lines to put first in the machine and sensor files.

    Returns
    -------
    dict of str to Path
        ``{"program": ..., "machine": ..., "sensor": ...}``.
    """
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    paths = {name: directory / f"{name}.toml" for name in ("program", "machine", "sensor")}
    paths["program"].write_text(program.to_toml(), encoding="utf-8")
    paths["machine"].write_text(machine_to_toml(machine, header), encoding="utf-8")
    paths["sensor"].write_text(sensor_to_toml(sensor, header), encoding="utf-8")
    return paths
