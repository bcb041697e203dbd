"""The analysis pipeline: filter -> segment -> flip/average -> fit -> squareness.

One module per step; :func:`analyze` runs them all on a
:class:`~imu_square.io.recording.Recording` and returns a frozen
:class:`RunResult`.
"""

from imu_square.pipeline.squareness import AnalysisOptions, RunResult, analyze

__all__ = ["AnalysisOptions", "RunResult", "analyze"]
