"""
A discrepancy found, named and closed
=====================================

The simulator is the model of the machine and the sensor. When a recording
disagrees with the model fitted to it by more than the noise, something the
model lacks is at work. :func:`imu_square.discrepancy.find_discrepancy`
(``imu-square discrepancy RUN.mcap``) fits the base model (squareness, sensor
rotation and offsets), measures the gap in nine views, each normalised by the
noise floor (1.0 = explained down to the noise), names the effect of the
simulator's vocabulary that closes the gap best, adds it, refits, and repeats
while an effect is significant. The theory is in :doc:`/discrepancy`.

Here the "recording" is simulated with two effects the base model lacks: a
servo mismatch between the axes and friction spikes after each reversal. The
test is short (r = 25 mm at 9000 mm/min, 20 cycles each way) and the sensor
is the paper's.
"""

import dataclasses

import matplotlib.pyplot as plt
import numpy as np

from imu_square.discrepancy import find_discrepancy
from imu_square.program import read_program
from imu_square.simulate import data_path, read_machine, read_sensor, simulate_run, with_effects

paper = read_program(data_path("program_paper.toml"))
program = dataclasses.replace(
    paper, radius_m=0.025, feeds_m_per_s=(0.15,), cycles_per_feed=(20,), cycles_per_direction=20
)
machine, sensor = with_effects(
    ["servo_mismatch", "reversal_spikes"],
    read_machine(data_path("machine_ideal.toml")),
    read_sensor(data_path("sensor_paper.toml")),
)
print(program.describe())
print(
    f"put in: servo lags x {machine.tau_x_s * 1e3:.2f} ms, y {machine.tau_y_s * 1e3:.2f} ms; "
    f"spikes x {machine.spike_x_m_s2:.3f}, y {machine.spike_y_m_s2:.3f} m/s², "
    f"tau {machine.spike_tau_s * 1e3:.0f} ms"
)
recording, truth = simulate_run(program, machine, sensor, seed=2)

# %%
# The workflow
# ------------
# What ``imu-square discrepancy`` prints: the noise floor, the base model, each
# step with the effect it named and its fitted parameters, and the gap per view
# after each step.

result = find_discrepancy(recording)
print(result.summary())

# %%
# Only the *difference* of the two servo lags shows in a circle test: a common
# lag is a rotation of both phases, which the sensor rotation ``eps_c``
# absorbs. The fitted lags are that difference, with one lag near zero (the
# note says when a fit leaves an effect's physical range).
#
# The gap closing, view by view
# -----------------------------

views = list(result.base_gap)
stages = [("base", result.base_gap)] + [(f"+{s.effect}", s.gap_after) for s in result.steps]
fig, ax = plt.subplots(figsize=(9, 4))
width = 0.8 / len(stages)
for i, (label, gaps) in enumerate(stages):
    ax.bar(np.arange(len(views)) + i * width, [gaps[v].gap for v in views], width, label=label)
ax.axhline(1.0, color="k", ls="--", lw=1, label="noise floor")
ax.set_yscale("log")
ax.set_xticks(np.arange(len(views)) + width * (len(stages) - 1) / 2, views, rotation=20)
ax.set_ylabel("gap / noise floor")
ax.set_title("The model's gap to the recording, step by step")
ax.legend(fontsize=8)
fig.tight_layout()
