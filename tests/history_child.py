"""A separate process that writes a history, for the reliability tests.

Run as ``python history_child.py MODE LOCATION ...``; it reports on stdout, one
line per event, flushed at once, so the parent knows what was committed even
when it kills this process with SIGKILL.

Modes:

- ``writer LOCATION FIRST BATCH``: from index FIRST on, forever: one
  transaction reports ``begin FIRST_OF_BATCH``, adds BATCH runs
  (:func:`run_for`) and a verdict on each, commits, then reports
  ``committed i:id i:id ...``;
- ``hold LOCATION INDEX RELEASE``: adds run INDEX inside a transaction,
  reports ``holding``, waits for the file RELEASE, commits and reports
  ``committed INDEX:id``;
- ``add LOCATION INDEX TIMEOUT_S``: opens, reports ``ready``, waits for the
  file named by $GO, adds run INDEX and reports
  ``{"id":..., "inserted":..., "elapsed_s":...}`` or ``error <one line>``;
- ``race LOCATION FIRST COUNT SHARED``: opens, waits for the file named by
  $GO, then adds runs FIRST..FIRST+COUNT-1 interleaved with run SHARED (the
  same recording in every racing process), one transaction each, and reports
  ``{"runs": {index: [id, inserted]}, "shared": [[id, inserted], ...]}``;
- ``open LOCATION``: waits for $GO, opens (creating the schema), reports the
  schema version.
"""

import hashlib
import json
import os
import sys
import time

from imu_square.errors import ImuSquareError
from imu_square.monitor.history.rows import EvaluationRow, RunRow
from imu_square.monitor.history.store import open_history

MACHINE = "mill-7"
SETTINGS = {"cutoff_hz": 4.0, "norm": "tukey", "grid_points": 512}


def run_for(index, machine=MACHINE):
    """The run numbered ``index``: every field a function of it, so it can be checked."""
    sha = hashlib.sha256(f"recording {index}".encode()).hexdigest()
    valid = index % 7 != 3
    cycles = 15
    per_cycle = {
        "pair": list(range(cycles)),
        "squareness_rad": [1e-5 * ((index * 31 + k) % 97) / 97 for k in range(cycles)],
        "t_s": [12.5 * k for k in range(cycles)],
    }
    return RunRow(
        machine_id=machine,
        recording_path=f"/data/{machine}/run-{index:06d}.mcap",
        recording_sha256=sha,
        settings=SETTINGS,
        software_version="0.1.0",
        recorded_at_ns=1_790_000_000_000_000_000 + index * 3_600_000_000_000,
        analysed_at_ns=1_800_000_000_000_000_000 + index,
        valid=valid,
        invalid_reason=None if valid else f"run {index}: too few cycles (2 < 3)",
        squareness_rad=1e-5 + index * 1e-9,
        u_squareness_rad=3e-6,
        u_squareness_bootstrap_rad=3.1e-6,
        dof=cycles - 1,
        crb_rad=2.5e-6,
        theta_x_rad=-0.0012,
        theta_y_rad=-0.0012 + 1e-5,
        eps_c_rad=0.0366 + index * 1e-9,
        u_eps_c_rad=1e-4,
        servo_mismatch_rad=2e-4,
        u_servo_mismatch_rad=4e-6,
        noise_density_m_s2_rthz=6.9e-5,
        amp_x_m_s2=0.1,
        amp_y_m_s2=0.1001,
        temperature_start_c=24.0 + index % 5,
        temperature_end_c=26.0,
        temperature_mean_c=25.0,
        time_since_power_on_s=600.0 + index,
        cycles_ccw=cycles,
        cycles_cw=cycles,
        quality={"clipped": False, "excess_noise": index % 2 == 0},
        warnings=[f"warning of run {index} with µm/m"],
        per_cycle=per_cycle,
        result={"squareness_urad": 10.0 + index * 1e-3, "source": f"run-{index}"},
    )


def index_of(row):
    """The index :func:`run_for` built ``row`` from."""
    return int(row.recording_path.rsplit("-", 1)[1].split(".")[0])


def _say(text):
    sys.stdout.write(text + "\n")
    sys.stdout.flush()


def _wait_for(path, limit_s=120.0):
    deadline = time.monotonic() + limit_s
    while path and not os.path.exists(path) and time.monotonic() < deadline:
        time.sleep(0.001)


def _wait_go():
    _wait_for(os.environ.get("GO"))


def main(argv):
    mode, location = argv[0], argv[1]
    if mode == "writer":
        first, batch = int(argv[2]), int(argv[3])
        with open_history(location) as history:
            _say("ready")
            index = first
            while True:
                done = []
                with history.transaction():
                    _say(f"begin {index}")
                    for i in range(index, index + batch):
                        row = run_for(i)
                        run_id, _ = history.add_run(row)
                        state = "no_baseline" if row.valid else "invalid"
                        history.add_evaluation(
                            EvaluationRow(run_id=run_id, state=state, statistics={"i": i})
                        )
                        done.append(f"{i}:{run_id}")
                _say("committed " + " ".join(done))
                index += batch
    elif mode == "hold":
        index, release = int(argv[2]), argv[3]
        with open_history(location) as history, history.transaction():
            run_id, _ = history.add_run(run_for(index))
            _say("holding")
            _wait_for(release)
        _say(f"committed {index}:{run_id}")
    elif mode == "add":
        index, timeout = int(argv[2]), float(argv[3])
        with open_history(location, busy_timeout_s=timeout) as history:
            _say("ready")
            _wait_go()
            t0 = time.monotonic()
            try:
                run_id, inserted = history.add_run(run_for(index))
            except ImuSquareError as exc:
                _say(f"error {exc}")
                return
            _say(
                json.dumps({"id": run_id, "inserted": inserted, "elapsed_s": time.monotonic() - t0})
            )
    elif mode == "race":
        first, count, shared = int(argv[2]), int(argv[3]), int(argv[4])
        out = {"runs": {}, "shared": []}
        with open_history(location) as history:
            _say("ready")
            _wait_go()
            for i in range(first, first + count):
                out["runs"][i] = history.add_run(run_for(i))
                out["shared"].append(history.add_run(run_for(shared)))
        _say(json.dumps(out))
    elif mode == "open":
        _wait_go()
        with open_history(location) as history:
            _say(str(history.schema_version))
    else:
        raise SystemExit(f"unknown mode {mode!r}")


if __name__ == "__main__":
    main(sys.argv[1:])
