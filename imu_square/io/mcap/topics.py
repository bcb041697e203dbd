"""Where a recording lives in an MCAP file: its topics, attachment and metadata.

``/imu/accel``
    ``imu_square/msg/AccelBatch`` (ros2msg schema, CDR): about 0.1 s of
    consecutive samples per message, see :mod:`imu_square.io.cdr`.
    ``log_time = publish_time = t0_ns`` of the batch.
``/imu/preview``
    ``geometry_msgs/msg/Vector3Stamped`` (CDR), the mean of the samples of
    each 1/100 s, frame ``"imu"``, for plotting in Foxglove; never read back.
``/test/events``
    JSON, one :class:`~imu_square.io.recording.Event` per message.
attachment ``program.toml``
    The test program, when the recording has one.
metadata ``sensor``, ``machine``, ``software``, ``recording``, ``sequence``
    Sensor fields, machine id, writer version and ``dt_ns``, the recording's
    metadata and processing log (as JSON text), and the first unwrapped
    sequence number.

MCAP log times are unsigned: a negative sample or event time is kept exactly
in the message, and its log time is clamped to 0.
"""

from dataclasses import fields

from imu_square.io.recording import Event

ACCEL_TOPIC = "/imu/accel"
PREVIEW_TOPIC = "/imu/preview"
EVENTS_TOPIC = "/test/events"
PROGRAM_ATTACHMENT = "program.toml"

EVENT_FIELDS = tuple(f.name for f in fields(Event))
EVENT_SCHEMA = {
    "title": "imu_square.Event",
    "type": "object",
    "properties": {
        "time_ns": {"type": "integer", "description": "time on the recording's clock [ns]"},
        "kind": {"type": "string"},
        "direction": {"type": "string"},
        "block": {"type": "integer"},
        "detail": {"type": "string"},
    },
    "required": list(EVENT_FIELDS),
}
