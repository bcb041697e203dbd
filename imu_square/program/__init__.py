"""The circle test program: its file (:mod:`.spec`) and its NC code (:mod:`.ncgen`)."""

from imu_square.program.spec import (
    DIRECTIONS,
    SUPPORTED_PLANES,
    BlockPlan,
    TestProgram,
    default_program,
    parse_program,
    program_from_mapping,
    read_program,
)

__all__ = [
    "DIRECTIONS",
    "SUPPORTED_PLANES",
    "BlockPlan",
    "TestProgram",
    "default_program",
    "parse_program",
    "program_from_mapping",
    "read_program",
]
