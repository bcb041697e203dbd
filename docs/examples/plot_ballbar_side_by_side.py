"""
The same machine against a ballbar
==================================

A ballbar reads the machine's squareness from the ``sin 2φ`` term of its
circle; the IMU circle test reads ``theta_y - theta_x``, the machine's
squareness plus the sensor's own non-orthogonality. On a machine file,
:func:`imu_square.reference.compare.compare_methods` (``imu-square compare``)
runs both on the same circles, together with the laser diagonal and the
L, T and + straightness tests, and says where and why each departs from the
machine's squareness.

Two machines that ship with the tool: the typical machining centre
(``machine_typical.toml``: 15 µm/m, servo mismatch, backlash, scale
mismatch) and Chapman's machine 7 with yaw (``machine_chapman7_yaw.toml``), a
750 mm × 250 mm machine whose quartic X straightness makes the methods
disagree.
"""

import matplotlib.pyplot as plt

from imu_square.reference.compare import compare_methods
from imu_square.simulate import data_path, read_machine

URAD = 1e-6

# %%
# Every method on each machine
# ----------------------------
# The IMU rows use the paper's sensor (7 µg/√Hz, turned 2.1°) with the
# simulated sensor's non-orthogonality removed, as a calibration would.

comparisons = {}
for name in ("machine_typical.toml", "machine_chapman7_yaw.toml"):
    comparison = compare_methods(read_machine(data_path(name)), seed=0)
    comparisons[name] = comparison
    print(
        f"{comparison.machine_name}: model squareness "
        f"{comparison.machine_squareness_rad / URAD:.1f} µm/m"
    )
    for row in comparison.rows:
        u = row.u_machine_squareness_rad
        value = f"{row.machine_squareness_rad / URAD:7.1f}" + (f" ± {u / URAD:4.1f}" if u else "")
        print(f"  {row.method:12s} {row.where:34s} {value:>16s}  {row.note}")

# %%
# On the typical machine the ballbar, the diagonal, the + test and the IMU
# read the machine's 15 µm/m (the IMU within its uncertainty, with the local
# scale mismatch it sees through the sensor's rotation), while the L and T
# tests whose arms run near the ends of X see that axis's yaw. On machine 7
# the L and T tests see the axes' yaw where their arms run, the 220° ballbar
# arc loses the orthogonality of the form's harmonics, and the IMU circles
# away from the middle read the local squareness through the sensor's
# rotation: the mean over the row of circles agrees with the ballbar mean.
#
# Ballbar and IMU, circle by circle
# ---------------------------------

fig, axes = plt.subplots(1, 2, figsize=(10, 4), sharey=True)
for ax, comparison in zip(axes, comparisons.values(), strict=True):
    ballbar = [r for r in comparison.rows if r.method == "ballbar" and r.arc_deg == 360]
    imu = [r for r in comparison.rows if r.method == "imu"]
    x = [r.location_m[0] * 1e3 for r in ballbar]
    ax.plot(x, [r.machine_squareness_rad / URAD for r in ballbar], "s", ms=9, label="ballbar 360°")
    ax.errorbar(
        [r.location_m[0] * 1e3 + 8 for r in imu],
        [r.machine_squareness_rad / URAD for r in imu],
        yerr=[r.u_machine_squareness_rad / URAD for r in imu],
        fmt="o",
        capsize=4,
        label="IMU circle ± u",
    )
    ax.axhline(comparison.machine_squareness_rad / URAD, color="k", ls=":", label="model")
    ax.set_title(comparison.machine_name)
    ax.set_xlabel("circle centre x [mm]")
axes[0].set_ylabel("machine squareness [µm/m]")
axes[0].legend()
fig.tight_layout()

# %%
# On a real machine the ballbar's reading anchors the monitor's baseline:
# ``imu-square baseline anchor --config monitor.toml --ballbar 15.0 --u 1.0``
# taken while the baseline nights ran makes every later night report the
# machine's squareness as well as its change.
