"""What the documentation's prose quotes from a command's output, checked against that output.

A block of output in the docs is produced by the build (the gallery, or the
``command-output`` directive). A figure or a message quoted *in a sentence*
is not, so each one is listed here with where it comes from: a page the
build produced (the quote must appear in what the command printed there), or
a command run here through the real CLI on the shipped files. Each quote must
appear both in the page that quotes it and in the output. ``...`` in a quote
stands for any text within one line of the output.
"""

import re
from html import unescape
from pathlib import Path

import pytest
from test_docs import site  # noqa: F401 -- the built site's fixture

from imu_square.cli import main

ROOT = Path(__file__).resolve().parents[1]
RECORDINGS = ROOT / "recordings"


def _flat(text):
    return " ".join(text.split())


def _quoted_in(doc, quote):
    """The quote is in the page's source (its line breaks and Markdown's don't count)."""
    assert _flat(quote) in _flat((ROOT / doc).read_text(encoding="utf-8")), (doc, quote)


def _printed_in(output_lines, quote):
    """Some line of the output holds the quote's parts, in order."""
    pattern = ".*?".join(re.escape(_flat(part)) for part in quote.split("..."))
    return any(re.search(pattern, _flat(line)) for line in output_lines)


def _built_output(page):
    """The lines of every output block on a built page (code blocks, gallery output)."""
    html = page.read_text(encoding="utf-8")
    blocks = re.findall(r"<pre[^>]*>(.*?)</pre>", html, flags=re.S)
    return [unescape(re.sub(r"<[^>]+>", "", b)) for b in blocks]


# (the page that quotes, the quote, the built page whose output holds it)
FROM_THE_BUILD = [
    # the verdict's forms, as the gallery's crash example prints them night by night
    (
        "docs/user-guide/reading-results.md",
        "squareness unchanged (+8.1 ± 19.8 µm/m (k=1) since the baseline of ...)",
        "auto_examples/plot_crash_alarm.html",
    ),
    (
        "docs/user-guide/reading-results.md",
        "squareness may be changing: ... past its warning limit",
        "auto_examples/plot_crash_alarm.html",
    ),
    (
        "docs/user-guide/reading-results.md",
        "squareness changed by ... (cusum alarm): check the machine",
        "auto_examples/plot_crash_alarm.html",
    ),
    (
        "docs/user-guide/reading-results.md",
        "alarm since ..., until a new baseline is set",
        "auto_examples/plot_crash_alarm.html",
    ),
    (
        "docs/examples/plot_crash_alarm.py",
        "baseline set from",
        "auto_examples/plot_crash_alarm.html",
    ),
    # baseline show's alarm design, as the same example prints it
    (
        "docs/user-guide/reading-results.md",
        "Designed for one false alarm in 730 valid nights (0.50 a year)",
        "auto_examples/plot_crash_alarm.html",
    ),
    (
        "docs/user-guide/reading-results.md",
        "A step of 30 µm/m (1.83 sigma, sigma 16.3 µm/m a night) is found after 17 nights "
        "(median; ...",
        "auto_examples/plot_crash_alarm.html",
    ),
    # init's crontab line, as the first machine's page shows init's output
    (
        "docs/user-guide/reading-results.md",
        "30 2 * * * /home/shop/imu-square/.venv/bin/imu-square nightly --config "
        "/home/shop/mill-3.toml >> /home/shop/mill-3.log 2>&1",
        "user-guide/first-machine.html",
    ),
    # the trial run's analysis
    ("docs/user-guide/first-machine.md", "1.000 x v²/r", "user-guide/first-machine.html"),
    (
        "docs/user-guide/troubleshooting.md",
        "rejected by the robust fit",
        "user-guide/first-machine.html",
    ),
]


@pytest.mark.parametrize(("doc", "quote", "page"), FROM_THE_BUILD)
def test_a_quote_of_a_built_output_is_what_the_build_printed(site, doc, quote, page):  # noqa: F811
    _quoted_in(doc, quote)
    output = [line for block in _built_output(site / page) for line in block.splitlines()]
    assert _printed_in(output, quote), (page, quote)


def _cut_recording(folder):
    """A recording cut mid-record, as a power cut leaves it."""
    cut = folder / "cut.mcap"
    cut.write_bytes((RECORDINGS / "square_20um.mcap").read_bytes()[:200_000])
    return [str(cut)]


def _with_cutoff(folder):
    return [str(RECORDINGS / "square_20um.mcap"), "--cutoff-hz", "1"]


def _with_a_quarter_of_the_circle(folder):
    """The sample recording and a program of a quarter of its radius and feed: the
    same period, a quarter of the acceleration."""
    text = (RECORDINGS / "config" / "program_r25.toml").read_text(encoding="utf-8")
    text = text.replace("radius_mm = 25.0", "radius_mm = 6.25")
    program = folder / "quarter.toml"
    program.write_text(text.replace("= 9000.0", "= 2250.0"), encoding="utf-8")
    return [str(RECORDINGS / "square_20um.mcap"), "--program", str(program)]


# (the page that quotes, the quote, the command, a function giving its file
# arguments in a scratch folder, the exit code the page states)
FROM_THE_CLI = [
    (
        "docs/user-guide/troubleshooting.md",
        "INCOMPLETE: it ends in the middle of a record",
        ["info"],
        _cut_recording,
        3,
    ),
    (
        "docs/user-guide/troubleshooting.md",
        "low-pass cutoff ... (below 10 x)",
        ["analyze"],
        _with_cutoff,
        0,
    ),
    (
        "docs/user-guide/analysing.md",
        "measured 0.90 m/s² but the program implies 0.22 m/s²: check the feed, the radius "
        "or the units",
        ["analyze"],
        _with_a_quarter_of_the_circle,
        2,
    ),
]


@pytest.mark.parametrize(("doc", "quote", "command", "files", "code"), FROM_THE_CLI)
def test_a_quote_of_a_command_is_what_the_command_prints(
    tmp_path, capsys, doc, quote, command, files, code
):
    _quoted_in(doc, quote)
    assert main([*command, *files(tmp_path)]) == code
    out = capsys.readouterr()
    assert _printed_in((out.out + out.err).splitlines(), quote), (quote, out.out, out.err)


def _state_codes_in_a_table(doc):
    """``{state: code}`` from a page's table rows ``| 11 | `alarm` |`` or ``| `alarm` | 11 |``."""
    text = (ROOT / doc).read_text(encoding="utf-8")
    rows = re.findall(r"^\| (\d+) \| `([a-z_]+)` \|", text, flags=re.M)
    rows += [
        (code, state) for state, code in re.findall(r"^\| `([a-z_]+)` \| (\d+) \|", text, re.M)
    ]
    return {state: int(code) for code, state in rows}


def test_the_exit_codes_the_docs_state_are_the_codes_the_commands_return():
    from imu_square import cli
    from imu_square.monitor.schedule import EXIT_CODES

    readme = _flat((ROOT / "README.md").read_text(encoding="utf-8"))
    shared = re.search(r"Exit codes are (.*?)\. ", readme).group(1)
    assert shared == (
        f"{cli.EXIT_OK} for done, {cli.EXIT_USER_ERROR} for a user's mistake, "
        f"{cli.EXIT_INCOMPLETE} for an incomplete recording, {cli.EXIT_WRITE_FAILED} when "
        f"writing failed part-way and {cli.EXIT_INTERRUPTED} when interrupted"
    ), shared
    states = re.search(r"exits with the machine's state instead: (.*?)\. ", readme).group(1)
    stated = {
        name.removesuffix(" yet").replace(" ", "_"): int(code)
        for code, name in re.findall(r"(\d+) ([a-z ]+)", states)
    }
    assert stated == EXIT_CODES, states
    for doc in ("docs/user-guide/troubleshooting.md", "docs/user-guide/reading-results.md"):
        assert _state_codes_in_a_table(doc) == EXIT_CODES, doc
    shared_rows = re.findall(
        r"^\| (\d+) \|", (ROOT / "docs/user-guide/troubleshooting.md").read_text("utf-8"), re.M
    )
    assert {int(c) for c in shared_rows} == {
        cli.EXIT_OK,
        cli.EXIT_USER_ERROR,
        cli.EXIT_INCOMPLETE,
        cli.EXIT_WRITE_FAILED,
        cli.EXIT_INTERRUPTED,
        *EXIT_CODES.values(),
    }
