"""What a recorder reports: where it is in a recording, and what it has done so far."""

import enum
import math
from dataclasses import dataclass, field

from acquisition.protocol import DeviceHeader
from imu_square.io.runlog import run_is_complete, run_problems


class RecorderState(enum.StrEnum):
    """Where the recorder is; it only moves forward, along :data:`TRANSITIONS`."""

    WAITING_FOR_HEADER = "waiting for header"
    WAITING_FOR_TRIGGER = "waiting for trigger"
    RECORDING = "recording"
    STOPPED = "stopped"


# Every move the recorder makes: the board's first header; the trigger (or a stop while
# waiting for it, which keeps the pre-trigger buffer); and the end, from wherever it was.
TRANSITIONS = {
    RecorderState.WAITING_FOR_HEADER: {RecorderState.WAITING_FOR_TRIGGER, RecorderState.STOPPED},
    RecorderState.WAITING_FOR_TRIGGER: {RecorderState.RECORDING, RecorderState.STOPPED},
    RecorderState.RECORDING: {RecorderState.STOPPED},
    RecorderState.STOPPED: set(),
}


@dataclass
class RecorderStatus:
    """What the recorder has done so far; a snapshot goes to the progress callback.

    Attributes
    ----------
    state : RecorderState
        Where the recorder is.
    samples_written : int
        Samples in the file.
    lost : int
        Samples missing from the file between its first and last sample.
    gaps : int
        Gap events written.
    crc_errors : int
        Frames or lines rejected by the parser since the trigger.
    resyncs : int
        Times the parser found its framing again since the trigger.
    reconnects : int
        Times the port was reopened since the trigger.
    stale_blocks : int
        Blocks dropped because their sequence number did not move forward.
    recorded_s : float
        Board time from the trigger to the newest sample. [s]
    expected_s : float
        Board time from the trigger to the stop condition; the program's
        duration when open-ended; NaN before the trigger. [s]
    rate_hz : float
        Samples per second of host time, measured over the run. [Hz]
    stop_reason : str
        ``"duration"`` or ``"done"`` (as planned), ``"interrupted"``, ``"port lost"``
        (it stayed lost), ``"board silent"`` (no samples), ``"board restarted"``,
        ``"error"``, ``"output error"`` (writing failed), or ``""`` while running.
    lost_at_end : int
        Samples missing after the last one received, up to where the recorder
        stopped, when the board went away (included in ``lost``).
    """

    state: RecorderState = RecorderState.WAITING_FOR_HEADER
    samples_written: int = 0
    lost: int = 0
    gaps: int = 0
    crc_errors: int = 0
    resyncs: int = 0
    reconnects: int = 0
    stale_blocks: int = 0
    recorded_s: float = 0.0
    expected_s: float = math.nan
    rate_hz: float = math.nan
    stop_reason: str = ""
    lost_at_end: int = 0
    header: DeviceHeader | None = field(default=None, repr=False)

    @property
    def complete(self):
        """True for a run that stopped as planned with nothing lost, rejected or reconnected."""
        return run_is_complete(self.stop_reason, self.lost, self.crc_errors, self.reconnects)

    @property
    def problems(self):
        """Why the run is incomplete, one phrase per reason (empty when complete)."""
        dt_s = self.header.dt_ns * 1e-9 if self.header is not None else math.nan
        return run_problems(
            self.stop_reason,
            self.lost,
            self.crc_errors,
            self.reconnects,
            self.lost_at_end,
            self.lost_at_end * dt_s,
            self.stop_reason,
        )

    def enter(self, state):
        """Move to ``state``, one of the moves :data:`TRANSITIONS` allows from here.

        Raises
        ------
        RuntimeError
            For any other move: a fault in the recorder.
        """
        if state not in TRANSITIONS[self.state]:
            raise RuntimeError(f"the recorder cannot go from '{self.state}' to '{state}'")
        self.state = state
