#!/usr/bin/env python3
"""Set up and run imu-square from a fresh checkout with nothing but Python 3.11+.

    python3 dev.py nightly [ARGS...]   # the monitor's nightly run on a demonstration machine
    python3 dev.py test [PYTEST ARGS]  # the whole test suite
    python3 dev.py lint                # ruff check, format check, vulture (dead code)
    python3 dev.py run ARGS...         # any imu-square command

The first call creates ``.venv`` next to this file and installs the project
with its test dependencies; later calls reinstall only when pyproject.toml
changes.
"""

import hashlib
import os
import subprocess
import sys
import venv
from pathlib import Path

ROOT = Path(__file__).resolve().parent
VENV = ROOT / ".venv"
BIN = VENV / ("Scripts" if os.name == "nt" else "bin")
STAMP = VENV / ".imu-square-installed"


def _ensure_env():
    if sys.version_info < (3, 11):  # noqa: UP036 -- dev.py may be run by an older python3
        sys.exit(f"dev.py: imu-square needs Python 3.11 or later, this is {sys.version.split()[0]}")
    digest = hashlib.sha256((ROOT / "pyproject.toml").read_bytes()).hexdigest()
    if STAMP.exists() and STAMP.read_text() == digest:
        return
    if not (BIN / "python").exists():
        print("dev.py: creating .venv", file=sys.stderr)
        venv.EnvBuilder(with_pip=True).create(VENV)
    print("dev.py: installing imu-square and its test dependencies", file=sys.stderr)
    pip = [str(BIN / "python"), "-m", "pip", "install", "--disable-pip-version-check", "-q"]
    subprocess.run([*pip, "-e", f"{ROOT}[test]"], check=True, cwd=ROOT)
    STAMP.write_text(digest)


def _run(cmd):
    return subprocess.run(cmd, cwd=ROOT).returncode


def main(argv):
    if not argv or argv[0] not in ("nightly", "test", "lint", "run"):
        print(__doc__, file=sys.stderr)
        return 2
    _ensure_env()
    what, rest = argv[0], argv[1:]
    if what == "nightly":
        # Without arguments: the demonstration machine (its history seeded on the first call).
        return _run([str(BIN / "imu-square"), "nightly", *(rest or ["--demo", "imu-square-demo"])])
    if what == "run":
        return _run([str(BIN / "imu-square"), *rest])
    if what == "lint":
        ruff = str(BIN / "ruff")
        return (
            _run([ruff, "check", "."])
            or _run([ruff, "format", "--check", "."])
            or _run([str(BIN / "vulture")])  # paths and whitelist: [tool.vulture]
        )
    code = _run([str(BIN / "python"), "-m", "pytest", *rest])
    if code == 5:  # pytest found no tests: that is a failure here, never a pass
        print("dev.py: pytest collected no tests", file=sys.stderr)
        return 1
    return code


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
