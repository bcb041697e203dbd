"""How a recorded run went, from the events the recorder wrote.

``imu-square record`` ends every file with a ``run_end`` event whose detail
is ``key=value`` pairs (``stop=done,samples=...,lost=...,crc_errors=...``),
and writes a ``gap`` event for every stretch of lost samples. A gap *after*
the last sample (its time is later than every sample's) is the missing tail
of a run whose board went away: the port stayed lost or the board fell
silent, and the recorder stopped without the rest. Its detail is
``lost=N,lost_s=T,cause=...``.

A run is complete when it stopped as planned (``duration`` or ``done``) with
nothing lost, rejected or reconnected; :func:`run_is_complete` is that rule,
shared by the recorder and by ``imu-square info``.
"""

from dataclasses import dataclass

CLEAN_STOPS = ("duration", "done")


def parse_detail(detail):
    """The ``key=value`` pairs of an event's detail.

    Parameters
    ----------
    detail : str
        E.g. ``"lost=12,lost_s=0.012"``.

    Returns
    -------
    dict of str to str
        Items without ``=`` are left out.
    """
    pairs = (item.partition("=") for item in detail.split(","))
    return {key.strip(): value.strip() for key, eq, value in pairs if eq}


def run_is_complete(stop, lost, crc_errors, reconnects):
    """Whether a run stopped as planned with nothing lost, rejected or reconnected.

    Parameters
    ----------
    stop : str
        Why the recorder stopped (``"done"``, ``"duration"``, ``"port lost"``, ...).
    lost : int
        Samples lost, in gaps and at the end.
    crc_errors : int
        Frames or lines the parser rejected.
    reconnects : int
        Times the port was reopened.

    Returns
    -------
    bool
    """
    return stop in CLEAN_STOPS and lost == 0 and crc_errors == 0 and reconnects == 0


@dataclass(frozen=True)
class RunOutcome:
    """What the recorder said about a run.

    Attributes
    ----------
    stop : str
        Why the recorder stopped.
    complete : bool
        See :func:`run_is_complete`.
    problems : tuple of str
        One phrase per reason the run is incomplete, for people.
    lost_at_end : int
        Samples missing between the last one in the file and the recorder's stop.
    lost_at_end_s : float
        The same in time. [s]
    """

    stop: str
    complete: bool
    problems: tuple
    lost_at_end: int
    lost_at_end_s: float

    def to_json_dict(self):
        """The outcome as a JSON-ready dict."""
        return {
            "stop": self.stop,
            "complete": self.complete,
            "problems": list(self.problems),
            "lost_at_end": self.lost_at_end,
            "lost_at_end_s": self.lost_at_end_s,
        }


def _count(fields, key):
    try:
        return int(fields.get(key, "0"))
    except ValueError:
        return 0


def run_problems(stop, lost, crc_errors, reconnects, lost_at_end=0, lost_at_end_s=0.0, cause=""):
    """Why a run is incomplete, one phrase per reason, for people.

    Parameters
    ----------
    stop : str
        Why the recorder stopped.
    lost : int
        Samples lost, in gaps and at the end.
    crc_errors : int
        Frames or lines the parser rejected.
    reconnects : int
        Times the port was reopened.
    lost_at_end : int
        Samples missing after the last one in the file (part of ``lost``).
    lost_at_end_s : float
        The same in time. [s]
    cause : str
        Why the tail is missing (``"port lost"``, ``"board silent"``).

    Returns
    -------
    tuple of str
        Empty for a complete run.
    """
    problems = []
    if stop not in CLEAN_STOPS and not (lost_at_end and stop == cause):
        problems.append(f"stopped early ({stop or 'no reason given'})")
    if lost_at_end:
        problems.append(
            f"the last {lost_at_end_s:.3f} s ({lost_at_end} samples) are missing "
            f"({cause or 'the board went away'})"
        )
    if lost > lost_at_end:
        problems.append(f"{lost - lost_at_end} samples lost in gaps")
    if crc_errors:
        problems.append(f"{crc_errors} frames or lines rejected (CRC or grammar)")
    if reconnects:
        problems.append(f"{reconnects} reconnect(s)")
    return tuple(problems)


def run_outcome(recording):
    """How the run in ``recording`` went, from its ``run_end`` and tail ``gap`` events.

    Parameters
    ----------
    recording : Recording
        A recording, usually read from a file ``imu-square record`` wrote.

    Returns
    -------
    RunOutcome or None
        None when the recording has no ``run_end`` event (simulated,
        imported, or cut before the recorder finished it).
    """
    ends = [e for e in recording.events if e.kind == "run_end"]
    if not ends:
        return None
    fields = parse_detail(ends[-1].detail)
    stop = fields.get("stop", "")
    lost, crc, reconnects = (_count(fields, k) for k in ("lost", "crc_errors", "reconnects"))
    last_ns = int(recording.time_ns[-1]) if recording.n_samples else None
    tail = [
        parse_detail(e.detail)
        for e in recording.events
        if e.kind == "gap" and last_ns is not None and e.time_ns > last_ns
    ]
    lost_at_end = sum(_count(t, "lost") for t in tail)
    lost_at_end_s = sum(float(t.get("lost_s", "0")) for t in tail)
    cause = ", ".join(sorted({t.get("cause", "") for t in tail} - {""}))
    return RunOutcome(
        stop=stop,
        complete=run_is_complete(stop, lost, crc, reconnects),
        problems=run_problems(stop, lost, crc, reconnects, lost_at_end, lost_at_end_s, cause),
        lost_at_end=lost_at_end,
        lost_at_end_s=lost_at_end_s,
    )
