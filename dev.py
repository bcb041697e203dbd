#!/usr/bin/env python3
"""Set up and run imu-square from a fresh checkout with nothing but Python 3.11+.

    python3 dev.py nightly [ARGS...]   # the monitor's nightly run on a demonstration machine
    python3 dev.py test [PYTEST ARGS]  # the whole test suite
    python3 dev.py lint                # ruff check, format check, vulture (dead code)
    python3 dev.py docs [SPHINX ARGS]  # the documentation site, gallery run, into docs/_build/html
    python3 dev.py run ARGS...         # any imu-square command

The first call creates ``.venv`` next to this file and installs the project
with its test dependencies; later calls reinstall only when pyproject.toml
changes. ``docs`` also installs the documentation's dependencies (the
``docs`` extra) the first time.
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
DOCS_STAMP = VENV / ".imu-square-docs-installed"


def _ensure_env(extras="test", stamp=STAMP):
    if sys.version_info < (3, 11):  # noqa: UP036 -- dev.py may be run by an older python3
        sys.exit(f"dev.py: imu-square needs Python 3.11 or later, this is {sys.version.split()[0]}")
    digest = hashlib.sha256((ROOT / "pyproject.toml").read_bytes()).hexdigest()
    if stamp.exists() and stamp.read_text() == digest:
        return
    if not (BIN / "python").exists():
        print("dev.py: creating .venv", file=sys.stderr)
        venv.EnvBuilder(with_pip=True).create(VENV)
    what = "and its documentation's " if "docs" in extras else ""
    print(f"dev.py: installing imu-square {what}and its test dependencies", file=sys.stderr)
    pip = [str(BIN / "python"), "-m", "pip", "install", "--disable-pip-version-check", "-q"]
    subprocess.run([*pip, "-e", f"{ROOT}[{extras}]"], check=True, cwd=ROOT)
    stamp.write_text(digest)
    if stamp is DOCS_STAMP:  # the test dependencies came with it
        STAMP.write_text(digest)


def _run(cmd):
    return subprocess.run(cmd, cwd=ROOT).returncode


def main(argv):
    if not argv or argv[0] not in ("nightly", "test", "lint", "run", "docs"):
        print(__doc__, file=sys.stderr)
        return 2
    what, rest = argv[0], argv[1:]
    if what == "docs":
        _ensure_env("test,docs", DOCS_STAMP)
        # The site into docs/_build/html; every gallery example runs. CI adds -W --keep-going.
        out = ROOT / "docs" / "_build"
        cmd = ["-m", "sphinx", "-b", "html", "-d", str(out / "doctrees"), *rest]
        return _run([str(BIN / "python"), *cmd, str(ROOT / "docs"), str(out / "html")])
    _ensure_env()
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
