"""LinuxCNC in the loop: its trajectory planner drives the simulated test.

LinuxCNC (Debian's ``linuxcnc-uspace``) runs the NC program that ``imu-square
program --dialect linuxcnc`` writes on a simulated machining centre kept in the
project (``imu_square/data/linuxcnc/``), headless and in real time; HAL's sampler
records the joints' commanded positions every servo period. Those samples are
"a motion" (:class:`imu_square.simulate.sampled_motion.SampledMotion`) that the
simulator and the emulated board take instead of our own trajectory.

- :mod:`.ini`: a LinuxCNC INI file and the machine's limits in it (``plan
  --linuxcnc-ini``);
- :mod:`.configuration`: the simulated machine's configuration folder;
- :mod:`.runner`: start LinuxCNC headless on a program and collect the samples;
- :mod:`.samples`: halsampler's output and the block markers in it;
- :mod:`.cache`: one controller run per program and configuration, reused;
- :mod:`.motion`: a program's motion on LinuxCNC, from the cache or a run.
"""

from imu_square.linuxcnc.ini import ControllerLimits, read_limits
from imu_square.linuxcnc.motion import linuxcnc_motion

__all__ = ["ControllerLimits", "linuxcnc_motion", "read_limits"]
