#!/usr/bin/env python3
"""imu-square's headless LinuxCNC display: run one program, then let LinuxCNC stop.

LinuxCNC starts this as its [DISPLAY] program with ``-ini FILE``, under its own
Python (the ``linuxcnc`` and ``hal`` modules). Like the Python user interfaces
of LinuxCNC's own tests, it resets the E-stop, switches the machine on, homes
every joint, switches to auto mode and runs [IMU_SQUARE] PROGRAM from its
first line. When the program has ended it lets the axes rest [IMU_SQUARE]
LEAD_OUT_S seconds, waits until halsampler has read the sampler's FIFO empty,
writes [IMU_SQUARE] RESULT (JSON: ``{"ok": true}`` or ``{"ok": false,
"error": "..."}``) and exits, which shuts LinuxCNC down.

It runs outside imu-square's environment and imports nothing of it.
"""

import json
import os
import sys
import time

import hal
import linuxcnc

STEP_TIMEOUT_S = 30.0
POLL_S = 0.02
DRAINED_SAMPLES = 100


class Failed(Exception):
    """LinuxCNC refused a step or reported an error."""


def settings():
    """The INI file's program, result path and lead-out."""
    ini = linuxcnc.ini(sys.argv[sys.argv.index("-ini") + 1])
    return (
        os.path.abspath(ini.find("IMU_SQUARE", "PROGRAM")),
        ini.find("IMU_SQUARE", "RESULT"),
        float(ini.find("IMU_SQUARE", "LEAD_OUT_S") or 1.0),
    )


def check_errors(errors):
    """Raise on an error message from LinuxCNC."""
    message = errors.poll()
    if message and message[0] in (linuxcnc.NML_ERROR, linuxcnc.OPERATOR_ERROR):
        raise Failed(message[1])


def wait_for(stat, errors, done, what, timeout_s=STEP_TIMEOUT_S):
    """Poll LinuxCNC's status until ``done(stat)``."""
    start = time.monotonic()
    while True:
        stat.poll()
        check_errors(errors)
        if done(stat):
            return
        if time.monotonic() - start > timeout_s:
            raise Failed(f"no {what} within {timeout_s:g} s")
        time.sleep(POLL_S)


def run(program):
    """Take the machine from E-stop to the end of the program."""
    command, stat, errors = linuxcnc.command(), linuxcnc.stat(), linuxcnc.error_channel()
    command.state(linuxcnc.STATE_ESTOP_RESET)
    wait_for(stat, errors, lambda s: s.task_state == linuxcnc.STATE_ESTOP_RESET, "E-stop reset")
    command.state(linuxcnc.STATE_ON)
    wait_for(stat, errors, lambda s: s.task_state == linuxcnc.STATE_ON, "machine on")
    command.home(-1)
    wait_for(stat, errors, lambda s: all(j["homed"] for j in s.joint[: s.joints]), "homing")
    command.mode(linuxcnc.MODE_AUTO)
    wait_for(stat, errors, lambda s: s.task_mode == linuxcnc.MODE_AUTO, "auto mode")
    command.program_open(program)
    wait_for(stat, errors, lambda s: s.echo_serial_number >= command.serial, "program opened")
    command.auto(linuxcnc.AUTO_RUN, 0)
    wait_for(stat, errors, lambda s: s.echo_serial_number >= command.serial, "program start")
    # the program's own length is the caller's to bound
    wait_for(stat, errors, lambda s: s.interp_state == linuxcnc.INTERP_IDLE, "program end", 1e9)
    if stat.task_state != linuxcnc.STATE_ON:
        raise Failed("the machine left the on state while the program ran")


def drain(lead_out_s):
    """Let the axes rest, then wait until halsampler has read all but the last moments.

    The sampler sets its depth pin after adding a sample, so it never reads 0;
    once it is below :data:`DRAINED_SAMPLES`, everything before the lead-out's
    last moments is out of the FIFO.
    """
    component = hal.component("imu-square-display")  # HAL reads need a component
    component.ready()
    time.sleep(lead_out_s)
    start = time.monotonic()
    while hal.get_value("sampler.0.curr-depth") > DRAINED_SAMPLES:
        if time.monotonic() - start > STEP_TIMEOUT_S:
            raise Failed("halsampler did not read the sampler's FIFO empty")
        time.sleep(POLL_S)


def main():
    program, result, lead_out_s = settings()
    try:
        run(program)
        drain(lead_out_s)
        outcome = {"ok": True}
    except Exception as exc:  # any failure must reach the result file
        outcome = {"ok": False, "error": f"{type(exc).__name__}: {exc}"}
    with open(result, "w", encoding="utf-8") as f:
        json.dump(outcome, f)
    return 0 if outcome["ok"] else 1


if __name__ == "__main__":
    sys.exit(main())
