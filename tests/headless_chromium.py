"""Debian's Chromium, headless: a page's DOM after its scripts ran, and its body's marks.

The report and the documentation tests put a probe script into a page that writes
what it measured into ``data-*`` attributes of ``<body>``; this reads them back.
"""

import re
import shutil
import subprocess

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")


def command(profile, *options):
    """Chromium's command line, headless, with a throw-away profile and options.

    Parameters
    ----------
    profile : Path
        A throw-away Chromium profile folder.
    *options : str
        More Chromium options (``--window-size=W,H``).

    Returns
    -------
    list of str
    """
    return [
        CHROMIUM,
        "--headless",
        "--no-sandbox",
        "--disable-gpu",
        "--disable-background-networking",
        "--disable-component-update",
        "--disable-sync",
        "--no-first-run",
        f"--user-data-dir={profile}",
        *options,
        "--virtual-time-budget=10000",
    ]


def body_marks(page, profile, *options):
    """Open a page headless and return its body's ``data-*`` marks and its DOM.

    Parameters
    ----------
    page : Path
        The HTML file.
    profile : Path
        A throw-away Chromium profile folder.
    *options : str
        More Chromium options (``--window-size=W,H``).

    Returns
    -------
    marks : dict of str to str
    dom : str
    """
    proc = subprocess.run(
        [*command(profile, *options), "--dump-dom", page.as_uri()],
        capture_output=True,
        text=True,
        timeout=120,
    )
    body = re.search(r"<body([^>]*)>", proc.stdout)
    assert body, proc.stderr[-2000:]
    return dict(re.findall(r'data-([a-z-]+)="([^"]*)"', body.group(1))), proc.stdout
