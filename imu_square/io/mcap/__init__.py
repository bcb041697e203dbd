"""Recordings as MCAP files: a streaming writer and a reader that survives a cut file.

:mod:`~imu_square.io.mcap.topics` says where a recording lives in the file,
:mod:`~imu_square.io.mcap.writer` writes it, :mod:`~imu_square.io.mcap.reader`
reads it back record by record (up to the first damage, through
:mod:`~imu_square.io.mcap.scan`, with the byte layout of
:mod:`~imu_square.io.mcap.layout`), and :mod:`~imu_square.io.mcap.recovery`
rewrites what a cut file holds as a whole file.
"""

from imu_square.io.mcap.reader import read_mcap, scan_mcap
from imu_square.io.mcap.recovery import recover_mcap
from imu_square.io.mcap.summary import summarize
from imu_square.io.mcap.topics import ACCEL_TOPIC, EVENTS_TOPIC, PREVIEW_TOPIC
from imu_square.io.mcap.writer import RecordingWriter, batch_layout, write_mcap

__all__ = [
    "ACCEL_TOPIC",
    "EVENTS_TOPIC",
    "PREVIEW_TOPIC",
    "RecordingWriter",
    "batch_layout",
    "read_mcap",
    "recover_mcap",
    "scan_mcap",
    "summarize",
    "write_mcap",
]
