"""A JSON-ready summary of a recording, for ``imu-square info``."""

from collections import Counter

from imu_square.io.runlog import run_outcome
from imu_square.json_values import json_safe


def summarize(recording):
    """A JSON-ready summary of a recording, for ``imu-square info``.

    Parameters
    ----------
    recording : Recording
        The recording.

    Returns
    -------
    dict
        ``samples``, ``duration_s`` [s], ``sample_rate_hz`` [Hz], ``dt_ns``
        [ns], ``start_time_ns`` [ns], ``gaps`` (count, lost), ``channels``
        (axes and temperature), ``program`` (file units) or None, ``sensor``
        (NaN as None), ``machine_id``, ``events`` (count by kind),
        ``metadata``, ``processing``, and ``run``: how the recorder said the
        run went (:class:`~imu_square.io.runlog.RunOutcome`), None for a
        file without a ``run_end`` event.
    """
    program = recording.program
    outcome = run_outcome(recording)
    return {
        "samples": recording.n_samples,
        "duration_s": recording.duration_s,
        "sample_rate_hz": recording.sample_rate_hz,
        "dt_ns": recording.dt_ns,
        "start_time_ns": int(recording.time_ns[0]) if recording.n_samples else None,
        "gaps": {"count": recording.gap_count, "lost": recording.lost_in_all},
        "channels": ["accel_x", "accel_y", "accel_z"]
        + (["temperature_c"] if recording.temperature_c is not None else []),
        "program": None
        if program is None
        else {
            **program.to_mapping(),
            # one period per feed in a multi-feed program
            "period_s": program.period_s
            if program.n_feeds == 1
            else [program.at_feed(f).period_s for f in range(program.n_feeds)],
            "n_blocks": program.n_blocks,
            "duration_s": program.duration_s,
        },
        "sensor": json_safe(recording.sensor),
        "machine_id": recording.machine_id,
        "events": dict(sorted(Counter(e.kind for e in recording.events).items())),
        "metadata": dict(recording.metadata),
        "processing": list(recording.processing),
        "run": None if outcome is None else outcome.to_json_dict(),
    }
