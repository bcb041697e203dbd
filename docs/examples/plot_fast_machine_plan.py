"""
A test planned for a fast machine
=================================

How long must a machine run circles, and how fast, for the monitor to see a
change of 10 µm/m? :func:`imu_square.program.planner.plan_test` (``imu-square
plan``) answers for a sensor and a machine: it searches the radius, feed and
cycles within the machine's feed, acceleration and travel and the sensor's
range, and predicts the standard deviation of one run from the Cramér-Rao
bound at the sensor's noise at the circle frequency.

Here a fast machining centre (30 m/min, 10 m/s², 500 mm of travel) with an
ADXL355-class sensor (25 µg/√Hz). We plan for a two-minute slot, then check the
prediction by simulating the planned test and analysing it with the pipeline.
"""

import dataclasses

import matplotlib.pyplot as plt
import numpy as np

from imu_square.pipeline import analyze
from imu_square.program.planner import Goal, Limits, SensorSpec, plan_test
from imu_square.simulate import data_path, read_machine, read_sensor, simulate_run

G = 9.80665
URAD = 1e-6
sensor_spec = SensorSpec(noise_density_m_s2_rthz=25e-6 * G)
goal = Goal(change_rad=10 * URAD, baseline_runs=5, stable_servo=True)

# %%
# The plan for two minutes
# ------------------------

limits = Limits(max_feed_m_s=0.5, max_accel_m_s2=10.0, travel_m=0.5, time_s=120.0)
plan = plan_test(sensor_spec, limits, goal)
print(plan.program.describe())
print(
    f"centripetal {plan.program.centripetal_m_s2:.2f} m/s², {plan.duration_s:.0f} s on the machine"
)
print(
    f"one run: sigma {plan.sigma_run_rad / URAD:.2f} µm/m (Cramér-Rao bound "
    f"{plan.crb_run_rad / URAD:.2f}, efficiency {plan.efficiency:.2f})"
)
print(
    f"against a baseline of 5 runs: sigma {plan.sigma_change_rad / URAD:.2f} µm/m; "
    f"detects {plan.detectable_change_rad / URAD:.1f} µm/m at 95 %"
)

# %%
# The prediction against the simulator
# ------------------------------------
# Eight simulated runs of the planned test on a machine with a servo mismatch,
# through the same pipeline the monitor uses. Their scatter should be about
# the predicted sigma of one run (eight runs estimate it to about ±25 %).

machine = read_machine(data_path("machine_ideal.toml"))
machine = dataclasses.replace(machine, tau_x_s=2.0e-3, tau_y_s=2.5e-3)
sensor = read_sensor(data_path("sensor_paper.toml"))
sensor = dataclasses.replace(sensor, noise_density_m_s2_rthz=sensor_spec.noise_density_m_s2_rthz)
values = []
for seed in range(8):
    recording, truth = simulate_run(plan.program, machine, sensor, seed=seed)
    result = analyze(recording)
    values.append((result.squareness_rad - truth["expected_squareness_rad"]) / URAD)
values = np.array(values)
print(
    f"simulated: error {values.mean():+.2f} µm/m on average, scatter "
    f"{values.std(ddof=1):.2f} µm/m against the predicted {plan.sigma_run_rad / URAD:.2f}"
)

# %%
# What more time buys
# -------------------
# The planner's prediction for slots from one to ten minutes: the detectable
# change falls as one over the square root of the time.

slots = [60, 90, 120, 180, 300, 450, 600]
detect = [
    plan_test(sensor_spec, dataclasses.replace(limits, time_s=t), goal).detectable_change_rad / URAD
    for t in slots
]
fig, ax = plt.subplots(figsize=(7, 4))
ax.plot(slots, detect, "o-", label="planned test")
ax.plot(120, plan.detectable_change_rad / URAD, "s", ms=10, mfc="none", label="the plan above")
ax.axhline(10, color="tab:red", ls="--", label="the goal: 10 µm/m")
ax.set_xlabel("time on the machine [s]")
ax.set_ylabel("change detected at 95 % [µm/m]")
ax.set_title("ADXL355-class sensor on a 30 m/min, 10 m/s² machine")
ax.legend()
fig.tight_layout()
