#!/bin/sh
# imu-square's block marker, as the user M-code the program calls at the start and end of
# every block (copied to USER_M_PATH as M<number>). LinuxCNC runs it once the motion before
# it has stopped; it raises the HAL signal the sampler records by one.
n=$(halcmd -s gets imu-square-marker) || exit 1
exec halcmd sets imu-square-marker $((n + 1))
