"""Model discrepancy: where the simulator and a recording disagree, and which effect is missing.

:func:`find_discrepancy` fits the project's simulator to a recording, shows
the gap in several views normalised by the noise floor, names the missing
physical effects from the simulator's vocabulary one at a time (adding each
to the model and refitting), says which effects this test cannot tell apart
and which extra test would. ``docs/discrepancy.md`` describes the method.
"""

from imu_square.discrepancy.result import DiscrepancyResult
from imu_square.discrepancy.views import VIEWS
from imu_square.discrepancy.workflow import DiscrepancyOptions, find_discrepancy

__all__ = ["VIEWS", "DiscrepancyOptions", "DiscrepancyResult", "find_discrepancy"]
