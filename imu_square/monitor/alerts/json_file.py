"""The JSON-file sink: the latest alert for a dashboard, or every alert as JSON Lines.

``mode = "latest"`` (the default) keeps one file holding the newest alert, the
whole :meth:`Alert.as_dict` object, replaced atomically: a dashboard or a
script polling it always reads a whole alert. An older alert delivered late
from the outbox never overwrites a newer one. ``mode = "append"`` keeps every
alert, one JSON object per line (JSON Lines), oldest first: each line is one
``O_APPEND`` write, which the kernel never interleaves with another's, and
an alert already in the file (same ``alert_id``) is not added twice. Its
size grows by about 1 kB a night.
"""

import json
import os
from dataclasses import dataclass
from pathlib import Path

from imu_square.io.atomic import write_atomic
from imu_square.monitor.alerts.alert import DEFAULT_ALERT_STATES, STATES, DeliveryError

JSON_FILE_MODES = ("latest", "append")


@dataclass(frozen=True)
class JsonFileSink:
    """Write alerts to a JSON file.

    Attributes
    ----------
    name : str
        The sink's name in outcomes and the outbox.
    states : tuple of str
        States that are written.
    path : Path
        The file; its folder must exist.
    mode : str
        ``"latest"`` or ``"append"`` (module docstring).
    """

    name: str
    states: tuple
    path: Path
    mode: str = "latest"
    timeout_s = None  # a local write does not wait on a server
    kind = "json_file"

    def deliver(self, alert, timeout_s=None):
        """Write ``alert`` to the file.

        Parameters
        ----------
        alert : Alert
            The alert.
        timeout_s : float, optional
            Unused: a local write has no timeout. [s]

        Raises
        ------
        DeliveryError
            If the file cannot be read or written (not permanent: a disk that
            is full or not mounted tonight may be back tomorrow).
        """
        try:
            if self.mode == "latest":
                if not self._newer_on_disk(alert):
                    write_atomic(self.path, alert.to_json(indent=2) + b"\n")
            else:
                self._append(alert)
        except OSError as exc:
            raise DeliveryError(f"cannot write {self.path}: {exc.strerror or exc}") from None

    def _append(self, alert):
        old = self.path.read_bytes() if self.path.exists() else b""
        if _holds(old, alert.alert_id):
            return
        line = alert.to_json() + b"\n"
        if old and not old.endswith(b"\n"):
            line = b"\n" + line  # a line cut short (a full disk) stays a line of its own
        fd = os.open(self.path, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o644)
        try:
            os.write(fd, line)
            os.fsync(fd)  # on disk before the outbox marks the alert delivered
        finally:
            os.close(fd)

    def _newer_on_disk(self, alert):
        try:
            on_disk = json.loads(self.path.read_bytes())
            return on_disk["created_at"] > alert.created_at  # ISO 8601 UTC sorts as text
        except (FileNotFoundError, ValueError, KeyError, TypeError):  # none, or not one of ours
            return False

    def describe(self):
        """What the sink does, for messages."""
        return f"{self.path} ({self.mode})"


def _holds(jsonl, alert_id):
    for line in jsonl.splitlines():
        try:
            if json.loads(line).get("alert_id") == alert_id:
                return True
        except (ValueError, AttributeError):
            continue
    return False


def json_file_from_table(table, name, default_states=DEFAULT_ALERT_STATES):
    """A ``[alerts.json_file]`` table.

    Parameters
    ----------
    table : imu_square.validation.TomlTable
        The checked table.
    name : str
        The sink's name when the table does not give one.
    default_states : tuple of str
        States when the table does not list them.

    Returns
    -------
    JsonFileSink
    """
    return JsonFileSink(
        name=name,
        states=table.choices("states", STATES, default=default_states),
        path=table.path("path"),
        mode=table.choice("mode", JSON_FILE_MODES, default="latest"),
    )
