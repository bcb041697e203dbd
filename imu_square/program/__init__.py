"""The circle test program: its file (:mod:`.spec`), its NC code (:mod:`.ncgen`)
and the strict parser that checks that code (:mod:`.gcode_check`)."""

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
