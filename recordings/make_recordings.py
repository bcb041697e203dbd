#!/usr/bin/env python3
"""Re-create the sample recordings in this folder, each with its truth file.

    python3 recordings/make_recordings.py

Every recording is simulated by ``imu-square simulate`` from the files in
``recordings/config/`` (or the package's built-in files) with a fixed seed, so
the output is reproducible bit for bit.
"""

import sys
from pathlib import Path

from imu_square.cli import main

HERE = Path(__file__).resolve().parent
CONFIG = HERE / "config"
# A fixed start, so that the files are the same bit for bit every time.
START = "2023-11-14T22:13:20Z"

# name: (extra arguments of `imu-square simulate`, what the recording shows)
RECORDINGS = {
    "square_20um": (
        ["--machine", CONFIG / "machine_square.toml", "--seed", "1"],
        "+20 µm/m machine squareness only; the sensor adds 10 µm/m of its own non-orthogonality",
    ),
    "typical_machine": (
        [
            "--effects",
            "servo_mismatch,backlash,reversal_spikes,structural_vibration",
            "--machine",
            CONFIG / "machine_square.toml",
            "--seed",
            "2",
        ],
        "the same machine with servo mismatch, backlash, reversal spikes and vibration",
    ),
    "gravity_no_events": (
        [
            "--effects",
            "gravity_coupling",
            "--machine",
            CONFIG / "machine_square.toml",
            "--no-events",
            "--seed",
            "3",
        ],
        "gravity coupling (biased by design) and no block events: segmentation from the signal",
    ),
}


def make_all():
    """Simulate every sample recording next to this script."""
    for name, (extra, _) in RECORDINGS.items():
        argv = [
            "simulate",
            "--program",
            str(CONFIG / "program_r25.toml"),
            "--sensor",
            str(CONFIG / "sensor_7ug_500hz.toml"),
            "-o",
            str(HERE / f"{name}.mcap"),
            "--start-time",
            START,
            *map(str, extra),
        ]
        code = main(argv)
        if code:
            return code
    return 0


if __name__ == "__main__":
    sys.exit(make_all())
