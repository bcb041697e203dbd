"""A block's commanded angle and time at constant feed: the program's timeline, for tests."""


def nominal_angle(program, block, t_s):
    """Commanded position angle at ``t_s`` within ``block``, at constant feed. [rad]"""
    omega = program.feeds[block.feed] / program.radius_m
    return block.start_angle_rad + block.sign * omega * (t_s - block.t_start_s)


def nominal_time(program, block, phi_rad):
    """Time at which ``block`` passes ``phi_rad``, at constant feed; from the first block. [s]"""
    omega = program.feeds[block.feed] / program.radius_m
    return block.t_start_s + block.sign * (phi_rad - block.start_angle_rad) / omega
