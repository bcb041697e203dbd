"""Run one NC program on LinuxCNC, headless, and collect the commanded positions.

The run folder (a fresh temporary folder) gets the configuration's files, the
program (``program.ngc``), the marker M-code's executable (``mcodes/M<n>``),
an empty tool table and parameter file. ``linuxcnc -r`` then starts on the INI
file without a GUI: its display (``display.py``) resets the E-stop, homes, runs
the program once and exits, and LinuxCNC shuts down. The motion controller runs
in real time, so this takes as long as the program takes on a machine, plus
LinuxCNC's start and stop (about 10 s).

What it needs, found by trial on Debian 12's ``linuxcnc-uspace`` 2.9:

- as root, ``rtapi_app`` refuses to start unless ``RTAPI_UID`` names a
  fallback user (``nobody`` here); ``RTAPI_FIFO_PATH`` then points into a
  folder that user can write;
- the display is a Python script for LinuxCNC's own Python (``PYTHON`` of
  ``linuxcnc_var``), found first on ``PATH``; ``DISPLAY`` is unset, so
  nothing opens a window;
- one LinuxCNC at a time per computer: its launcher shuts down a running one
  (``/tmp/linuxcnc.lock``). A run refuses to start while that lock exists (it
  may be a real machine's controller) and waits for another imu-square run.

``HOME`` is the run folder, so LinuxCNC's logs stay there. The folder is
deleted after a good run and kept, with its logs, after a failed one.
"""

import fcntl
import json
import os
import pwd
import shutil
import signal
import subprocess
import tempfile
from pathlib import Path

from imu_square.errors import ControllerError
from imu_square.linuxcnc.configuration import DISPLAY_NAME, FILES, INI_NAME, MARKER_NAME
from imu_square.linuxcnc.samples import parse_halsampler
from imu_square.simulate.sampled_motion import ServoSamples

INSTALL_HINT = (
    "LinuxCNC is not installed: on Debian 12 run 'apt-get install linuxcnc-uspace' "
    "(about 100 packages, no real-time kernel needed)"
)
# LinuxCNC's launcher keeps this while it runs; a second launcher shuts the first one down.
LINUXCNC_LOCK = Path("/tmp/linuxcnc.lock")
# imu-square's runs take turns on this.
RUN_LOCK = Path(tempfile.gettempdir()) / "imu-square-linuxcnc.lock"
# Time for LinuxCNC to start and stop, beyond the program's own. [s]
START_STOP_S = 60.0
# After SIGTERM, how long the launcher may take to shut LinuxCNC down. [s]
STOP_GRACE_S = 30.0


def linuxcnc_version():
    """LinuxCNC's version, e.g. ``"2.9.0~pre1+git20230208.f1270d6ed7"``.

    Raises
    ------
    ControllerError
        If LinuxCNC is not installed.
    """
    return _linuxcnc_var("LINUXCNCVERSION")


def _linuxcnc_var(name):
    tool = shutil.which("linuxcnc_var")
    if tool is None or shutil.which("linuxcnc") is None:
        raise ControllerError(INSTALL_HINT)
    out = subprocess.run([tool, name], capture_output=True, text=True, check=False, timeout=30)
    if out.returncode != 0 or not out.stdout.strip():
        raise ControllerError(f"{INSTALL_HINT} (linuxcnc_var {name} answered nothing)")
    return out.stdout.strip()


def _environment(folder):
    """LinuxCNC's environment: its Python first on PATH, no X display, logs in ``folder``."""
    python_bin = str(Path(_linuxcnc_var("PYTHON")).parent)
    launcher_bin = str(Path(shutil.which("linuxcnc")).parent)
    keep = ("LANG", "LC_ALL", "TZ", "TMPDIR")
    env = {k: os.environ[k] for k in keep if k in os.environ}
    env.update(
        PATH=os.pathsep.join(dict.fromkeys([python_bin, launcher_bin, "/usr/bin", "/bin"])),
        HOME=str(folder),
        RTAPI_FIFO_PATH=str(folder / "rtapi" / "fifo"),
    )
    (folder / "rtapi").mkdir()
    if os.getuid() == 0:
        user = _fallback_user()
        env["RTAPI_UID"] = str(user)
        folder.chmod(0o711)  # the fallback user passes through to its FIFO folder
        os.chown(folder / "rtapi", user, -1)
    return env


def _fallback_user():
    try:
        return pwd.getpwnam("nobody").pw_uid
    except KeyError:
        return 65534


def _prepare(folder, configuration, nc_text, marker_mcode):
    for name in FILES:
        (folder / name).write_bytes(configuration.read(name))
    (folder / DISPLAY_NAME).chmod(0o755)
    mcodes = folder / "mcodes"
    mcodes.mkdir()
    marker = mcodes / f"M{marker_mcode}"
    marker.write_bytes(configuration.read(MARKER_NAME))
    marker.chmod(0o755)
    (folder / "program.ngc").write_text(nc_text, encoding="utf-8")
    (folder / "sim.tbl").write_text("", encoding="utf-8")
    (folder / "sim.var").write_text("", encoding="utf-8")


def _log_tail(folder, lines=8):
    text = ""
    for name in ("linuxcnc.log", "linuxcnc_debug.txt"):
        path = folder / name
        if path.is_file():
            text += path.read_text(encoding="utf-8", errors="replace")
    kept = [line for line in text.splitlines() if "fallback_uid" not in line and line.strip()]
    return " | ".join(kept[-lines:])


def _wait(process, timeout_s, folder):
    """Wait for the launcher; on a timeout or an interrupt, have it shut LinuxCNC down."""
    try:
        return process.wait(timeout=timeout_s)
    except BaseException as exc:
        process.terminate()  # the launcher traps SIGTERM and shuts LinuxCNC down
        try:
            process.wait(timeout=STOP_GRACE_S)
        except subprocess.TimeoutExpired:
            os.killpg(process.pid, signal.SIGKILL)  # the session it was started in
            process.wait()
        if isinstance(exc, subprocess.TimeoutExpired):
            raise ControllerError(
                f"LinuxCNC did not finish the program within {timeout_s:.0f} s; its logs are "
                f"in {folder}"
            ) from None
        raise


def _run_in(folder, timeout_s):
    env = _environment(folder)
    with open(folder / "linuxcnc.log", "wb") as log:
        process = subprocess.Popen(
            ["linuxcnc", "-r", INI_NAME],
            cwd=folder,
            env=env,
            stdin=subprocess.DEVNULL,
            stdout=log,
            stderr=subprocess.STDOUT,
            start_new_session=True,
        )
        code = _wait(process, timeout_s, folder)
    result = folder / "display-result.json"
    outcome = json.loads(result.read_text()) if result.is_file() else None
    if outcome is None or not outcome.get("ok"):
        why = outcome["error"] if outcome else f"LinuxCNC exited with {code}"
        raise ControllerError(
            f"LinuxCNC did not run the program: {why}; logs in {folder}: {_log_tail(folder)}"
        )
    return (folder / "samples.txt").read_text(encoding="ascii", errors="replace")


def run_on_linuxcnc(nc_text, configuration, marker_mcode, duration_s, progress=None):
    """Run a program on LinuxCNC and sample its commanded positions.

    Parameters
    ----------
    nc_text : str
        The program, as ``imu-square program --dialect linuxcnc --marker-mcode``
        writes it.
    configuration : Configuration
        The machine's configuration folder.
    marker_mcode : int
        The program's marker M-code (100-199).
    duration_s : float
        The program's expected time on the machine; the run is abandoned after
        twice that plus :data:`START_STOP_S`. [s]
    progress : callable, optional
        Called with a line of text when the run waits or starts.

    Returns
    -------
    ServoSamples
        Its ``source`` names LinuxCNC, its version and the configuration.

    Raises
    ------
    ControllerError
        LinuxCNC is not installed, another LinuxCNC runs, or the run failed.
    """
    say = progress or (lambda text: None)
    version = linuxcnc_version()
    with open(RUN_LOCK, "a") as lock:
        try:
            fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            say("waiting for another imu-square LinuxCNC run to finish")
            fcntl.flock(lock, fcntl.LOCK_EX)
        if LINUXCNC_LOCK.exists():
            raise ControllerError(
                f"LinuxCNC is already running on this computer ({LINUXCNC_LOCK} exists): "
                "imu-square does not start a second one, whose launcher would shut the first "
                "down; stop it (or remove a stale lock) and try again"
            )
        folder = Path(tempfile.mkdtemp(prefix="imu-square-linuxcnc-"))
        _prepare(folder, configuration, nc_text, marker_mcode)
        say(
            f"running the program on LinuxCNC {version} in real time "
            f"(about {duration_s + 15:.0f} s)"
        )
        text = _run_in(folder, 2 * duration_s + START_STOP_S)
    xy, markers = parse_halsampler(text, str(folder / "samples.txt"))
    shutil.rmtree(folder, ignore_errors=True)
    source = {
        "source": "linuxcnc",
        "controller": "LinuxCNC",
        "version": version,
        "configuration": configuration.describe(),
        "marker_mcode": marker_mcode,
    }
    return ServoSamples(configuration.servo_period_s, xy, markers, source)
